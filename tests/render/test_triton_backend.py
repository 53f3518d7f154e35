"""The fused ``triton`` backend against the float64 dense oracle and finite differences.

Runs on CUDA where a GPU and triton are present, or on the CPU under Triton's interpreter
(``TRITON_INTERPRET=1`` with triton installed); elsewhere it is skipped with the registry's
reason. The registry test at the end runs everywhere.
"""

from __future__ import annotations

import pytest
import torch

from robogs.format.errors import InputError
from robogs.format.render import Gaussians, RenderConfig, available_backends, render
from robogs.format.render.backends import backend_entries

FIELDS = ("rgb", "alpha", "depth_expected", "normals", "extra")


def _reason() -> str:
    for e in backend_entries():
        if e.name == "triton":
            return str(e.reason)
    return "triton is not in the backend registry"


HAVE = "triton" in available_backends()
DEVICE = "cuda" if torch.cuda.is_available() else "cpu"
needs_triton = pytest.mark.skipif(not HAVE, reason=f"triton backend unavailable: {_reason()}")


def _f32(g: Gaussians) -> Gaussians:
    return Gaussians(**{k: (v.float() if v is not None else None) for k, v in vars(g).items()})


def _leaves(g: Gaussians) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone().requires_grad_(True) for k, v in vars(g).items() if v is not None}


def _scene(make_gaussians, make_camera, kind, n=80, seed=3, extra=3, **kw):
    g = make_gaussians(n, kind, seed=seed, extra=extra, sh_coeffs=4, device=DEVICE, **kw)
    return g, make_camera(device=DEVICE)


@needs_triton
@pytest.mark.parametrize("extra", [2, 12])  # 9 and 19 feature columns (one and two dot blocks)
@pytest.mark.parametrize("tile", [8, 16])
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_forward_matches_dense(make_gaussians, make_camera, kind, tile, extra):
    g, cam = _scene(make_gaussians, make_camera, kind, extra=extra)
    cfg = RenderConfig(kind=kind, tile_size=tile, background=(0.2, 0.4, 0.6))
    a = render(_f32(g), cam, config=cfg, backend="triton")
    b = render(g, cam, config=cfg, backend="dense")
    assert a.rgb.dtype == torch.float32 and float(b.alpha.max()) > 0.5
    d = {f: float((getattr(a, f).double() - getattr(b, f)).abs().max()) for f in FIELDS}
    assert max(d.values()) <= 5e-5, d
    med = (a.depth_median.double() - b.depth_median).abs()
    assert float(med.max()) <= 1e-4, float(med.max())
    # float64 inputs are rendered in float32 and returned in float64
    c = render(g, cam, config=cfg, backend="triton")
    assert c.rgb.dtype == torch.float64
    assert float((c.rgb - b.rgb).abs().max()) <= 5e-5


@needs_triton
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_deep_scene_stop_rule_and_median(make_gaussians, make_camera, kind):
    """Opaque layers: most pixels end by the stop rule (T < 1e-4), medians cross 0.5."""
    g, cam = _scene(
        make_gaussians, make_camera, kind, n=600, seed=7, opacity_shift=4.0, scale=(0.03, 0.15)
    )
    cfg = RenderConfig(kind=kind, tile_size=16)
    a = render(_f32(g), cam, config=cfg, backend="triton")
    b = render(g, cam, config=cfg, backend="dense")
    assert float((b.alpha > 0.999).double().mean()) > 0.3
    d = {f: float((getattr(a, f).double() - getattr(b, f)).abs().max()) for f in FIELDS}
    assert max(d.values()) <= 2e-4, d
    # a float32 T can land on the other side of 0.5 than float64 only at a near tie
    off = ((a.depth_median.double() - b.depth_median).abs() > 1e-4).double().mean()
    assert float(off) <= 0.01, float(off)
    assert float((b.depth_median > 0).double().mean()) > 0.5


def _grads(g: Gaussians, cam, cfg, backend: str, weights: dict[str, torch.Tensor]):
    leaves = _leaves(g)
    out = render(Gaussians(**leaves), cam, config=cfg, backend=backend)
    out.means2d.retain_grad()
    loss = sum((getattr(out, f) * w).sum() for f, w in weights.items())
    loss.backward()
    grads = {k: v.grad.double() for k, v in leaves.items()}
    grads["means2d"] = out.means2d.grad.double()
    return grads


@needs_triton
@pytest.mark.parametrize("n,shift", [(60, 0.0), (300, 4.0)])
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_gradients_match_dense(make_gaussians, make_camera, kind, n, shift):
    g, cam = _scene(make_gaussians, make_camera, kind, n=n, opacity_shift=shift)
    cfg = RenderConfig(kind=kind, tile_size=16, background=(0.1, 0.2, 0.3))
    ref = render(g, cam, config=cfg, backend="dense")
    gen = torch.Generator().manual_seed(1)
    weights = {
        f: torch.randn(getattr(ref, f).shape, generator=gen, dtype=torch.float64).to(DEVICE)
        for f in FIELDS + ("depth_median",)
    }
    a = _grads(_f32(g), cam, cfg, "triton", {f: w.float() for f, w in weights.items()})
    b = _grads(g, cam, cfg, "dense", weights)
    for k in b:
        scale = float(b[k].abs().max())
        err = float((a[k] - b[k]).abs().max())
        assert scale > 0 and err <= 2e-3 * scale, (k, err, scale)


def _smooth_scene(kind: str, n: int = 8) -> Gaussians:
    """Large, half-transparent Gaussians whose support cut lies outside the 37 x 29 image, facing
    the camera: the render is smooth in every parameter (no support or stop-rule jumps)."""
    gen = torch.Generator().manual_seed(11)
    ns = 3 if kind == "3dgs" else 2
    means = torch.randn(n, 3, generator=gen) * 0.15 + torch.tensor([0.0, 0.0, 2.0])
    quats = torch.cat([torch.ones(n, 1), 0.15 * torch.randn(n, 3, generator=gen)], dim=1)
    g = Gaussians(
        means=means,
        quats=quats,
        log_scales=torch.log(torch.rand(n, ns, generator=gen) * 0.4 + 0.6),
        opacity_logits=torch.randn(n, generator=gen) * 0.4 - 0.5,
        sh=torch.randn(n, 1, 3, generator=gen) * 0.5,
    )
    return Gaussians(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})


@needs_triton
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_gradients_match_finite_differences(make_camera, kind):
    """Central differences of the triton forward itself (float32, h = 1e-2) on every opacity
    logit, centre coordinate and log-scale of a smooth scene."""
    g = _smooth_scene(kind)
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind=kind, tile_size=16)
    w = torch.rand(cam.height, cam.width, 3, generator=torch.Generator().manual_seed(2))
    w = w.to(DEVICE)

    def loss(gg: Gaussians) -> float:
        with torch.no_grad():
            return float((render(gg, cam, config=cfg, backend="triton").rgb * w).sum())

    leaves = _leaves(g)
    (render(Gaussians(**leaves), cam, config=cfg, backend="triton").rgb * w).sum().backward()
    h = 1e-2
    for field in ("opacity_logits", "means", "log_scales"):
        an_all = leaves[field].grad
        for sel in [tuple(int(i) for i in ix) for ix in torch.nonzero(torch.ones_like(an_all))]:
            plus, minus = _leaves(g), _leaves(g)
            with torch.no_grad():
                plus[field][sel] += h
                minus[field][sel] -= h
            fd = (loss(Gaussians(**plus)) - loss(Gaussians(**minus))) / (2 * h)
            an = float(an_all[sel])
            assert abs(fd - an) <= 0.01 * abs(an) + 0.05, (field, sel, fd, an)


@needs_triton
def test_means2d_gradient_matches_torch_backend(make_gaussians, make_camera):
    g, cam = _scene(make_gaussians, make_camera, "3dgs", n=120)
    g = _f32(g)
    cfg = RenderConfig(kind="3dgs", tile_size=16)
    ones = {"rgb": torch.ones(cam.height, cam.width, 3, device=DEVICE)}
    a = _grads(g, cam, cfg, "triton", ones)["means2d"]
    b = _grads(g, cam, cfg, "torch", ones)["means2d"]
    assert float(b.abs().max()) > 0
    assert float((a - b).abs().max()) <= 1e-4 * float(b.abs().max())


@needs_triton
def test_bad_tile_size_is_a_clear_error(make_gaussians, make_camera):
    g, cam = _scene(make_gaussians, make_camera, "3dgs", n=5)
    with pytest.raises(InputError, match="tile_size 4"):
        render(g, cam, config=RenderConfig(tile_size=4), backend="triton")


@pytest.mark.skipif(not (HAVE and DEVICE == "cuda"), reason="needs the triton backend on CUDA")
def test_cpu_tensors_are_refused_on_a_gpu_machine(make_gaussians, make_camera):
    g = make_gaussians(5, "3dgs")
    with pytest.raises(InputError, match="CUDA tensors"):
        render(g, make_camera(), backend="triton")


def test_registry_lists_triton_with_a_reason():
    entry = [e for e in backend_entries() if e.name == "triton"]
    assert len(entry) == 1
    if HAVE:
        assert entry[0].status == "ok"
    else:
        assert entry[0].status == "unavailable"
        assert "CUDA" in str(entry[0].reason) or "triton" in str(entry[0].reason)

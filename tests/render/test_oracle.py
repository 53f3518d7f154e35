"""The tiled torch backend against the dense oracle (forward and gradients), float64."""

from __future__ import annotations

import pytest
import torch

from robogs.format.render import RenderConfig, render

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
FIELDS = ("rgb", "alpha", "depth_expected", "depth_median", "normals", "extra")
TOL = 1e-5


def max_diffs(a, b) -> dict[str, float]:
    return {f: float((getattr(a, f) - getattr(b, f)).abs().max()) for f in FIELDS}


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("tile_size", [4, 8, 16])
@pytest.mark.parametrize("sh_coeffs", [1, 4, 9, 16])
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_torch_matches_dense_random(
    make_gaussians, make_camera, kind, sh_coeffs, tile_size, device
):
    g = make_gaussians(
        80, kind, seed=sh_coeffs + tile_size, sh_coeffs=sh_coeffs, extra=3, device=device
    )
    cam = make_camera(device=device)
    cfg = RenderConfig(kind=kind, tile_size=tile_size, chunk=5, background=(0.2, 0.4, 0.6))
    a = render(g, cam, config=cfg)
    b = render(g, cam, config=cfg, backend="dense")
    assert float(b.alpha.max()) > 0.5  # the scene is in view
    d = max_diffs(a, b)
    assert max(d.values()) <= TOL, d


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_torch_matches_dense_deep_scene(make_gaussians, make_camera, kind, device):
    """Many opaque layers: the stop rule (T < 1e-4) and the median crossing are exercised."""
    g = make_gaussians(900, kind, seed=7, scale=(0.03, 0.15), opacity_shift=4.0, device=device)
    cam = make_camera(device=device)
    cfg = RenderConfig(kind=kind, tile_size=8, chunk=16, tile_batch=3)
    a = render(g, cam, config=cfg)
    b = render(g, cam, config=cfg, backend="dense")
    assert float((b.alpha > 0.999).float().mean()) > 0.3  # many pixels hit the stop rule
    assert float((b.depth_median > 0).float().mean()) > 0.5
    d = max_diffs(a, b)
    assert max(d.values()) <= TOL, d


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_gaussians_on_tile_borders(make_gaussians, make_camera, kind):
    """Means on tile corners and edges render the same as the oracle.

    The means sit 0.0137 px off the corners: exactly on them, pixel offsets are half-integers
    and a pixel can land exactly on the 3-sigma cut, where rounding decides either way."""
    cam = make_camera(width=32, height=24, pose=False)
    g = make_gaussians(16, kind, seed=3, opacity_shift=2.0)
    u = torch.tensor([8.0, 16.0, 8.0, 24.0] * 4, dtype=torch.float64) + 0.0137
    v = torch.tensor([8.0] * 8 + [16.0] * 8, dtype=torch.float64) - 0.0137
    z = g.means[:, 2]
    g.means = torch.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z], dim=-1)
    cfg = RenderConfig(kind=kind, tile_size=8, chunk=4)
    d = max_diffs(render(g, cam, config=cfg), render(g, cam, config=cfg, backend="dense"))
    assert max(d.values()) <= TOL, d


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_result_independent_of_tile_size_and_chunk(make_gaussians, make_camera, kind):
    g = make_gaussians(150, kind, seed=11)
    cam = make_camera()
    ref = render(g, cam, config=RenderConfig(kind=kind, tile_size=16, chunk=64))
    for ts, chunk, batch in [(3, 1, 1), (5, 7, None), (32, 2, 2)]:
        out = render(
            g, cam, config=RenderConfig(kind=kind, tile_size=ts, chunk=chunk, tile_batch=batch)
        )
        d = max_diffs(out, ref)
        assert max(d.values()) <= TOL, (ts, chunk, d)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_gradients_match_dense(make_gaussians, make_camera, kind, device):
    g = make_gaussians(40, kind, seed=5, sh_coeffs=9, extra=2, device=device)
    params = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh, g.extra]
    for p in params:
        p.requires_grad_(True)
    cam = make_camera(device=device)
    cfg = RenderConfig(kind=kind, tile_size=8, chunk=6)
    gen = torch.Generator().manual_seed(0)
    grads = []
    for backend in ("torch", "dense"):
        out = render(g, cam, config=cfg, backend=backend)
        loss = (
            sum(
                (
                    getattr(out, f)
                    * torch.randn(getattr(out, f).shape, generator=gen, dtype=torch.float64).to(
                        device
                    )
                ).sum()
                for f in FIELDS
                if f != "depth_median"
            )
            + out.depth_median.sum()
        )
        grads.append(torch.autograd.grad(loss, params))
        gen.manual_seed(0)
    for name, a, b in zip(
        ("means", "quats", "log_scales", "opacity", "sh", "extra"), *grads, strict=True
    ):
        scale = float(b.abs().max()) + 1e-12
        assert float((a - b).abs().max()) <= 1e-8 * max(1.0, scale), name


@pytest.mark.parametrize("device", DEVICES)
def test_float32_close_to_float64(make_gaussians, make_camera, device):
    g64 = make_gaussians(200, "3dgs", seed=2, device=device)
    g32 = type(g64)(**{k: (v.float() if v is not None else None) for k, v in vars(g64).items()})
    cam = make_camera(device=device)
    a = render(g64, cam)
    b = render(g32, cam)
    assert float((a.rgb - b.rgb.double()).abs().max()) < 1e-4
    assert float((a.alpha - b.alpha.double()).abs().max()) < 1e-4

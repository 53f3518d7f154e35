"""The fused Triton projection (``triton_project.py``) against ``project()`` in float64.

Runs where the ``triton`` backend runs (CUDA, or the CPU under ``TRITON_INTERPRET=1``); skipped
with the registry's reason elsewhere. Scenes mix ordinary Gaussians with ones behind the camera,
off screen, tiny (sub-pixel) and huge (larger than the image), so that every branch of the
projection (depth cut, FOV clamp of the Jacobian, low-pass, culling) is exercised.
"""

from __future__ import annotations

import math

import pytest
import torch

from robogs.format.render import Gaussians, RenderConfig, available_backends, render
from robogs.format.render.backends import backend_entries
from robogs.format.render.projection import project


def _reason() -> str:
    for e in backend_entries():
        if e.name == "triton":
            return str(e.reason)
    return "triton is not in the backend registry"


HAVE = "triton" in available_backends()
DEVICE = "cuda" if torch.cuda.is_available() else "cpu"
pytestmark = pytest.mark.skipif(not HAVE, reason=f"triton backend unavailable: {_reason()}")

DIFF = ("means2d", "depth", "conic", "log_opacity", "rgb", "normals")
DIFF_2DGS = ("means2d", "depth", "ray", "log_opacity", "rgb", "normals")
LEAVES = ("means", "quats", "log_scales", "opacity_logits", "sh")


def _mixed_scene(
    make_gaussians, n: int = 300, sh_coeffs: int = 16, seed: int = 4, kind: str = "3dgs"
) -> Gaussians:
    """Random Gaussians (float64); the first rows are placed in the hard cases."""
    g = make_gaussians(n, kind, seed=seed, sh_coeffs=sh_coeffs, extra=2, spread=0.5)
    means, ls = g.means.clone(), g.log_scales.clone()
    means[0:8, 2] = torch.linspace(-1.0, 0.005, 8, dtype=means.dtype)  # behind / at the camera
    means[8:16, 0] += torch.linspace(-6.0, 6.0, 8, dtype=means.dtype)  # off screen (FOV clamp)
    means[16:20, 2] = 200.0  # beyond far is not reached by small_camera: far away, tiny
    ls[20:30] = math.log(1e-4)  # tiny: the low-pass dominates
    ls[30:40] = math.log(3.0)  # huge: larger than the image
    ls[40:45, 0] = math.log(1e-4)  # needles
    return Gaussians(
        means=means,
        quats=g.quats,
        log_scales=ls,
        opacity_logits=g.opacity_logits,
        sh=g.sh,
        extra=g.extra,
    )


def _fused(g: Gaussians, cam, cfg):
    from robogs.format.render.triton_project import project_fused

    return project_fused(g, cam, cfg)


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float, atol_frac: float) -> tuple[bool, float]:
    """|a - b| <= rtol |b| + atol_frac max|b| everywhere; returns the worst excess ratio."""
    a, b = a.double(), b.double()
    tol = rtol * b.abs() + atol_frac * float(b.abs().max()) + 1e-30
    r = float(((a - b).abs() / tol).max()) if b.numel() else 0.0
    return r <= 1.0, r


@pytest.mark.parametrize("kind,antialiased", [("3dgs", False), ("3dgs", True), ("2dgs", False)])
@pytest.mark.parametrize(
    "sh_coeffs,sh_degree", [(1, None), (4, None), (9, None), (16, None), (16, 1)]
)
def test_outputs_match_project(
    make_gaussians, make_camera, kind, antialiased, sh_coeffs, sh_degree
):
    g = _mixed_scene(make_gaussians, sh_coeffs=sh_coeffs, kind=kind)
    g = Gaussians(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind=kind, antialiased=antialiased, sh_degree=sh_degree, lowpass_scale=1.3)
    ref = project(g, cam, cfg)
    out = _fused(g, cam, cfg)
    assert torch.equal(out.visible, ref.visible)
    assert 0 < int(ref.visible.sum()) < len(g)  # some culled, some not
    for f in (DIFF if kind == "3dgs" else DIFF_2DGS) + ("exp_min", "bbox"):
        ok, r = _close(getattr(out, f), getattr(ref, f), rtol=2e-4, atol_frac=2e-6)
        assert ok, (f, r)
    assert out.lowpass_inv_sq == ref.lowpass_inv_sq and out.extra is g.extra


def _grads(g: Gaussians, cam, cfg, fn, weights):
    leaves = {k: getattr(g, k).detach().clone().requires_grad_(True) for k in LEAVES}
    p = fn(Gaussians(**leaves, extra=None), cam, cfg)
    loss = sum((getattr(p, f) * w.to(getattr(p, f).dtype)).sum() for f, w in weights.items())
    loss.backward()
    return {
        k: (v.grad.double() if v.grad is not None else torch.zeros_like(v, dtype=torch.float64))
        for k, v in leaves.items()
    }


@pytest.mark.parametrize("kind,antialiased", [("3dgs", False), ("3dgs", True), ("2dgs", False)])
@pytest.mark.parametrize("sh_coeffs,sh_degree", [(1, None), (4, None), (16, None), (16, 2)])
def test_gradients_match_project(
    make_gaussians, make_camera, kind, antialiased, sh_coeffs, sh_degree
):
    g = _mixed_scene(make_gaussians, n=200, sh_coeffs=sh_coeffs, seed=9, kind=kind)
    g = Gaussians(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind=kind, antialiased=antialiased, sh_degree=sh_degree)
    ref = project(g, cam, cfg)
    gen = torch.Generator().manual_seed(5)
    # weights scaled by each output's typical size, so that no term hides the others
    weights = {}
    for f in DIFF if kind == "3dgs" else DIFF_2DGS:
        v = getattr(ref, f).detach()
        typ = v.abs().median().clamp_min(1e-6) if v.dim() == 1 else v.abs().median(0).values
        w = torch.randn(v.shape, generator=gen, dtype=torch.float64).to(DEVICE)
        weights[f] = w / typ.clamp_min(1e-6)
    a = _grads(g, cam, cfg, _fused, weights)
    b = _grads(g, cam, cfg, project, weights)
    for k in LEAVES:
        assert float(b[k].abs().max()) > 0, k
        ok, r = _close(a[k], b[k], rtol=2e-3, atol_frac=2e-5)
        assert ok, (k, r)


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_each_output_reaches_its_fields(make_gaussians, make_camera, kind):
    """One output at a time (a wrong term cannot be cancelled by another output's)."""
    g = _mixed_scene(make_gaussians, n=120, sh_coeffs=16, seed=2, kind=kind)
    g = Gaussians(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind=kind, antialiased=True)
    gen = torch.Generator().manual_seed(8)
    ref = project(g, cam, cfg)
    for f in DIFF if kind == "3dgs" else DIFF_2DGS:
        v = getattr(ref, f).detach()
        w = torch.randn(v.shape, generator=gen, dtype=torch.float64).to(DEVICE)
        w = w * ref.visible.reshape(-1, *([1] * (v.dim() - 1))).to(w.dtype)
        a = _grads(g, cam, cfg, _fused, {f: w})
        b = _grads(g, cam, cfg, project, {f: w})
        for k in LEAVES:
            ok, r = _close(a[k], b[k], rtol=2e-3, atol_frac=2e-5)
            assert ok, (f, k, r)


def test_float32_inputs_and_empty(make_gaussians, make_camera):
    g = make_gaussians(7, "3dgs", seed=1, sh_coeffs=4, dtype=torch.float32, device=DEVICE)
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind="3dgs")
    out, ref = _fused(g, cam, cfg), project(g, cam, cfg)
    assert out.rgb.dtype == torch.float32
    assert float((out.conic - ref.conic).abs().max()) <= 1e-4 * float(ref.conic.abs().max())
    empty = Gaussians(**{k: v[:0] for k, v in vars(g).items() if v is not None})
    assert _fused(empty, cam, cfg).means2d.shape == (0, 2)


def _render_grads(g, cam, cfg, weights):
    leaves = {
        k: v.detach().clone().requires_grad_(True) for k, v in vars(g).items() if v is not None
    }
    out = render(Gaussians(**leaves), cam, config=cfg, backend="triton")
    out.means2d.retain_grad()
    loss = sum((getattr(out, f) * w).sum() for f, w in weights.items())
    loss.backward()
    grads = {k: v.grad.double() for k, v in leaves.items()}
    grads["means2d"] = out.means2d.grad.double()
    return out, grads


@pytest.mark.parametrize("kind,antialiased", [("3dgs", False), ("3dgs", True), ("2dgs", False)])
def test_render_with_the_flag_matches_without(
    make_gaussians, make_camera, monkeypatch, kind, antialiased
):
    from robogs.format.render import triton_raster as tr

    g = make_gaussians(150, kind, seed=3, sh_coeffs=9, extra=2, dtype=torch.float32)
    g = Gaussians(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})
    cam = make_camera(device=DEVICE)
    cfg = RenderConfig(kind=kind, tile_size=16, antialiased=antialiased, background=(0.1, 0.2, 0.3))
    gen = torch.Generator().manual_seed(1)
    fields = ("rgb", "alpha", "depth_expected", "normals", "extra", "depth_median")
    shapes = {"rgb": (3,), "normals": (3,), "extra": (2,)}
    weights = {
        f: torch.randn(cam.height, cam.width, *shapes.get(f, ()), generator=gen).to(DEVICE)
        for f in fields
    }
    monkeypatch.setattr(tr, "_FUSED_PROJECTION", False)
    a, ga = _render_grads(g, cam, cfg, weights)
    monkeypatch.setattr(tr, "_FUSED_PROJECTION", True)
    b, gb = _render_grads(g, cam, cfg, weights)
    assert float(a.alpha.detach().max()) > 0.5
    for f in fields + ("means2d", "radii"):
        x, y = getattr(a, f).detach(), getattr(b, f).detach()
        d = float((x - y).abs().max())
        assert d <= 1e-4 * max(1.0, float(x.abs().max())), (f, d)
    for k in ga:
        scale = float(ga[k].abs().max())
        assert scale > 0 and float((ga[k] - gb[k]).abs().max()) <= 1e-3 * scale, k

"""Finite-difference gradient checks of the tiled backend (float64, tiny scenes)."""

from __future__ import annotations

import pytest
import torch

from robogs.format.render import Gaussians, RenderConfig, render


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_gradcheck(make_gaussians, make_camera, kind):
    g = make_gaussians(
        6, kind, seed=1, sh_coeffs=4, extra=0, centre_z=1.0, spread=0.12, scale=(0.03, 0.08)
    )
    cam = make_camera(width=12, height=10, pose=False)
    cam = type(cam)(
        width=12, height=10, fx=12.0, fy=12.0, cx=6.2, cy=4.9, T_world_cam=cam.T_world_cam
    )
    params = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh]
    for p in params:
        p.requires_grad_(True)
    cfg = RenderConfig(kind=kind, tile_size=4, chunk=3)

    def f(means, quats, log_scales, opacity_logits, sh):
        out = render(Gaussians(means, quats, log_scales, opacity_logits, sh), cam, config=cfg)
        return out.rgb, out.alpha, out.depth_expected, out.normals

    out = f(*params)
    assert float(out[1].detach().max()) > 0.3  # the Gaussians are in view
    assert torch.autograd.gradcheck(f, params, eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)


def test_gradcheck_camera_pose(make_gaussians, make_camera):
    """The render is differentiable w.r.t. T_world_cam (for pose refinement)."""
    g = make_gaussians(
        5, "3dgs", seed=4, extra=0, sh_coeffs=1, centre_z=1.0, spread=0.1, scale=(0.03, 0.08)
    )
    base = make_camera(pose=False)
    xi = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    cfg = RenderConfig(tile_size=4, chunk=4)

    def f(t):
        T = torch.eye(4, dtype=torch.float64)
        T = torch.cat([torch.cat([T[:3, :3], t[:, None]], 1), T[3:]], 0)
        cam = type(base)(width=12, height=10, fx=12.0, fy=12.0, cx=6.2, cy=4.9, T_world_cam=T)
        return render(g, cam, config=cfg).rgb

    assert torch.autograd.gradcheck(f, (xi,), eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)

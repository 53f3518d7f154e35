"""``RenderOutput.means2d`` is on the autograd graph: its gradient is dL/d(screen mean).

Oracle: a central finite difference of the dense backend's loss in which one Gaussian's
projected mean moves by +-h px while its 2D covariance, depth, colour and opacity stay fixed.
The moved Gaussian is built here from first principles (pinhole Jacobian, pseudo-inverse and
eigendecomposition in numpy/scipy): a 3D covariance that projects to the same 2D covariance at
the shifted position.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.format.render import Camera, Gaussians, RenderConfig, render

FX, FY, CX, CY, W, H = 40.0, 42.0, 12.3, 9.8, 24, 20


def _camera(**kw) -> Camera:
    return Camera(
        width=W,
        height=H,
        fx=FX,
        fy=FY,
        cx=CX,
        cy=CY,
        T_world_cam=torch.eye(4, dtype=torch.float64),
        **kw,
    )


def _scene(seed: int = 0) -> Gaussians:
    """Five overlapping Gaussians in view, one behind the camera, one below 1/255 opacity."""
    gen = np.random.default_rng(seed)
    n = 7
    means = np.c_[gen.uniform(-0.05, 0.05, (n, 2)), gen.uniform(0.9, 1.3, n)]
    means[5, 2] = -1.0  # behind the camera: culled
    opacity = gen.uniform(-0.5, 1.5, n)
    opacity[6] = -7.0  # sigmoid(-7) < 1/255: culled
    return Gaussians(
        means=torch.tensor(means),
        quats=torch.tensor(gen.normal(size=(n, 4))),
        log_scales=torch.tensor(np.log(gen.uniform(0.02, 0.06, (n, 3)))),
        opacity_logits=torch.tensor(opacity),
        sh=torch.tensor(gen.normal(size=(n, 1, 3)) * 0.4),  # degree 0: no view dependence
        extra=torch.tensor(gen.uniform(size=(n, 2))),
    )


def _loss_weights(cam: Camera, seed: int = 1) -> dict[str, torch.Tensor]:
    """Fixed random per-pixel weights of a linear loss over rgb, alpha, depth and extras."""
    gen = torch.Generator().manual_seed(seed)
    h, w = cam.height, cam.width
    shapes = {"rgb": (h, w, 3), "alpha": (h, w), "depth_expected": (h, w), "extra": (h, w, 2)}
    return {k: torch.rand(s, generator=gen, dtype=torch.float64) - 0.3 for k, s in shapes.items()}


def _loss(out, weights) -> torch.Tensor:
    return sum((getattr(out, k) * w).sum() for k, w in weights.items())


def _jacobian(p: np.ndarray) -> np.ndarray:
    x, y, z = p
    return np.array([[FX / z, 0.0, -FX * x / z**2], [0.0, FY / z, -FY * y / z**2]])


def _shifted(g: Gaussians, i: int, axis: int, h: float) -> Gaussians:
    """Gaussian i's projected mean moved by ``h`` px along ``axis``; its 2D covariance kept."""
    p = g.means[i].numpy()
    q = g.quats[i].numpy()
    R = Rotation.from_quat(q[[1, 2, 3, 0]]).as_matrix()  # scipy is scalar-last
    cov3 = R @ np.diag(np.exp(2.0 * g.log_scales[i].numpy())) @ R.T
    cov2 = _jacobian(p) @ cov3 @ _jacobian(p).T
    p2 = p.copy()
    p2[axis] += h * p[2] / (FX if axis == 0 else FY)
    J2 = _jacobian(p2)
    A = J2.T @ np.linalg.inv(J2 @ J2.T)  # J2 @ A = I
    ray = p2 / np.linalg.norm(p2)  # J2 @ ray = 0: extent along the ray does not project
    cov3_new = A @ cov2 @ A.T + 0.03**2 * np.outer(ray, ray)
    np.testing.assert_allclose(J2 @ cov3_new @ J2.T, cov2, rtol=1e-12, atol=1e-12)
    ev, V = np.linalg.eigh(cov3_new)
    if np.linalg.det(V) < 0:
        V[:, 0] = -V[:, 0]
    xyzw = Rotation.from_matrix(V).as_quat()
    means, quats, log_scales = g.means.clone(), g.quats.clone(), g.log_scales.clone()
    means[i] = torch.from_numpy(p2)
    quats[i] = torch.from_numpy(xyzw[[3, 0, 1, 2]])
    log_scales[i] = torch.from_numpy(0.5 * np.log(ev))
    return Gaussians(means, quats, log_scales, g.opacity_logits, g.sh, g.extra)


def _means2d_grad(g: Gaussians, cam: Camera, cfg: RenderConfig, backend: str, weights):
    g = Gaussians(
        g.means.clone().requires_grad_(True), g.quats, g.log_scales, g.opacity_logits, g.sh, g.extra
    )
    out = render(g, cam, config=cfg, backend=backend)
    out.means2d.retain_grad()
    _loss(out, weights).backward()
    assert out.means2d.grad is not None, f"{backend}: means2d is not on the graph"
    return out.means2d.detach(), out.means2d.grad


def test_means2d_grad_matches_finite_differences():
    g, cam = _scene(), _camera()
    weights = _loss_weights(cam)
    cfg = RenderConfig(tile_size=4, chunk=3)
    h = 1e-5
    fd = torch.zeros(len(g), 2, dtype=torch.float64)
    with torch.no_grad():
        base = render(g, cam, config=cfg, backend="dense")
        for i in range(5):  # the visible ones
            for axis in (0, 1):
                lp = _loss(
                    render(_shifted(g, i, axis, h), cam, config=cfg, backend="dense"), weights
                )
                lm = _loss(
                    render(_shifted(g, i, axis, -h), cam, config=cfg, backend="dense"), weights
                )
                fd[i, axis] = (lp - lm) / (2 * h)
    assert float(base.alpha.max()) > 0.5
    assert float(fd[:5].abs().min()) > 1e-3  # every visible Gaussian moves the loss
    for backend in ("torch", "dense"):
        m2d, grad = _means2d_grad(g, cam, cfg, backend, weights)
        torch.testing.assert_close(grad, fd, rtol=1e-5, atol=1e-6, msg=backend)
        expect = torch.stack(
            [FX * g.means[:5, 0] / g.means[:5, 2] + CX, FY * g.means[:5, 1] / g.means[:5, 2] + CY],
            1,
        )
        torch.testing.assert_close(m2d[:5], expect, rtol=0, atol=1e-12)
        assert m2d[5:].abs().max() == 0 and grad[5:].abs().max() == 0  # culled rows


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_means2d_grad_torch_matches_dense_posed(make_gaussians, make_camera, kind):
    """A posed camera and view-dependent colour: both backends give the same screen gradient."""
    g = make_gaussians(30, kind, seed=5, sh_coeffs=9, extra=2)
    cam = make_camera()
    cfg = RenderConfig(kind=kind, tile_size=8, chunk=4)
    weights = _loss_weights(cam)
    _, a = _means2d_grad(g, cam, cfg, "torch", weights)
    _, b = _means2d_grad(g, cam, cfg, "dense", weights)
    assert float(b.norm(dim=1).max()) > 1e-3
    torch.testing.assert_close(a, b, rtol=1e-7, atol=1e-9)


def test_means2d_grad_distorted_camera(make_gaussians):
    """Through the undistortion warp: the gradient still reaches means2d (render-grid px)."""
    g = make_gaussians(20, "3dgs", seed=2, sh_coeffs=1, extra=0, spread=0.2)
    cam = _camera(distortion_model="plumb_bob", distortion=(-0.2, 0.05, 0.001, -0.001, 0.0))
    cfg = RenderConfig(undistort_scale=2.0, tile_size=8)
    weights = {k: v for k, v in _loss_weights(cam).items() if k != "extra"}
    _, a = _means2d_grad(g, cam, cfg, "torch", weights)
    _, b = _means2d_grad(g, cam, cfg, "dense", weights)
    assert float(b.norm(dim=1).max()) > 1e-3
    torch.testing.assert_close(a, b, rtol=1e-7, atol=1e-9)

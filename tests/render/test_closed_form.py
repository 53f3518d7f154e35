"""Closed-form cases: one Gaussian, occlusion, the stop rule, SH constants, rotations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.format.frames import quat_to_matrix as quat_to_rotmat
from robogs.format.render import Camera, Gaussians, RenderConfig, eval_sh, render
from robogs.format.render.sh import SH_C0, sh_basis

F64 = torch.float64


def one_camera(size: int = 33, f: float = 50.0) -> Camera:
    c = size / 2
    return Camera(
        width=size, height=size, fx=f, fy=f, cx=c, cy=c, T_world_cam=torch.eye(4, dtype=F64)
    )


def gaussians(means, log_scale, logits, dc) -> Gaussians:
    n = len(means)
    return Gaussians(
        means=torch.tensor(means, dtype=F64),
        quats=torch.tensor([[1.0, 0.0, 0.0, 0.0]] * n, dtype=F64),
        log_scales=torch.tensor([[log_scale[i]] * 3 for i in range(n)], dtype=F64),
        opacity_logits=torch.tensor(logits, dtype=F64),
        sh=torch.tensor(dc, dtype=F64)[:, None, :],
    )


@pytest.mark.parametrize("backend", ["torch", "dense"])
def test_single_isotropic_gaussian_analytic_alpha(backend):
    cam = one_camera()
    z, s, logit = 2.0, 0.04, 1.0
    g = gaussians([[0.0, 0.0, z]], [math.log(s)], [logit], [[0.3, -0.2, 0.1]])
    out = render(g, cam, backend=backend)
    o = 1 / (1 + math.exp(-logit))
    var = (cam.fx * s / z) ** 2 + 0.3  # EWA: J S J^T + 0.3 I, px^2
    ys, xs = np.mgrid[0:33, 0:33] + 0.5
    d2 = (xs - cam.cx) ** 2 + (ys - cam.cy) ** 2
    power = 0.5 * d2 / var
    alpha = o * np.exp(-power)
    alpha[(power > 4.5) | (alpha < 1 / 255)] = 0.0
    np.testing.assert_allclose(out.alpha.numpy(), alpha, atol=1e-12)
    peak = np.unravel_index(int(out.alpha.argmax()), out.alpha.shape)
    assert peak == (16, 16)  # the projected mean (16.5, 16.5) is pixel (16, 16)'s centre
    assert float(out.alpha[16, 16]) == pytest.approx(o, abs=1e-12)
    inside = out.alpha.numpy() > 0
    np.testing.assert_allclose(out.depth_expected.numpy()[inside], z, atol=1e-12)
    assert float(out.depth_expected[0, 0]) == 0.0
    np.testing.assert_allclose(out.depth_median.numpy(), np.where(alpha >= 0.5, z, 0.0), atol=1e-12)
    colour = np.clip(0.5 + SH_C0 * np.array([0.3, -0.2, 0.1]), 0, None)
    np.testing.assert_allclose(out.rgb.numpy(), alpha[..., None] * colour, atol=1e-12)
    if backend == "torch":  # the dense oracle has no bounding boxes (radii are 0)
        assert float(out.radii[0, 0]) == pytest.approx(3 * math.sqrt(var), rel=1e-9)
    assert out.means2d[0].tolist() == pytest.approx([16.5, 16.5])


@pytest.mark.parametrize("backend", ["torch", "dense"])
def test_opaque_front_gaussian_hides_the_back_one(backend):
    cam = one_camera()
    g = gaussians(
        [[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]],
        [math.log(0.05), math.log(0.1)],
        [10.0, 0.5],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    )
    out = render(g, cam, config=RenderConfig(background=(0.0, 0.0, 1.0)), backend=backend)
    a_f = 0.99  # clamped MAX_ALPHA
    a_b = 1 / (1 + math.exp(-0.5))
    c_f = 0.5 + SH_C0 * np.array([1.0, 0.0, 0.0])
    c_b = 0.5 + SH_C0 * np.array([0.0, 1.0, 0.0])
    w_f, w_b = a_f, (1 - a_f) * a_b
    alpha = w_f + w_b
    expect_rgb = w_f * c_f + w_b * c_b + (1 - alpha) * np.array([0.0, 0.0, 1.0])
    assert out.rgb[16, 16].numpy() == pytest.approx(expect_rgb, abs=1e-12)
    assert float(out.alpha[16, 16]) == pytest.approx(alpha, abs=1e-12)
    assert float(out.depth_median[16, 16]) == 1.0
    assert float(out.depth_expected[16, 16]) == pytest.approx(
        (w_f * 1.0 + w_b * 2.0) / alpha, abs=1e-12
    )


@pytest.mark.parametrize("backend", ["torch", "dense"])
def test_stop_rule_drops_the_pair_that_would_end_the_pixel(backend):
    """alphas 0.99, 0.98, 0.9 at the centre: T goes 1 -> 0.01 -> 2e-4; the third would push it to
    2e-5 < 1e-4, so it is not composited and the pixel ends with alpha = 1 - 2e-4."""
    cam = one_camera()
    big = math.log(0.2)
    logit = lambda a: math.log(a / (1 - a))  # noqa: E731
    g = gaussians(
        [[0.0, 0.0, 1.0], [0.0, 0.0, 1.5], [0.0, 0.0, 2.0]],
        [big, big, big],
        [10.0, logit(0.98), logit(0.9)],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    )
    out = render(g, cam, config=RenderConfig(chunk=2), backend=backend)
    assert float(out.alpha[16, 16]) == pytest.approx(1 - 2e-4, abs=1e-12)
    c = [0.5 + SH_C0 * np.eye(3)[i] for i in range(3)]
    assert out.rgb[16, 16].numpy() == pytest.approx(0.99 * c[0] + 0.01 * 0.98 * c[1], abs=1e-12)


def test_sh_degree0_colour():
    dc = torch.tensor([[[0.7, -0.4, -3.0]]], dtype=F64)
    dirs = torch.tensor([[0.0, 0.6, 0.8]], dtype=F64)
    rgb = eval_sh(dc, dirs)
    assert rgb[0].tolist() == pytest.approx(
        [0.5 + SH_C0 * 0.7, 0.5 - SH_C0 * 0.4, 0.0]
    )  # clamped at 0


def test_sh_basis_is_orthonormal_and_matches_closed_forms():
    n = 200_000
    k = torch.arange(n, dtype=F64) + 0.5
    zc = 1 - 2 * k / n
    phi = math.pi * (1 + 5**0.5) * k
    r = torch.sqrt(1 - zc * zc)
    dirs = torch.stack([r * torch.cos(phi), r * torch.sin(phi), zc], dim=-1)  # Fibonacci sphere
    Y = sh_basis(dirs, 3)
    gram = 4 * math.pi * (Y.T @ Y) / n
    assert float((gram - torch.eye(16, dtype=F64)).abs().max()) < 1e-3
    x, y, z = dirs.unbind(-1)
    c1 = math.sqrt(3 / (4 * math.pi))
    assert torch.allclose(Y[:, 1:4], torch.stack([-c1 * y, c1 * z, -c1 * x], -1))
    c20 = math.sqrt(5 / (16 * math.pi))
    assert torch.allclose(Y[:, 6], c20 * (3 * z * z - 1))


def test_sh_colour_uses_direction_from_camera_centre():
    """A degree-1 term along +z (camera forward) changes colour with the viewing direction."""
    sh = torch.zeros(1, 4, 3, dtype=F64)
    sh[0, 2] = 1.0  # coefficient of C1 * z
    g = Gaussians(
        means=torch.tensor([[0.0, 0.0, 2.0]], dtype=F64),
        quats=torch.tensor([[1.0, 0, 0, 0]], dtype=F64),
        log_scales=torch.full((1, 3), math.log(0.2), dtype=F64),
        opacity_logits=torch.tensor([10.0], dtype=F64),
        sh=sh,
    )
    cam = one_camera()
    out = render(g, cam)
    c1 = 0.4886025119029199
    assert out.rgb[16, 16, 0].item() == pytest.approx(0.99 * (0.5 + c1 * 1.0), abs=1e-12)
    out0 = render(g, cam, config=RenderConfig(sh_degree=0))
    assert out0.rgb[16, 16, 0].item() == pytest.approx(0.99 * 0.5, abs=1e-12)


def test_quaternion_matches_scipy():
    q = torch.randn(50, 4, dtype=F64, generator=torch.Generator().manual_seed(0))
    R = quat_to_rotmat(q * 3.0)  # not normalised on purpose
    ref = Rotation.from_quat(q[:, [1, 2, 3, 0]].numpy()).as_matrix()  # scipy is (x, y, z, w)
    np.testing.assert_allclose(R.numpy(), ref, atol=1e-12)

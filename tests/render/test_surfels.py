"""2DGS surfels: normals, exact plane depth and the low-pass filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.format.render import Camera, Gaussians, RenderConfig, render

F64 = torch.float64


def surfel(mean, quat_wxyz, scales, logit=3.0) -> Gaussians:
    return Gaussians(
        means=torch.tensor([mean], dtype=F64),
        quats=torch.tensor([quat_wxyz], dtype=F64),
        log_scales=torch.log(torch.tensor([scales], dtype=F64)),
        opacity_logits=torch.tensor([logit], dtype=F64),
        sh=torch.zeros(1, 1, 3, dtype=F64),
    )


def camera(size=40, f=60.0) -> Camera:
    return Camera(
        width=size,
        height=size,
        fx=f,
        fy=f,
        cx=size / 2,
        cy=size / 2,
        T_world_cam=torch.eye(4, dtype=F64),
    )


@pytest.mark.parametrize("backend", ["torch", "dense"])
def test_facing_surfel_normal_and_plane_depth(backend):
    g = surfel([0.05, -0.03, 1.5], [1.0, 0.0, 0.0, 0.0], [0.1, 0.06])
    out = render(g, camera(), config=RenderConfig(kind="2dgs"), backend=backend)
    hit = out.alpha > 0
    assert int(hit.sum()) > 100
    # the surfel's normal is +z (away from the camera); it is flipped to face the camera
    np.testing.assert_allclose(
        out.normals[hit].numpy(), np.tile([0.0, 0.0, -1.0], (int(hit.sum()), 1)), atol=1e-12
    )
    np.testing.assert_allclose(out.depth_expected[hit].numpy(), 1.5, atol=1e-12)
    med = out.depth_median[out.alpha >= 0.5]
    assert med.numel() > 0 and torch.allclose(med, torch.tensor(1.5, dtype=F64), atol=1e-12)


@pytest.mark.parametrize("backend", ["torch", "dense"])
def test_tilted_surfel_depth_is_the_ray_plane_intersection(backend):
    rot = Rotation.from_euler("xy", [35.0, -20.0], degrees=True)
    q = rot.as_quat()  # x, y, z, w
    g = surfel([0.02, 0.01, 1.2], [q[3], q[0], q[1], q[2]], [0.12, 0.08])
    cam = camera()
    out = render(g, cam, config=RenderConfig(kind="2dgs"), backend=backend)
    n = rot.as_matrix()[:, 2]
    p = np.array([0.02, 0.01, 1.2])
    ys, xs = np.mgrid[0:40, 0:40] + 0.5
    rays = np.stack([(xs - cam.cx) / cam.fx, (ys - cam.cy) / cam.fy, np.ones_like(xs)], -1)
    t = (n @ p) / (rays @ n)  # depth of the hit (rays have z = 1)
    hit = out.alpha.numpy() > 0
    assert hit.sum() > 100
    np.testing.assert_allclose(out.depth_expected.numpy()[hit], t[hit], atol=1e-9)
    facing = -n if n @ p > 0 else n
    np.testing.assert_allclose(
        out.normals.numpy()[hit], np.tile(facing, (hit.sum(), 1)), atol=1e-12
    )


def test_edge_on_surfel_renders_through_the_low_pass_filter():
    """Seen exactly edge-on (the camera lies in the surfel's plane) no ray meets the disk in
    front of the camera; the screen-space filter (Huang et al. 2024, Eq. 11) still draws a blob
    alpha = o exp(-|x - c|^2) around the projected centre, cut at rho = 2 |x - c|^2 <= 9."""
    q = Rotation.from_euler("x", 90.0, degrees=True).as_quat()
    g = surfel([0.0, 0.0, 1.0], [q[3], q[0], q[1], q[2]], [0.1, 0.1], logit=2.0)
    cam = camera()
    a = render(g, cam, config=RenderConfig(kind="2dgs")).alpha
    b = render(g, cam, config=RenderConfig(kind="2dgs"), backend="dense").alpha
    o = 1 / (1 + math.exp(-2.0))
    ys, xs = np.mgrid[0:40, 0:40] + 0.5
    d2 = (xs - 20.0) ** 2 + (ys - 20.0) ** 2
    expect = np.where(2 * d2 <= 9, o * np.exp(-d2), 0.0)
    expect[expect < 1 / 255] = 0.0
    np.testing.assert_allclose(a.numpy(), expect, atol=1e-12)
    np.testing.assert_allclose(b.numpy(), expect, atol=1e-12)

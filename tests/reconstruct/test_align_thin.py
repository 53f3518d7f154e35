"""A thin link: the TSDF must not fatten it, and a fat one must neither scale the fit nor hide.

Issue 21 at full size: the UR5 pusher tip (a 40 x 40 mm prism) came out 70-76 mm across, its
median residual 11-15 mm, and the alignment RMS 5.4-6.1 mm against 5 mm. Two causes, each with an
oracle here: (1) with a constant weight behind the surface, views from the far side of a part
thinner than the truncation mark the voxels beyond it as inside; (2) the residual was the
distance to the nearest of 20k *samples* of the URDF mesh, not to its surface (up to the sample
spacing too high on the large links).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from robogs.format.render import Camera
from robogs.reconstruct.align import Similarity, align_to_meshes, closest_points_on_triangles
from robogs.reconstruct.tsdf import extract_mesh, fuse_tsdf

TIP = (0.04, 0.04, 0.14)  # the UR5 sample's pusher tip, m
TIP_CENTRE = np.array([0.0, 0.0, 0.32])  # it hangs 25-39 cm over the table


def test_closest_points_on_triangles_match_brute_force():
    rng = np.random.default_rng(0)
    tri = rng.normal(size=(400, 3, 3))
    p = rng.normal(size=(400, 3)) * 2.0  # every Voronoi region (vertices, edges, face) is hit
    got = closest_points_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    want = trimesh.triangles.closest_point(tri, p)
    assert np.abs(got - want).max() < 1e-9


def _similarity(seed: int) -> Similarity:
    rng = np.random.default_rng(seed)
    R = Rotation.from_rotvec(rng.normal(size=3) * 0.3).as_matrix()
    return Similarity(0.7, R, rng.normal(size=3) * 0.2)


def _links() -> dict[str, trimesh.Trimesh]:
    """Three large box links and the thin tip, at the reference pose (m)."""
    return {
        "upper": trimesh.creation.box((0.5, 0.17, 0.17)).apply_translation((0.0, 0.0, 0.3)),
        "fore": trimesh.creation.box((0.4, 0.12, 0.12)).apply_translation((0.3, 0.2, 0.6)),
        "base": trimesh.creation.box((0.15, 0.15, 0.06)).apply_translation((0.0, 0.0, 0.03)),
        "tip": trimesh.creation.box(TIP).apply_translation((0.45, 0.25, 0.45)),
    }


def test_a_fattened_thin_link_does_not_scale_the_fit_and_counts_in_the_rms():
    """Three large box links reconstructed exactly and a thin 40 mm link whose surface is pushed
    out by 10 mm (every point exactly 10 mm from the prism: a convex body's face point moved
    along its normal), all moved by a known similarity. Closed form: the fit is the inverse
    similarity, the residual is 0 on the exact links and 10 mm on the thin one, so the RMS is
    10 mm * sqrt(n_thin / n) and the median 0. The nearest-of-20k-samples residual of the old
    code read the exact links' median as ~1.5 mm (their sample spacing).

    2000 points a link (was 4000, 2.3x the CPU): the closed form holds for any sample of the
    surfaces; the fit still converges to the inverse to 1e-14 in scale and 1e-15 m, RMS 9e-6 mm
    off the closed form, on this sample and on three other sample seeds (h77). At 1000 points
    the fit stopped 1.2 mm off in translation on this seed: keep it well above that."""
    delta = 0.010
    meshes = _links()
    S = _similarity(1)
    inv = Similarity(1 / S.scale, S.R.T, -(S.R.T @ S.t) / S.scale)
    pts = {}
    for k, (n, m) in enumerate(meshes.items()):
        p, f = trimesh.sample.sample_surface(m, 2000, seed=k)
        if n == "tip":
            p = p + delta * np.asarray(m.face_normals)[f]
        pts[n] = inv.apply(p)
    res = align_to_meshes(pts, meshes)
    back = res.transform.compose(inv)  # the identity when the fit is exact
    assert back.scale == pytest.approx(1.0, abs=5e-5)  # ICP converges linearly: 100 steps
    assert back.rotation_deg < 5e-3 and np.linalg.norm(back.t) < 1e-5
    n_thin, n = len(pts["tip"]), sum(len(p) for p in pts.values())
    assert res.rms_mm == pytest.approx(1e3 * delta * np.sqrt(n_thin / n), abs=0.01)
    assert res.median_mm < 0.01
    assert res.per_target_mm["tip"] == pytest.approx(10.0, abs=0.01)
    assert max(v for k, v in res.per_target_mm.items() if k != "tip") < 0.01


def test_parts_fattened_all_round_shift_their_offsets_not_the_scale():
    """Every link's surface pushed out (3 mm, the thin one 10 mm), as a coarse TSDF does. Closed
    form: the true pose leaves every point exactly at its link's offset, so the fit with
    per-link offsets is the inverse similarity, the offsets are (3, 3, 3, 10) mm and the RMS is
    sqrt(mean offset^2) = 5.635 mm. Point-to-point ICP alone turns the thickness into scale
    (1 % here, the camera centres of the full-size sample moved 0.5 % with the TSDF)."""
    meshes = _links()
    delta = {"upper": 0.003, "fore": 0.003, "base": 0.003, "tip": 0.010}
    S = _similarity(1)
    inv = Similarity(1 / S.scale, S.R.T, -(S.R.T @ S.t) / S.scale)
    pts = {}
    for k, (n, m) in enumerate(meshes.items()):
        p, f = trimesh.sample.sample_surface(m, 4000, seed=k)
        pts[n] = inv.apply(p + delta[n] * np.asarray(m.face_normals)[f])
    res = align_to_meshes(pts, meshes)
    back = res.transform.compose(inv)
    assert back.scale == pytest.approx(1.0, abs=1e-6)
    assert back.rotation_deg < 1e-4 and np.linalg.norm(back.t) < 1e-6
    for n, dl in delta.items():
        assert res.per_target_offset_mm[n] == pytest.approx(1e3 * dl, abs=1e-3)
    assert res.rms_mm == pytest.approx(1e3 * np.sqrt((3 * 0.003**2 + 0.010**2) / 4), abs=1e-3)
    plain = align_to_meshes(pts, meshes, offsets=False)
    assert abs(plain.transform.compose(inv).scale - 1.0) > 5e-3


def _ray_box_depth(o: np.ndarray, d: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Ray parameter of the first hit of rays o + t d [N, 3] on box [lo, hi] (inf: none); the slab
    method (Kay & Kajiya 1986)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    tn = np.nanmax(np.minimum(t1, t2), axis=1)
    tf = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tn <= tf) & (tn > 0), tn, np.inf)


def _thin_tip_views(n: int = 40, width: int = 320, height: int = 240):
    """Exact depth maps (camera z, m) of the tip over a table plane z = 0, cameras on the upper
    hemisphere 1.2 m from the tip looking at it; the tip is ~11 px wide, as at full size."""
    f = 340.0
    lo, hi = TIP_CENTRE - np.array(TIP) / 2, TIP_CENTRE + np.array(TIP) / 2
    golden = np.pi * (3 - np.sqrt(5))
    depths, cams = [], []
    for i in range(n):
        z = 0.25 + 0.7 * (i + 0.5) / n  # elevations 15-75 deg
        r = np.sqrt(1 - z * z)
        c = TIP_CENTRE + 1.2 * np.array([r * np.cos(golden * i), r * np.sin(golden * i), z])
        fwd = TIP_CENTRE - c
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        T = np.eye(4)
        T[:3, :3] = np.stack([right, down, fwd], 1)  # OpenCV axes: x right, y down, z forward
        T[:3, 3] = c
        u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        rays_c = np.stack([(u - width / 2) / f, (v - height / 2) / f, np.ones_like(u)], -1)
        rays = rays_c.reshape(-1, 3) @ T[:3, :3].T
        o = np.broadcast_to(c, rays.shape)
        t_box = _ray_box_depth(o, rays, lo, hi)
        t_plane = np.where(rays[:, 2] < 0, -c[2] / rays[:, 2], np.inf)
        t = np.minimum(t_box, t_plane)  # camera z = t (rays have unit z in the camera)
        depths.append(torch.as_tensor(np.where(np.isfinite(t), t, 0.0).reshape(height, width)))
        cams.append(
            Camera(
                width=width,
                height=height,
                fx=f,
                fy=f,
                cx=width / 2,
                cy=height / 2,
                T_world_cam=torch.as_tensor(T),
            )
        )
    return depths, cams


def _tip_width_mm(**fuse_options: float | None) -> tuple[float, float]:
    """Cross-section of the fused tip (9.4 mm voxels, 4-voxel truncation, as at full size):
    its x and y extents at mid-height, mm."""
    depths, cams = _thin_tip_views()
    lo, hi = np.array([-0.15, -0.15, -0.02]), np.array([0.15, 0.15, 0.45])
    vol = fuse_tsdf(depths, cams, lo, hi, resolution=50, **fuse_options)
    assert vol.voxel_size == pytest.approx(0.0094, abs=2e-4)
    v = np.asarray(extract_mesh(vol).vertices)
    mid = v[(np.abs(v[:, 2] - TIP_CENTRE[2]) < 0.04) & (np.abs(v[:, :2]).max(1) < 0.1)]
    assert len(mid) > 20
    return tuple(float(x) * 1e3 for x in np.ptp(mid[:, :2], axis=0))


def test_the_tsdf_does_not_fatten_a_part_thinner_than_its_truncation():
    """True depth maps, so any growth is the fusion's. With a constant weight behind the
    surface (the old fusion) the 40 mm tip comes out 45.6 x 45.9 mm here (63 x 56 mm in the
    UR5 sample's true depth maps, where more of the arm is around it); with the default
    drop-off (2 voxels) 41.1 x 40.8 mm (1 voxel: 39.8 x 39.6)."""
    new = _tip_width_mm()
    old = _tip_width_mm(dropoff_voxels=None)
    assert max(new) < 42.5, new
    assert min(old) > 44.0, old

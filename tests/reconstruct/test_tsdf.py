"""TSDF fusion and meshing on analytic shapes: depth maps ray-cast in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import trimesh

from robogs.format.render import Camera
from robogs.reconstruct.mesh_clean import clean_mesh
from robogs.reconstruct.mesh_metrics import point_metrics
from robogs.reconstruct.tsdf import extract_mesh, fuse_tsdf

W, H, F = 64, 48, 60.0


def _look_at(eye: np.ndarray) -> np.ndarray:
    z = -eye / np.linalg.norm(eye)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.95 else np.array([1.0, 0.0, 0.0])
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def _cameras(n: int = 30, dist: float = 1.0) -> list[Camera]:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = i * math.pi * (3 - math.sqrt(5))
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    return [
        Camera(
            width=W,
            height=H,
            fx=F,
            fy=F,
            cx=W / 2,
            cy=H / 2,
            T_world_cam=torch.tensor(_look_at(dist * d)),
        )
        for d in dirs
    ]


def _rays(cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    T = cam.T_world_cam.numpy()
    u = (np.arange(W) + 0.5 - cam.cx) / cam.fx
    v = (np.arange(H) + 0.5 - cam.cy) / cam.fy
    d = np.stack(np.meshgrid(u, v), -1)
    d = np.concatenate([d, np.ones((H, W, 1))], -1)  # z = 1: the ray parameter is the depth
    return T[:3, 3], d @ T[:3, :3].T


def _sphere_depth(cam: Camera, R: float) -> torch.Tensor:
    o, d = _rays(cam)
    a = (d * d).sum(-1)
    b = 2 * d @ o
    c = o @ o - R * R
    disc = b * b - 4 * a * c
    t = np.where(disc > 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 0.0)
    return torch.tensor(t, dtype=torch.float32)


def _box_depth(cam: Camera, half: np.ndarray) -> torch.Tensor:
    o, d = _rays(cam)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / d
        t2 = (half - o) / d
    tmin = np.nanmax(np.minimum(t1, t2), -1)
    tmax = np.nanmin(np.maximum(t1, t2), -1)
    return torch.tensor(np.where((tmax >= tmin) & (tmin > 0), tmin, 0.0), dtype=torch.float32)


def _surface_samples_sphere(R: float, n: int) -> np.ndarray:
    p = np.random.default_rng(0).normal(size=(n, 3))
    return R * p / np.linalg.norm(p, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def sphere_volume():
    cams = _cameras()
    depths = [_sphere_depth(c, 0.25) for c in cams]
    return fuse_tsdf(depths, cams, np.full(3, -0.32), np.full(3, 0.32), resolution=64)


def test_sphere_chamfer_within_half_a_voxel(sphere_volume):
    vol = sphere_volume
    mesh, rep = clean_mesh(extract_mesh(vol))
    assert rep.inner_shells == 0
    pts, _ = trimesh.sample.sample_surface(mesh, 20_000, seed=0)
    m = point_metrics(np.asarray(pts), _surface_samples_sphere(0.25, 20_000))
    voxel_mm = vol.voxel_size * 1e3
    assert m.chamfer_l1_mm < 0.5 * voxel_mm, (m.chamfer_l1_mm, voxel_mm)
    # outward normals and the enclosed volume of the sphere
    assert mesh.volume == pytest.approx(4 / 3 * math.pi * 0.25**3, rel=0.02)
    out = np.einsum("ij,ij->i", mesh.triangles_center, mesh.face_normals)
    assert (out > 0).mean() > 0.999


def test_narrow_band_allocates_a_fraction_of_the_grid(sphere_volume):
    vol = sphere_volume
    assert vol.allocated_voxels < 0.6 * math.prod(vol.dims)
    t, observed = vol.dense()
    assert t.shape == vol.dims and observed.sum() > 0


def test_box_chamfer_within_half_a_voxel():
    cams = _cameras()
    half = np.array([0.2, 0.12, 0.08])
    depths = [_box_depth(c, half) for c in cams]
    vol = fuse_tsdf(depths, cams, -half - 0.06, half + 0.06, resolution=64)
    mesh, _ = clean_mesh(extract_mesh(vol))
    box = trimesh.creation.box(extents=2 * half)
    ref, _ = trimesh.sample.sample_surface(box, 20_000, seed=1)
    pts, _ = trimesh.sample.sample_surface(mesh, 20_000, seed=0)
    m = point_metrics(np.asarray(pts), np.asarray(ref))
    assert m.chamfer_l1_mm < 0.5 * vol.voxel_size * 1e3, (m.chamfer_l1_mm, vol.voxel_size * 1e3)


def test_inner_shell_appears_without_erosion_and_cleaning_removes_it(sphere_volume):
    raw = extract_mesh(sphere_volume, erode=False)
    comps = raw.split(only_watertight=False)
    assert len(comps) >= 2  # the truncation boundary behind the surface
    cleaned, rep = clean_mesh(raw)
    assert rep.inner_shells >= 1
    r = np.linalg.norm(cleaned.vertices, axis=1)
    assert np.median(np.abs(r - 0.25)) < 0.5 * sphere_volume.voxel_size


def test_empty_depths_are_refused():
    from robogs.format.errors import InputError

    cams = _cameras(3)
    with pytest.raises(InputError, match="no depth map has a valid pixel"):
        fuse_tsdf([torch.zeros(H, W)] * 3, cams, np.full(3, -0.3), np.full(3, 0.3), resolution=32)


def test_narrow_band_gives_the_dense_grid_result(sphere_volume):
    cams = _cameras()
    depths = [_sphere_depth(c, 0.25) for c in cams]
    dense = fuse_tsdf(
        depths, cams, np.full(3, -0.32), np.full(3, 0.32), resolution=64, narrow_band=False
    )
    assert dense.allocated_voxels == math.prod(dense.dims) > sphere_volume.allocated_voxels
    a, b = extract_mesh(sphere_volume), extract_mesh(dense)
    assert len(a.faces) == len(b.faces)
    assert np.allclose(np.sort(a.vertices, axis=0), np.sort(b.vertices, axis=0), atol=1e-9)


def _outward(mesh: trimesh.Trimesh) -> float:
    """Fraction of the faces of a mesh around the origin whose normal points away from it."""
    return float((np.einsum("ij,ij->i", mesh.triangles_center, mesh.face_normals) > 0).mean())


def test_cleaning_drops_small_parts_and_turns_every_face_to_free_space(sphere_volume):
    raw = extract_mesh(sphere_volume)
    ref = _outward(raw)  # marching cubes faces free space (all but a sliver at most)
    assert ref > 0.9999
    rng = np.random.default_rng(5)
    faces = np.asarray(raw.faces).copy()
    flip = rng.random(len(faces)) < 0.3  # inconsistent winding, face 0 included
    flip[0] = True
    faces[flip] = faces[flip][:, ::-1]
    floater = trimesh.creation.icosphere(subdivisions=0, radius=0.01).apply_translation([0.28] * 3)
    scrambled = trimesh.util.concatenate(
        [trimesh.Trimesh(raw.vertices, faces, process=False), floater]
    )
    kw = {"free_space": sphere_volume.sample, "probe_m": sphere_volume.voxel_size}
    for opts in (kw, {}):  # by the TSDF, and (closed surface) by the volume
        cleaned, rep = clean_mesh(scrambled, **opts)
        assert rep.small_components == 1 and rep.components_in == 2
        assert cleaned.is_winding_consistent and _outward(cleaned) >= ref, opts
        assert np.median(np.abs(np.linalg.norm(cleaned.vertices, axis=1) - 0.25)) < 2e-3
    # an open sheet (the upper cap) wound inwards: only the TSDF can tell its outside
    cap = raw.submesh([np.flatnonzero(raw.triangles_center[:, 2] > 0.1)], append=True)
    cap = trimesh.Trimesh(cap.vertices, np.asarray(cap.faces)[:, ::-1], process=False)
    assert _outward(cap) < 0.001
    cleaned, rep = clean_mesh(cap, fill_holes=False, **kw)
    assert rep.flipped == 1 and _outward(cleaned) > 0.999


def test_depth_edges_are_dropped_and_planes_kept():
    from robogs.reconstruct.tsdf import drop_depth_edges

    # a 1 m plate in front of a 2 m wall: the pixels on both sides of the step go, and the
    # background's border with "no depth" (0) too; a plane sloping 2 % per pixel stays
    d = torch.full((20, 30), 2.0)
    d[5:15, 10:20] = 1.0
    d[:, 27:] = 0.0
    out = drop_depth_edges(d)
    edge = torch.zeros_like(d, dtype=torch.bool)
    edge[[5, 14], 10:20] = edge[5:15, [10, 19]] = True  # the plate's border ring
    edge[[4, 15], 10:20] = edge[5:15, [9, 20]] = True  # the wall's pixels beside it
    edge[:, 26] = True  # the wall's last column before "no depth"
    assert torch.equal(out == 0, edge | (d == 0))
    assert torch.equal(out[~(out == 0)], d[~(out == 0)])
    ramp = 1.0 + 0.02 * torch.arange(30.0)[None].expand(20, 30)
    assert torch.equal(drop_depth_edges(ramp), ramp)

"""Space carving shrinks the visual hull of a textured plane seen from above to the plane.

Views are ray-cast in closed form (a 0.6 m square at z = 0 with a 0.1 m checkerboard, cameras on
the upper hemisphere only), and the visual hull is carved by a brute-force loop here: the hull is
a slab above the plane (and a cone below it), which silhouettes cannot remove.
"""

from __future__ import annotations

import math
import sys

import numpy as np
import torch

from robogs.format.render import Camera
from robogs.reconstruct.carve import carve_photo_hull, refine_along_normals
from robogs.reconstruct.views import View

W, H, F = 96, 72, 90.0
HALF, TILE = 0.3, 0.1
COLOURS = np.array([[0.8, 0.3, 0.2], [0.2, 0.35, 0.8]])


def _look_at(eye: np.ndarray) -> np.ndarray:
    z = -eye / np.linalg.norm(eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, eye
    return T


def _view(i: int, elev_deg: float, azim_deg: float, textured: bool) -> View:
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    T = _look_at(
        1.0 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    )
    u = (np.arange(W) + 0.5 - W / 2) / F
    v = (np.arange(H) + 0.5 - H / 2) / F
    d = np.stack(np.meshgrid(u, v), -1)
    d = np.concatenate([d, np.ones((H, W, 1))], -1) @ T[:3, :3].T
    t = -T[2, 3] / d[..., 2]
    p = T[:3, 3] + t[..., None] * d
    hit = (t > 0) & (np.abs(p[..., 0]) < HALF) & (np.abs(p[..., 1]) < HALF)
    tone = (np.floor(p[..., 0] / TILE) + np.floor(p[..., 1] / TILE)).astype(int) % 2
    rgb = np.where(hit[..., None], COLOURS[tone if textured else np.zeros_like(tone)], 0.0)
    cam = Camera(width=W, height=H, fx=F, fy=F, cx=W / 2, cy=H / 2, T_world_cam=torch.tensor(T))
    rgb_t = torch.tensor(rgb, dtype=torch.float32)
    return View(f"c/{i}", "c", i, i, cam, rgb_t, hit.astype(np.int64))


def _views(textured: bool = True) -> list[View]:
    """48 views on the upper hemisphere (elevations 30-82 deg), neighbours 13-30 deg apart."""
    out = []
    for k, elev in enumerate((30.0, 43.0, 56.0, 69.0, 82.0)):
        m = (14, 12, 10, 8, 4)[k]
        for j in range(m):
            out.append(_view(len(out), elev, 360.0 * j / m + 11.0 * k, textured))
    return out


def _visual_hull(views: list[View], lo: np.ndarray, vox: float, n: int) -> np.ndarray:
    """Brute force: a voxel centre survives unless a view sees it against the background."""
    ijk = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1).reshape(-1, 3)
    c = lo + (ijk + 0.5) * vox
    occ = np.ones(len(c), bool)
    for v in views:
        T = v.camera.T_world_cam.numpy()
        pc = (c - T[:3, 3]) @ T[:3, :3]
        col = np.floor(F * pc[:, 0] / pc[:, 2] + W / 2).astype(int)
        row = np.floor(F * pc[:, 1] / pc[:, 2] + H / 2).astype(int)
        inside = (pc[:, 2] > 0) & (col >= 0) & (col < W) & (row >= 0) & (row < H)
        lab = v.labels[row.clip(0, H - 1), col.clip(0, W - 1)]
        occ &= ~inside | (lab > 0)
    return occ.reshape(n, n, n)


def _centres(mask: np.ndarray, lo: np.ndarray, vox: float) -> np.ndarray:
    return lo + (np.argwhere(mask) + 0.5) * vox


def test_carving_a_textured_plane_leaves_the_plane():
    views = _views()
    n, lo = 40, np.array([-0.36, -0.36, -0.36])
    vox = 0.72 / n
    hull = _visual_hull(views, lo, vox, n)
    hc = _centres(hull, lo, vox)
    above = hc[(np.abs(hc[:, :2]) < 0.2).all(1)]
    assert above[:, 2].max() > 5 * vox  # the silhouettes leave a slab above the plane
    res = carve_photo_hull(hull, lo, vox, views, known=set(), tau=0.03)
    assert res.carved > 0 and res.iterations > 1
    # away from the border, the confirmed surface is within 1.5 voxels of the plane, but for
    # tile interiors, where voxels above are photo-consistent too
    conf = _centres(res.confirmed, lo, vox)
    mid = conf[(np.abs(conf[:, :2]) < 0.2).all(1)]
    assert (np.abs(mid[:, 2]) < 1.6 * vox).mean() > 0.7
    assert np.abs(mid[:, 2]).max() < 4 * vox
    # and it covers the plane: the 2 cm cells of the central 0.4 m square
    cells = {tuple(c) for c in np.floor(conf[:, :2] / 0.02).astype(int)}
    grid = [(i, j) for i in range(-10, 10) for j in range(-10, 10)]
    assert np.mean([c in cells for c in grid]) > 0.9
    # what is left stands on the plane or below it: the slab is gone
    left = _centres(res.occupancy, lo, vox)
    left_above = left[(np.abs(left[:, :2]) < 0.2).all(1)]
    assert (left_above[:, 2] > 1.5 * vox).mean() < 0.25 and left_above[:, 2].max() <= 4 * vox


def test_a_textureless_plane_is_not_carved_below_its_hull():
    # a uniform colour is photo-consistent at any height: carving must not dig into it
    views = _views(textured=False)
    n, lo = 40, np.array([-0.36, -0.36, -0.36])
    vox = 0.72 / n
    hull = _visual_hull(views, lo, vox, n)
    res = carve_photo_hull(hull, lo, vox, views, known=set(), tau=0.03)
    assert res.carved == 0 and (res.occupancy == hull).all()


def test_labels_of_known_parts_occlude_and_mismatched_labels_carve():
    views = _views()
    n, lo = 40, np.array([-0.36, -0.36, -0.36])
    vox = 0.72 / n
    hull = _visual_hull(views, lo, vox, n)
    # every pixel labelled as a known part: no view may judge any voxel
    known = carve_photo_hull(hull, lo, vox, views, known={1}, tau=0.03)
    assert known.carved == 0 and not known.confirmed.any()
    # two labels split along x = 0 with a uniform colour: only the labels can carve the slab
    flat = _views(textured=False)
    for v in flat:
        T = v.camera.T_world_cam.numpy()
        u = (np.arange(W) + 0.5 - W / 2) / F
        w = (np.arange(H) + 0.5 - H / 2) / F
        d = np.concatenate([np.stack(np.meshgrid(u, w), -1), np.ones((H, W, 1))], -1) @ T[:3, :3].T
        x = T[0, 3] - T[2, 3] / d[..., 2] * d[..., 0]
        v.labels = np.where(v.labels > 0, np.where(x < 0, 1, 2), 0)
    res = carve_photo_hull(hull, lo, vox, flat, known=set(), tau=0.03)
    assert res.carved > 0

    def top_over_split(centres: np.ndarray) -> float:
        on = (np.abs(centres[:, 0]) < vox) & (np.abs(centres[:, 1]) < 0.1)
        return float(centres[on, 2].max())

    assert top_over_split(_centres(hull, lo, vox)) > 5 * vox
    assert top_over_split(_centres(res.occupancy, lo, vox)) < 3 * vox  # the slab is carved


def _box_view(i: int, eye: np.ndarray, half: np.ndarray) -> View:
    """A box with one flat shade per face (Lambert-like), ray-cast; label 1."""
    T = _look_at(eye)
    u = (np.arange(W) + 0.5 - W / 2) / F
    v = (np.arange(H) + 0.5 - H / 2) / F
    d = np.concatenate([np.stack(np.meshgrid(u, v), -1), np.ones((H, W, 1))], -1) @ T[:3, :3].T
    o = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    tnear = np.minimum(t1, t2)
    tmin, tmax = np.nanmax(tnear, -1), np.nanmin(np.maximum(t1, t2), -1)
    hit = (tmax >= tmin) & (tmin > 0)
    axis = np.nanargmax(tnear, -1)  # the slab entered last is the face hit
    sign = np.take_along_axis(np.sign(-d), axis[..., None], -1)[..., 0] > 0
    shade = 0.35 + 0.1 * axis + 0.25 * sign  # six distinct shades
    rgb = np.where(hit[..., None], shade[..., None] * np.array([0.3, 1.0, 0.4]), 0.0)
    cam = Camera(width=W, height=H, fx=F, fy=F, cx=W / 2, cy=H / 2, T_world_cam=torch.tensor(T))
    return View(
        f"b/{i}", "b", i, i, cam, torch.tensor(rgb, dtype=torch.float32), hit.astype(np.int64)
    )


def test_a_box_seen_from_all_around_keeps_its_shaded_edges():
    # an edge voxel shows one face to some views and another to the rest; far-apart views
    # disagree about it although it is on the surface. Comparing only neighbouring views keeps it
    half = np.array([0.1, 0.08, 0.06])
    i = np.arange(48) + 0.5
    z = 1 - 2 * i / 48
    phi = i * math.pi * (3 - math.sqrt(5))
    dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1)
    dirs[:, 2] = np.clip(dirs[:, 2], -0.95, 0.95)  # keep the look-at up vector valid
    views = [_box_view(k, 0.8 * d / np.linalg.norm(d), half) for k, d in enumerate(dirs)]
    n, lo = 40, np.array([-0.16, -0.16, -0.16])
    vox = 0.32 / n
    hull = _visual_hull(views, lo, vox, n)
    inside = (np.abs(_centres(hull, lo, vox)) < half - vox).all(1)
    assert inside.sum() > 100
    res = carve_photo_hull(hull, lo, vox, views, known=set(), tau=0.03)
    left = res.occupancy[tuple(np.argwhere(hull)[inside].T)]
    assert left.all()  # nothing inside the true box is carved
    assert res.occupancy.sum() > 0.9 * hull.sum()
    # comparing every pair of views instead eats the box away
    eaten = carve_photo_hull(hull, lo, vox, views, known=set(), tau=0.03, max_angle_deg=180.0)
    assert eaten.occupancy[tuple(np.argwhere(hull)[inside].T)].mean() < 0.5


def _plane_seeds(z: float) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(-0.15, 0.151, 0.03)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    pts = np.column_stack([xy, np.full(len(xy), z)])
    return pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1))


def test_refinement_slides_seeds_onto_a_textured_plane(monkeypatch):
    # a finer checker (4 cm, ~3.6 px) than the carving tests': the sweep needs texture under
    # the seed; seeds 0.7 voxel above or 0.5 below the plane come to the nearest of the 9
    # offsets (quarter-voxel steps) to the plane
    monkeypatch.setattr(sys.modules[__name__], "TILE", 0.04)
    views = _views()
    vox = 0.018
    for z0, want in ((0.7 * vox, -0.75 * vox), (-0.5 * vox, 0.5 * vox)):
        pts, nrm = _plane_seeds(z0)
        moved, delta = refine_along_normals(pts, nrm, views, vox)
        assert np.allclose(moved[:, :2], pts[:, :2])
        assert np.allclose(moved[:, 2], z0 + delta)
        assert np.mean(np.isclose(delta, want)) > 0.8, delta / vox
        assert np.median(np.abs(moved[:, 2])) <= 0.25 * vox


def test_refinement_leaves_a_textureless_plane_and_normal_less_seeds():
    views = _views(textured=False)
    pts, nrm = _plane_seeds(0.7 * 0.018)
    _, delta = refine_along_normals(pts, nrm, views, 0.018)
    assert (delta == 0).all()  # every offset agrees: nothing to prefer
    nrm[:] = np.nan
    _, delta = refine_along_normals(pts, nrm, _views(), 0.018)
    assert (delta == 0).all()

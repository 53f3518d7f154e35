"""The support plane: a noisy tabletop with a rim of a box's wall, and a box on it.

Oracle: the plane the mesh was built on (height, tilt), the noise it was given, and which
vertices lie above or below it by construction.
"""

from __future__ import annotations

import numpy as np
import trimesh

from robogs.reconstruct.support import fit_support_plane, flatten_table, rest_on_plane

H = 0.012  # table top height, m
SIGMA = 0.002  # vertical noise of the top, m


def _table(tilt_deg: float = 0.0, seed: int = 0) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A 1 x 0.8 m top at height H tilted about y, with noise; a 2 cm rim of wall at x > 0.45
    (the bit of a box's wall that won the vote). Returns the mesh and its true unit normal."""
    rng = np.random.default_rng(seed)
    g = np.linspace(-0.5, 0.5, 81), np.linspace(-0.4, 0.4, 65)
    xy = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 2)
    a = np.radians(tilt_deg)
    z = H + np.tan(a) * xy[:, 0] + rng.normal(0.0, SIGMA, len(xy))
    verts = np.column_stack([xy, z])
    nx, ny = len(g[0]), len(g[1])
    idx = np.arange(nx * ny).reshape(nx, ny)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    faces = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    # a vertical rim at x = 0.45..0.5, y in [-0.05, 0.05], 2 cm up
    ry = np.linspace(-0.05, 0.05, 6)
    rim = np.array([[0.47, y, H + h] for h in (0.005, 0.02) for y in ry])
    base = len(verts)
    rf = [[base + i, base + i + 1, base + 6 + i] for i in range(5)]
    rf += [[base + i + 1, base + 7 + i, base + 6 + i] for i in range(5)]
    m = trimesh.Trimesh(np.concatenate([verts, rim]), np.concatenate([faces, rf]), process=False)
    n = np.array([-np.sin(a), 0.0, np.cos(a)])
    return m, n


def test_a_level_noisy_top_is_fitted_levelled_at_its_height():
    m, _ = _table()
    plane, tilt = fit_support_plane(m.vertices, m.vertex_normals)
    assert tilt < 0.5
    assert np.allclose(plane.normal, [0, 0, 1])
    assert abs(plane.offset - H) < 3 * SIGMA / np.sqrt(plane.inliers) + 1e-4
    assert abs(plane.sigma - SIGMA) < 0.2 * SIGMA


def test_a_tilted_top_keeps_its_tilt():
    m, n = _table(tilt_deg=4.0)
    plane, tilt = fit_support_plane(m.vertices, m.vertex_normals)
    assert abs(tilt - 4.0) < 0.1 and abs(plane.tilt_deg - 4.0) < 0.1
    assert np.degrees(np.arccos(plane.normal @ n)) < 0.1


def test_flattening_puts_the_top_on_the_plane_and_drops_the_rim():
    m, _ = _table()
    plane, _ = fit_support_plane(m.vertices, m.vertex_normals)
    flat, moved, dropped = flatten_table(m, plane)
    top = flat.vertices
    assert abs(top[:, 2].max() - plane.offset) < 1e-9  # nothing above the plane is left
    assert moved >= 0.99 * (len(m.vertices) - 12)  # the noisy top, within 3.5 sigma
    assert dropped >= 5  # the rim's upper faces (2 cm up, far outside the band)
    # a box standing on it: its vertices below the plane move onto it, the rest stay
    box = trimesh.creation.box(extents=(0.1, 0.08, 0.06))
    box.apply_translation([0.3, 0.0, H + 0.03 - 0.004])  # its bottom 4 mm into the top
    rested, n = rest_on_plane(box, plane)
    assert n == 4  # the four bottom corners
    assert abs(rested.vertices[:, 2].min() - plane.offset) < 1e-12
    assert np.allclose(np.sort(rested.vertices[:, 2])[4:], np.sort(box.vertices[:, 2])[4:])


def test_no_upward_faces_no_plane():
    wall = trimesh.creation.box(extents=(0.001, 0.5, 0.5))
    side = wall.vertices[:, 0] > 0
    assert fit_support_plane(wall.vertices[side], np.tile([1.0, 0, 0], (side.sum(), 1))) is None

"""Clean a fused mesh: drop inner shells and small components, fill small holes, orient normals.

2DGS (Huang et al. 2024, ``post_process_mesh``) keeps the largest clusters of connected
triangles; a scene holds several objects, so here every component with at least
``min_fraction`` of the faces (and ``min_faces`` faces) stays. Components with a negative signed
volume are inner shells: marching cubes orients faces towards free space (positive TSDF), so a
shell facing inwards is the truncation boundary behind a surface, not a surface. A component
counts as an inner shell only when its volume is negative *and* its bounding box lies inside
that of a larger component with a positive volume: an open sheet (a table top seen from above)
has no meaningful inside, and its volume sign says nothing.

**Orientation.** Each component's winding is made consistent (``trimesh.repair.fix_winding``:
adjacent faces traverse their shared edge in opposite directions), then the component is
turned to face free space: with ``free_space`` (the fused TSDF, positive in front of the
surface), by the majority of its faces over ``sign(f(c + h n) - f(c - h n))`` at the face centres
c, which also orients open sheets; without it, closed components by the sign of their volume.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["CleanReport", "clean_mesh"]


@dataclass
class CleanReport:
    """What cleaning removed (``fragments``: faces of a link's or object's small pieces, removed
    after segmentation by ``segment.drop_fragments``)."""

    components_in: int
    inner_shells: int
    small_components: int
    faces_in: int
    faces_out: int
    flipped: int = 0
    fragments: int = 0


def clean_mesh(
    mesh: trimesh.Trimesh,
    *,
    min_fraction: float = 0.005,
    min_faces: int = 50,
    fill_holes: bool = True,
    free_space: Callable[[np.ndarray], np.ndarray] | None = None,
    probe_m: float = 0.0,
) -> tuple[trimesh.Trimesh, CleanReport]:
    """Clean ``mesh`` (not modified); returns the cleaned copy and a report.

    Args:
        mesh: the marching-cubes mesh, m.
        min_fraction, min_faces: components with fewer faces than both are dropped.
        fill_holes: fill small holes (``trimesh.repair.fill_holes``).
        free_space: signed distance (any scale) at world points [N, 3] -> [N], positive in free
            space (e.g. :meth:`TSDFVolume.sample`); None: orient closed components by volume.
        probe_m: step along the face normals for ``free_space``, m (about one voxel).
    """
    n_in = len(mesh.faces)
    if n_in == 0:
        return mesh.copy(), CleanReport(0, 0, 0, 0, 0)
    m = mesh.copy()
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces())
    m.remove_unreferenced_vertices()
    parts = sorted(m.split(only_watertight=False), key=lambda p: -len(p.faces))
    total = sum(len(p.faces) for p in parts)
    keep, inner, small, flipped = [], 0, 0, 0
    outer_boxes: list[np.ndarray] = []
    for p in parts:
        if len(p.faces) < max(min_faces, min_fraction * total):
            small += 1
            continue
        trimesh.repair.fix_winding(p)
        vol = _signed_volume(p)
        if vol < 0 and any(_box_inside(p.bounds, b) for b in outer_boxes):
            inner += 1
            continue
        if _facing(p, free_space, probe_m) < 0:
            # a new mesh, not ``invert()``: trimesh 5.2 keeps stale face normals after it
            p = trimesh.Trimesh(p.vertices, np.asarray(p.faces)[:, ::-1], process=False)
            flipped += 1
            vol = -vol
        if vol > 0:
            outer_boxes.append(p.bounds)
        keep.append(p)
    if not keep:
        out = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), process=False)
        return out, CleanReport(len(parts), inner, small, n_in, 0, flipped)
    out = trimesh.util.concatenate(keep)
    if fill_holes:
        trimesh.repair.fill_holes(out)
        trimesh.repair.fix_winding(out)  # filled faces follow their oriented neighbours
    return out, CleanReport(len(parts), inner, small, n_in, len(out.faces), flipped)


def _facing(
    p: trimesh.Trimesh, free_space: Callable[[np.ndarray], np.ndarray] | None, probe_m: float
) -> float:
    """> 0 when the (consistently wound) component faces free space, < 0 when it faces away."""
    if free_space is not None and probe_m > 0:
        c, n = np.asarray(p.triangles_center), np.asarray(p.face_normals)
        d = free_space(c + probe_m * n) - free_space(c - probe_m * n)
        return float(np.sign(d).sum())
    if p.is_watertight:
        return _signed_volume(p)
    return 0.0


def _box_inside(inner: np.ndarray, outer: np.ndarray) -> bool:
    """Axis-aligned box [2, 3] ``inner`` within ``outer``."""
    return bool((inner[0] >= outer[0]).all() and (inner[1] <= outer[1]).all())


def _signed_volume(m: trimesh.Trimesh) -> float:
    """Signed volume about the centroid (divergence theorem; meaningful for nearly closed surfaces), m^3."""
    tri = m.triangles - m.vertices.mean(axis=0)
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)

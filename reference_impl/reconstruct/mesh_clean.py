"""Clean a fused mesh: drop inner shells and small components, fill small holes, orient normals.

2DGS (Huang et al. 2024, ``post_process_mesh``) keeps the largest clusters of connected
triangles; a scene holds several objects, so here every component with at least
``min_fraction`` of the faces (and ``min_faces`` faces) stays. Components with a negative signed
volume are inner shells: marching cubes orients faces towards free space (positive TSDF), so a
shell facing inwards is the truncation boundary behind a surface, not a surface. A component
counts as an inner shell only when its volume is negative *and* its bounding box lies inside
that of a larger component with a positive volume: an open sheet (a table top seen from above)
has no meaningful inside, and its volume sign says nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["CleanReport", "clean_mesh"]


@dataclass
class CleanReport:
    """What cleaning removed."""

    components_in: int
    inner_shells: int
    small_components: int
    faces_in: int
    faces_out: int


def clean_mesh(
    mesh: trimesh.Trimesh,
    *,
    min_fraction: float = 0.005,
    min_faces: int = 50,
    fill_holes: bool = True,
) -> tuple[trimesh.Trimesh, CleanReport]:
    """Clean ``mesh`` (not modified); returns the cleaned copy and a report."""
    n_in = len(mesh.faces)
    if n_in == 0:
        return mesh.copy(), CleanReport(0, 0, 0, 0, 0)
    m = mesh.copy()
    m.merge_vertices()
    m.update_faces(m.nondegenerate_faces())
    m.remove_unreferenced_vertices()
    parts = sorted(m.split(only_watertight=False), key=lambda p: -len(p.faces))
    total = sum(len(p.faces) for p in parts)
    keep, inner, small = [], 0, 0
    outer_boxes: list[np.ndarray] = []
    for p in parts:
        if len(p.faces) < max(min_faces, min_fraction * total):
            small += 1
            continue
        vol = _signed_volume(p)
        if vol < 0 and any(_box_inside(p.bounds, b) for b in outer_boxes):
            inner += 1
            continue
        if vol > 0:
            outer_boxes.append(p.bounds)
        keep.append(p)
    if not keep:
        out = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), process=False)
        return out, CleanReport(len(parts), inner, small, n_in, 0)
    out = trimesh.util.concatenate(keep)
    if fill_holes:
        trimesh.repair.fill_holes(out)
    trimesh.repair.fix_winding(out)
    return out, CleanReport(len(parts), inner, small, n_in, len(out.faces))


def _box_inside(inner: np.ndarray, outer: np.ndarray) -> bool:
    """Axis-aligned box [2, 3] ``inner`` within ``outer``."""
    return bool((inner[0] >= outer[0]).all() and (inner[1] <= outer[1]).all())


def _signed_volume(m: trimesh.Trimesh) -> float:
    """Signed volume about the centroid (divergence theorem; meaningful for nearly closed surfaces), m^3."""
    tri = m.triangles - m.vertices.mean(axis=0)
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)

"""The pusher: URDF collision geometry of a link as the model's sphere or capsule.

Every collision element of a link becomes a *swept sphere*: a segment ``a..b`` in the link
frame and a radius ``r`` (a sphere is a zero-length segment; a cylinder or capsule its axis; a
box its longest axis with the half thickness as radius; a mesh its principal axis with the
largest vertex distance from that axis as radius). Distances from an object centre to the
shape are point-to-segment distances minus ``r``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.urdf import capsules

__all__ = ["Shape", "collision_shapes", "segment_param", "shape_distance"]


@dataclass(frozen=True)
class Shape:
    """A swept sphere in a link frame.

    Attributes:
        link: URDF link name.
        kind: the URDF geometry (``sphere``, ``cylinder``, ``capsule``, ``box``, ``mesh``).
        a, b: [3] segment ends in the link frame [m] (equal for a sphere).
        radius: [m].
        note: how the geometry was reduced (empty for sphere, cylinder, capsule).
    """

    link: str
    kind: str
    a: np.ndarray
    b: np.ndarray
    radius: float
    note: str = ""

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.b - self.a))


def _origin(el: Any) -> np.ndarray:
    """4x4 of a yourdfpy origin (None: identity)."""
    return np.eye(4) if el is None else np.asarray(el, dtype=float)


def _segment(T: np.ndarray, half: float, axis: int = 2) -> tuple[np.ndarray, np.ndarray]:
    u = T[:3, axis] * half
    return T[:3, 3] - u, T[:3, 3] + u


def _mesh_shape(link: str, mesh: Any, T: np.ndarray) -> Shape:
    v = np.asarray(mesh.vertices, dtype=float) @ T[:3, :3].T + T[:3, 3]
    c = v.mean(axis=0)
    _, s, vt = np.linalg.svd(v - c, full_matrices=False)
    ext = np.ptp((v - c) @ vt.T, axis=0)
    if ext[0] < 1.3 * ext[2]:  # roughly round: a sphere around the centroid
        r = float(np.linalg.norm(v - c, axis=1).max())
        return Shape(link, "mesh", c, c, r, "mesh -> bounding sphere")
    u = vt[0]
    t = (v - c) @ u
    radial = np.linalg.norm((v - c) - t[:, None] * u, axis=1)
    r = float(radial.max())
    half = max(0.0, 0.5 * float(np.ptp(t)) - r)
    mid = c + u * 0.5 * (t.max() + t.min())
    return Shape(link, "mesh", mid - half * u, mid + half * u, r, "mesh -> capsule on its axis")


def collision_shapes(urdf: Any, urdf_path: Path, *, mesh_loader: Any = None) -> list[Shape]:
    """Swept spheres of every collision element of a ``yourdfpy.URDF`` (see module docstring).

    Args:
        urdf: the model (meshes need not be loaded).
        urdf_path: its file (unused; kept for callers).
        mesh_loader: ``(filename) -> trimesh.Trimesh`` for mesh collisions; None skips them.
    """
    shapes: list[Shape] = []
    for link in urdf.robot.links:
        for col in link.collisions:
            T = _origin(col.origin)
            g = col.geometry
            if g is None:
                continue
            if g.sphere is not None:
                shapes.append(
                    Shape(link.name, "sphere", T[:3, 3], T[:3, 3], float(g.sphere.radius))
                )
            elif g.cylinder is not None:
                a, b = _segment(T, 0.5 * float(g.cylinder.length))
                shapes.append(Shape(link.name, "cylinder", a, b, float(g.cylinder.radius)))
            elif g.box is not None:
                size = np.asarray(g.box.size, dtype=float)
                order = np.argsort(size)  # thin, middle, long
                r = 0.5 * float(size[order[0]])
                half = max(0.0, 0.5 * float(size[order[2]]) - r)
                a, b = _segment(T, half, int(order[2]))
                note = "box -> capsule: long axis, half thickness as radius"
                shapes.append(Shape(link.name, "box", a, b, r, note))
            elif g.mesh is not None and mesh_loader is not None:
                mesh = mesh_loader(g.mesh.filename)
                scale = g.mesh.scale
                if scale is not None:
                    mesh = mesh.copy()
                    mesh.apply_scale(np.broadcast_to(np.asarray(scale, dtype=float), 3))
                shapes.append(_mesh_shape(link.name, mesh, T))
    for cap in capsules(urdf):  # yourdfpy does not know the tag; robogs.format.urdf keeps them
        a, b = _segment(np.asarray(cap.origin, dtype=float), 0.5 * cap.length)
        shapes.append(Shape(cap.link, "capsule", a, b, cap.radius))
    return shapes


def segment_param(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Parameter in [0, 1] of the point of segment(s) ``a..b`` [..., 3] nearest to ``p`` [..., 3]."""
    ab = b - a
    den = np.sum(ab * ab, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(den > 0, np.sum((p - a) * ab, axis=-1) / np.where(den > 0, den, 1.0), 0.0)
    return np.clip(t, 0.0, 1.0)


def shape_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray:
    """Distance [m] from points ``p`` [..., 3] to the swept sphere ``a..b, radius`` (world)."""
    t = segment_param(p, a, b)[..., None]
    return np.linalg.norm(p - (a + t * (b - a)), axis=-1) - radius

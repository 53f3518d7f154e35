"""Bind Gaussians to the faces of their target's mesh (the Gaussian–Mesh binding of Robo-GS).

For a centre p and its nearest triangle (a, b, c) (``trimesh.proximity.closest_point``), the
binding stores the face index, the signed distance ``offset = (p - a) . n`` along the unit face
normal ``n = (b - a) x (c - a) / |...|`` and the barycentric weights (u, v) of vertices b and c of
the orthogonal projection ``p - offset n`` onto the face's plane. Then
``p = (1 - u - v) a + u b + v c + offset n`` holds exactly (spec §6), even where the nearest
point lies on an edge (u or v then leave [0, 1] by the tangential distance over the face size).
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["bind_to_mesh", "bound_positions"]


def bind_to_mesh(
    points: np.ndarray, mesh: trimesh.Trimesh
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face [N] int32, (u, v) [N, 2] and offset [N] (m) binding ``points`` [N, 3] to ``mesh``.

    ``points`` and ``mesh`` must be in the same frame. Points whose nearest face is degenerate
    get face -1.
    """
    pts = np.asarray(points, np.float64)
    if len(pts) == 0:
        return np.zeros(0, np.int32), np.zeros((0, 2), np.float32), np.zeros(0, np.float32)
    _, _, face = trimesh.proximity.closest_point(mesh, pts)
    face = np.asarray(face, np.int64)
    tri = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[face]]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b - a, c - a
    n = np.cross(e1, e2)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-15
    n = n / np.where(ok, norm, 1.0)[:, None]
    off = np.einsum("ij,ij->i", pts - a, n)
    q = pts - off[:, None] * n - a
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    r1, r2 = (q * e1).sum(1), (q * e2).sum(1)
    det = g11 * g22 - g12 * g12
    ok &= np.abs(det) > 1e-30
    det = np.where(ok, det, 1.0)
    u = (g22 * r1 - g12 * r2) / det
    v = (g11 * r2 - g12 * r1) / det
    face_out = np.where(ok, face, -1).astype(np.int32)
    uv = np.where(ok[:, None], np.stack([u, v], 1), 0.0).astype(np.float32)
    return face_out, uv, np.where(ok, off, 0.0).astype(np.float32)


def bound_positions(
    mesh: trimesh.Trimesh, face: np.ndarray, uv: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """Positions [N, 3] that a binding describes (the inverse of :func:`bind_to_mesh`)."""
    tri = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[face]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    w = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], 1)
    return np.einsum("nk,nkd->nd", w, tri) + offset[:, None].astype(np.float64) * n

"""The support surface: a plane ``n . x = d`` (world frame, m) under the objects.

Two sources: the top face of a table mesh under the objects (:func:`plane_from_mesh`), or a
robust total-least-squares fit to the objects' bottom-face centres at rest
(:func:`fit_plane`). Total least squares: the plane through the centroid whose normal is the
singular vector of the smallest singular value (Pearson 1901, "On lines and planes of closest
fit"); outliers beyond 3.5 robust sigmas are dropped and the fit repeated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.format.errors import InputError

__all__ = ["Plane", "fit_plane", "plane_from_mesh"]


@dataclass(frozen=True)
class Plane:
    """A plane ``normal . x = offset`` (world, m), normal pointing up (+z side).

    Attributes:
        normal: [3] unit normal.
        offset: d [m].
        sigma: 1-sigma uncertainty of the plane height at its centroid [m] (0 for a mesh).
        point: [3] a point of the plane near the data (its centroid) [m].
        n_points: number of points the fit kept (0 for a mesh).
    """

    normal: np.ndarray
    offset: float
    sigma: float
    point: np.ndarray
    n_points: int = 0

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """z of the plane at world (x, y) points [..., 2] [m]."""
        n = self.normal
        return (self.offset - xy[..., 0] * n[0] - xy[..., 1] * n[1]) / n[2]

    @property
    def tilt_deg(self) -> float:
        """Angle between the normal and world +z [deg]."""
        return float(np.degrees(np.arccos(np.clip(self.normal[2], -1.0, 1.0))))


def _up(n: np.ndarray) -> np.ndarray:
    n = n / np.linalg.norm(n)
    return -n if n[2] < 0 else n


def fit_plane(
    points: np.ndarray, *, normal_hint: np.ndarray | None = None, min_spread: float = 0.02
) -> Plane:
    """Robust plane through ``points`` [N, 3] (m).

    When the points span less than ``min_spread`` m in their second principal direction (an
    object that only rested in one place) the normal cannot come from them: ``normal_hint``
    (e.g. the mean up axis of the resting objects) is used and only the offset is fitted.

    Raises:
        InputError: fewer than 3 points, or a degenerate spread without a hint.
    """
    p = np.asarray(points, dtype=float)
    if len(p) < 3:
        raise InputError(f"{len(p)} resting samples are too few to fit the support plane")
    keep = np.ones(len(p), dtype=bool)
    for _ in range(4):
        q = p[keep]
        c = q.mean(axis=0)
        _, s, vt = np.linalg.svd(q - c, full_matrices=False)
        spread = s[1] / np.sqrt(len(q))
        if spread >= min_spread:
            n = _up(vt[2])
        elif normal_hint is not None:
            n = _up(np.asarray(normal_hint, dtype=float))
        else:
            raise InputError(
                f"the resting samples span {spread * 1000:.0f} mm: too little to fit a plane",
                hint="push the object to more places, or give the table as a mesh asset",
            )
        r = p @ n - float(np.median(q @ n))
        mad = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        new = np.abs(r - np.median(r[keep])) <= max(3.5 * mad, 1e-4)
        if np.array_equal(new, keep):
            break
        keep = new
    q = p[keep]
    d = float(np.mean(q @ n))
    res = q @ n - d
    sigma = float(np.std(res) / np.sqrt(max(len(q), 1)))
    return Plane(n, d, sigma, q.mean(axis=0), int(keep.sum()))


def plane_from_mesh(vertices: np.ndarray, faces: np.ndarray, above: np.ndarray) -> Plane | None:
    """The top face of a table mesh (world-frame ``vertices`` [V, 3] m) under the point ``above``.

    Among the upward-facing triangles (normal within 30 deg of +z) whose vertical projection
    contains ``above`` (x, y) and that lie below it, the highest one gives the plane (its normal
    and offset). Returns None when no face of the mesh lies under the point.
    """
    tri = vertices[faces]  # [F, 3, 3]
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-12
    nrm[ok] /= length[ok, None]
    up = ok & (nrm[:, 2] > np.cos(np.radians(30.0)))
    best, best_z = None, -np.inf
    x, y, z = (float(v) for v in above)
    for i in np.flatnonzero(up):
        a, b, c = tri[i]
        # barycentric coordinates of (x, y) in the projected triangle
        m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
        det = np.linalg.det(m)
        if abs(det) < 1e-14:
            continue
        u, v = np.linalg.solve(m, [x - a[0], y - a[1]])
        if u < -1e-9 or v < -1e-9 or u + v > 1 + 1e-9:
            continue
        zf = a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2])
        if zf < z and zf > best_z:
            best, best_z = i, zf
    if best is None:
        return None
    n = nrm[best]
    return Plane(n, float(n @ tri[best, 0]), 0.0, np.array([x, y, best_z]), 0)

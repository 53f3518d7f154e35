"""The support plane of a reconstructed table, and the objects standing on it.

The table's part of the scene mesh is one TSDF surface: its top carries a few mm of noise, and
along its borders with the objects and links that stand on it, a rim of their walls that won
the label vote (a voxel or two up the wall). Its highest vertex is therefore several mm above
its top, and the objects' lowest vertices, at the junction, a few mm below: a box resting on
the table reads as sunk into it (check G011, 2 mm budget), and a physics model built on that
mesh rests the box on a bump.

As in tabletop segmentation (Rusu et al. 2009, "Close-range scene segmentation and
reconstruction of 3D point cloud maps for mobile manipulation in domestic environments",
IROS), the table is modelled by its plane and the objects are what stands above it:

* :func:`fit_support_plane`: total least squares (the normal is the singular vector of the
  smallest singular value; Pearson 1901) through the table's upward-facing vertices, refitted
  without the points beyond 3.5 robust sigmas (1.4826 x the median absolute deviation), and
  levelled when it tilts less than 1 deg (see there);
* :func:`flatten_table`: the table's vertices within the band (``band_sigmas`` robust sigmas,
  at least ``min_band_m``) of the plane move onto it; faces reaching above the band (the rim of
  what stands on the table) are dropped;
* :func:`rest_on_plane`: an object's vertices below the plane (the junction: nothing of an
  object below a table top can be seen) move onto it.

The plane's height and tilt are reported; they are measured, not imposed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["SupportPlane", "fit_support_plane", "flatten_table", "rest_on_plane"]


@dataclass(frozen=True)
class SupportPlane:
    """A plane ``normal . x = offset`` (world, m), normal pointing along ``up``.

    Attributes:
        normal: [3] unit normal.
        offset: d, m.
        sigma: robust standard deviation of the inliers' distances to the plane, m.
        inliers: points the last fit kept.
    """

    normal: np.ndarray
    offset: float
    sigma: float
    inliers: int

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance [N] of points [N, 3] (m) to the plane, positive above it."""
        return np.asarray(points, np.float64) @ self.normal - self.offset

    def project(self, points: np.ndarray) -> np.ndarray:
        """Points [N, 3] moved along the normal onto the plane (m)."""
        p = np.asarray(points, np.float64)
        return p - self.distance(p)[:, None] * self.normal

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """z [N] of the plane above world (x, y) [N, 2], m (the normal must not be horizontal)."""
        n = self.normal
        return (self.offset - xy[:, 0] * n[0] - xy[:, 1] * n[1]) / n[2]

    @property
    def tilt_deg(self) -> float:
        """Angle between the normal and world +z, degrees."""
        return float(np.degrees(np.arccos(np.clip(abs(self.normal[2]), 0.0, 1.0))))

    def to_json(self) -> dict[str, float | list[float] | int]:
        return {
            "normal": [float(x) for x in self.normal],
            "offset_m": float(self.offset),
            "sigma_mm": self.sigma * 1e3,
            "tilt_deg": self.tilt_deg,
            "inliers": int(self.inliers),
        }


def _robust_sigma(r: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


def fit_support_plane(
    points: np.ndarray,
    normals: np.ndarray,
    *,
    up: tuple[float, float, float] = (0.0, 0.0, 1.0),
    max_angle_deg: float = 30.0,
    reject_sigmas: float = 3.5,
    rounds: int = 4,
    level_deg: float = 1.0,
) -> tuple[SupportPlane, float] | None:
    """Robust plane through the points [N, 3] (m) whose unit normals [N, 3] lie within
    ``max_angle_deg`` of ``up``, and the tilt of the free fit (degrees); None with fewer than
    3 such points.

    A free fit tilted less than ``level_deg`` is levelled (normal ``up``, the same inliers):
    in the robot's world a table the robot stands on is level to within the alignment's
    accuracy (cameras within 0.3 deg on the SfM sample), and a tilt of a few tenths of a degree
    would put one end of a 1 m top several mm above the other.
    """
    up_ = np.asarray(up, np.float64) / np.linalg.norm(up)
    p = np.asarray(points, np.float64)
    ok = np.asarray(normals, np.float64) @ up_ >= np.cos(np.radians(max_angle_deg))
    p = p[ok]
    if len(p) < 3:
        return None
    keep = np.ones(len(p), bool)
    n, d, sigma = up_, 0.0, 0.0
    for _ in range(rounds):
        q = p[keep]
        c = q.mean(axis=0)
        n = np.linalg.svd(q - c, full_matrices=False)[2][2]
        n = -n if n @ up_ < 0 else n
        d = float(n @ c)
        r = p @ n - d
        sigma = _robust_sigma(r[keep])
        new = np.abs(r - np.median(r[keep])) <= reject_sigmas * max(sigma, 1e-9)
        if new.sum() < 3 or (new == keep).all():
            break
        keep = new
    tilt = float(np.degrees(np.arccos(np.clip(n @ up_, -1.0, 1.0))))
    if tilt < level_deg:
        n = up_
        r = p[keep] @ n
        d, sigma = float(np.median(r)), _robust_sigma(r)
    return SupportPlane(n, d, sigma, int(keep.sum())), tilt


def flatten_table(
    mesh: trimesh.Trimesh,
    plane: SupportPlane,
    *,
    band_sigmas: float = 3.5,
    min_band_m: float = 0.0,
) -> tuple[trimesh.Trimesh, int, int]:
    """The table mesh with its top on the plane: (mesh, vertices moved, faces dropped).

    Vertices within ``max(band_sigmas * sigma, min_band_m)`` of the plane are projected onto
    it; faces with a vertex above that band are dropped (and vertices no face uses).
    """
    band = max(band_sigmas * plane.sigma, min_band_m)
    v = np.asarray(mesh.vertices, np.float64).copy()
    f = np.asarray(mesh.faces)
    dist = plane.distance(v)
    near = np.abs(dist) <= band
    v[near] = plane.project(v[near])
    keep = ~(dist > band)[f].any(axis=1)
    faces = f[keep]
    used = np.unique(faces)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    out = trimesh.Trimesh(v[used], remap[faces], process=False)
    return out, int(near.sum()), int((~keep).sum())


def rest_on_plane(mesh: trimesh.Trimesh, plane: SupportPlane) -> tuple[trimesh.Trimesh, int]:
    """The object mesh with its vertices below the plane moved onto it: (mesh, vertices moved)."""
    v = np.asarray(mesh.vertices, np.float64).copy()
    below = plane.distance(v) < 0
    v[below] = plane.project(v[below])
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False), int(below.sum())

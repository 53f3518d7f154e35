"""Mesh quality against a reference: accuracy, completeness, Chamfer, F-score, normal consistency.

Both surfaces are represented by area-uniform point samples (``trimesh.sample``, fixed seed) with
the normals of the faces they lie on; nearest neighbours come from ``scipy.spatial.cKDTree``.
With ``d(p, Q)`` the distance from p to the nearest sample of Q:

* accuracy = mean d(pred -> ref); completeness = mean d(ref -> pred) (DTU, Aanæs et al. 2016);
* Chamfer-L1 = (accuracy + completeness) / 2 (the DTU / Occupancy Networks convention);
* Chamfer-L2 = (mean d(pred -> ref)^2 + mean d(ref -> pred)^2) / 2;
* F-score at tau (Knapitsch et al. 2017, Tanks and Temples): precision = P(d(pred -> ref) < tau),
  recall = P(d(ref -> pred) < tau), F = 2PR / (P + R) (0 when both are 0);
* normal consistency (Mescheder et al. 2019): mean |n_p . n_q| over nearest pairs, both ways, averaged.

**Robo-GS compatible reading** (:func:`robogs_compat`). The paper reports "MSE" and an "F-score
with tolerance 1e-5", but its script compares vertex arrays index by index and has no threshold
(see the research notes). We read it as: MSE = Chamfer-L2 in m^2 of nearest-neighbour distances
between the metric meshes, and the tolerance as a threshold on the *squared* distance,
1e-5 m^2 (tau = 3.16 mm). Assumptions: both meshes in metres and in the same frame (after the
metric alignment), no decimation, no x400 scaling. Numbers from this reading are not comparable
to the paper's table; they are what its definitions most plausibly meant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial import cKDTree

__all__ = [
    "MeshMetrics",
    "point_metrics",
    "mesh_metrics",
    "sample_mesh",
    "robogs_compat",
    "COMPAT_TAU_M",
]

#: squared-distance tolerance of the Robo-GS-compatible F-score, m^2, and its tau, m
COMPAT_SQ_TOL_M2 = 1e-5
COMPAT_TAU_M = math.sqrt(COMPAT_SQ_TOL_M2)


@dataclass
class MeshMetrics:
    """Distances in mm (Chamfer-L2 in mm^2); F-scores keyed by tau in mm."""

    accuracy_mm: float
    completeness_mm: float
    chamfer_l1_mm: float
    chamfer_l2_mm2: float
    fscore: dict[float, float]
    precision: dict[float, float]
    recall: dict[float, float]
    normal_consistency: float
    n_pred: int
    n_ref: int
    extra: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, object]:
        return {
            "accuracy_mm": self.accuracy_mm,
            "completeness_mm": self.completeness_mm,
            "chamfer_l1_mm": self.chamfer_l1_mm,
            "chamfer_l2_mm2": self.chamfer_l2_mm2,
            "fscore": {f"{k:g}mm": v for k, v in self.fscore.items()},
            "precision": {f"{k:g}mm": v for k, v in self.precision.items()},
            "recall": {f"{k:g}mm": v for k, v in self.recall.items()},
            "normal_consistency": self.normal_consistency,
            "n_pred": self.n_pred,
            "n_ref": self.n_ref,
            **self.extra,
        }


def sample_mesh(mesh: trimesh.Trimesh, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` area-uniform samples [n, 3] of ``mesh`` and the unit normals [n, 3] of their faces."""
    pts, fid = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return np.asarray(pts), np.asarray(mesh.face_normals)[fid]


def point_metrics(
    pred: np.ndarray,
    ref: np.ndarray,
    *,
    pred_normals: np.ndarray | None = None,
    ref_normals: np.ndarray | None = None,
    taus_mm: tuple[float, ...] = (1.0, 2.0, 5.0),
    workers: int = 1,
) -> MeshMetrics:
    """Metrics of two sampled surfaces (points [N, 3] and [M, 3] in metres, same frame)."""
    pred, ref = np.asarray(pred, np.float64), np.asarray(ref, np.float64)
    if len(pred) == 0 or len(ref) == 0:
        nan = float("nan")
        zero = {float(t): 0.0 for t in taus_mm}
        return MeshMetrics(
            nan, nan, nan, nan, dict(zero), dict(zero), dict(zero), nan, len(pred), len(ref)
        )
    d_pr, i_pr = cKDTree(ref).query(pred, k=1, workers=workers)
    d_rp, i_rp = cKDTree(pred).query(ref, k=1, workers=workers)
    acc, comp = float(d_pr.mean()), float(d_rp.mean())
    fs, pr, rc = {}, {}, {}
    for tau in taus_mm:
        t = tau * 1e-3
        p, r = float((d_pr < t).mean()), float((d_rp < t).mean())
        pr[float(tau)], rc[float(tau)] = p, r
        fs[float(tau)] = 0.0 if p + r == 0 else 2 * p * r / (p + r)
    nc = float("nan")
    if pred_normals is not None and ref_normals is not None:
        a = np.abs(np.einsum("ij,ij->i", pred_normals, ref_normals[i_pr])).mean()
        b = np.abs(np.einsum("ij,ij->i", ref_normals, pred_normals[i_rp])).mean()
        nc = float(0.5 * (a + b))
    return MeshMetrics(
        acc * 1e3,
        comp * 1e3,
        0.5 * (acc + comp) * 1e3,
        0.5 * float((d_pr**2).mean() + (d_rp**2).mean()) * 1e6,
        fs,
        pr,
        rc,
        nc,
        len(pred),
        len(ref),
    )


def mesh_metrics(
    pred: trimesh.Trimesh,
    ref: trimesh.Trimesh,
    *,
    n: int = 200_000,
    taus_mm: tuple[float, ...] = (1.0, 2.0, 5.0),
    seed: int = 0,
    workers: int = 1,
) -> MeshMetrics:
    """Sample both meshes with ``n`` points each and compare (see :func:`point_metrics`)."""
    p, pn = sample_mesh(pred, n, seed)
    r, rn = sample_mesh(ref, n, seed + 1)
    return point_metrics(p, r, pred_normals=pn, ref_normals=rn, taus_mm=taus_mm, workers=workers)


def robogs_compat(pred: np.ndarray, ref: np.ndarray, workers: int = 1) -> dict[str, float]:
    """The Robo-GS "MSE / F-score (tolerance 1e-5)" under the reading in the module docstring.

    Returns:
        ``mse_m2`` (Chamfer-L2, m^2), ``fscore`` at squared distance < 1e-5 m^2 and ``tau_mm``.
    """
    m = point_metrics(pred, ref, taus_mm=(COMPAT_TAU_M * 1e3,), workers=workers)
    return {
        "mse_m2": m.chamfer_l2_mm2 * 1e-6,
        "fscore": m.fscore[COMPAT_TAU_M * 1e3],
        "tau_mm": COMPAT_TAU_M * 1e3,
    }

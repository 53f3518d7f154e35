"""Metric alignment of a reconstruction to the URDF: a similarity transform by Umeyama + ICP.

Robo-GS rescales and re-orients its reconstruction by hand (``compute_scale.py``,
``reorient.py``). Here the transform comes from the data: points of the reconstruction that the
labels assign to link L are matched to the nearest point of L's URDF visual mesh at the recorded
joint state, and ``x -> s R x + t`` is fitted in closed form (Umeyama 1991, "Least-squares
estimation of transformation parameters between two point patterns"), iterated as ICP with
correspondences restricted to the same link (Besl & McKay 1992), rejecting pairs farther than
3x the median distance. ICP starts from Umeyama on the per-link centroids (the labels give the
correspondence), so a capture in an arbitrary world (an SfM frame, scale and orientation) needs
no manual pre-alignment. The residual is the point-to-surface distance after alignment, in mm.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from robogs.format.errors import InputError

__all__ = ["Similarity", "umeyama", "AlignmentResult", "align_to_meshes"]


@dataclass(frozen=True)
class Similarity:
    """``x -> scale R x + t`` (world to world)."""

    scale: float
    R: np.ndarray
    t: np.ndarray

    @classmethod
    def identity(cls) -> Similarity:
        return cls(1.0, np.eye(3), np.zeros(3))

    def apply(self, x: np.ndarray) -> np.ndarray:
        return self.scale * (np.asarray(x) @ self.R.T) + self.t

    def matrix(self) -> np.ndarray:
        """[4, 4] homogeneous form."""
        M = np.eye(4)
        M[:3, :3] = self.scale * self.R
        M[:3, 3] = self.t
        return M

    def compose(self, other: Similarity) -> Similarity:
        """``self ∘ other``."""
        return Similarity(
            self.scale * other.scale, self.R @ other.R, self.scale * self.R @ other.t + self.t
        )

    @property
    def rotation_deg(self) -> float:
        c = np.clip((np.trace(self.R) - 1.0) / 2.0, -1.0, 1.0)
        return float(np.degrees(np.arccos(c)))


def umeyama(src: np.ndarray, dst: np.ndarray, *, with_scale: bool = True) -> Similarity:
    """Least-squares similarity mapping ``src`` [N, 3] onto ``dst`` [N, 3] (Umeyama 1991, Eq. 40-42).

    Raises:
        InputError: fewer than 3 pairs or degenerate (collinear) points.
    """
    src, dst = np.asarray(src, np.float64), np.asarray(dst, np.float64)
    if len(src) < 3 or src.shape != dst.shape:
        raise InputError(f"a similarity needs >= 3 matched points, got {len(src)}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    var_s = float((xs**2).sum() / len(src))
    if var_s < 1e-18:
        raise InputError("the points to align are all at one place")
    cov = xd.T @ xs / len(src)
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    scale = float(np.trace(np.diag(D) @ S) / var_s) if with_scale else 1.0
    return Similarity(scale, R, mu_d - scale * R @ mu_s)


@dataclass
class AlignmentResult:
    """The fitted transform and how well it fits.

    Attributes:
        transform: reconstruction world -> URDF world.
        rms_mm, median_mm, p90_mm: point-to-surface distances after alignment.
        before_rms_mm: the same before alignment (identity).
        pairs: matched points used in the last iteration.
        iterations: ICP iterations run.
        per_target_mm: median distance per target after alignment (excluded ones too).
        excluded: targets left out of the fit and of the RMS, median and p90.
    """

    transform: Similarity
    rms_mm: float
    median_mm: float
    p90_mm: float
    before_rms_mm: float
    pairs: int
    iterations: int
    per_target_mm: dict[str, float] = field(default_factory=dict)
    excluded: list[str] = field(default_factory=list)


def _initial_guess(src: list[np.ndarray], dst: list[np.ndarray], with_scale: bool) -> Similarity:
    """Start of ICP: Umeyama on the per-target centroids when there are 3 or more targets
    not on one line; else the overall centroids and RMS radii (no rotation)."""
    cs = np.array([p.mean(0) for p in src])
    cd = np.array([q.mean(0) for q in dst])
    if len(cs) >= 3:
        sv = np.linalg.svd(cs - cs.mean(0), compute_uv=False)
        if sv[1] > 1e-3 * max(sv[0], 1e-12):
            return umeyama(cs, cd, with_scale=with_scale)
    a, b = np.concatenate(src), np.concatenate(dst)
    ma, mb = a.mean(0), b.mean(0)
    scale = 1.0
    if with_scale:
        ra = np.sqrt(((a - ma) ** 2).sum(1).mean())
        rb = np.sqrt(((b - mb) ** 2).sum(1).mean())
        scale = float(rb / ra) if ra > 0 else 1.0
    return Similarity(scale, np.eye(3), mb - scale * ma)


def align_to_meshes(
    points: dict[str, np.ndarray],
    meshes: dict[str, trimesh.Trimesh],
    *,
    with_scale: bool = True,
    iterations: int = 100,
    samples: int = 20_000,
    seed: int = 0,
    exclude: Collection[str] = (),
) -> AlignmentResult:
    """Fit a similarity taking labelled points onto the meshes of the same names (ICP + Umeyama).

    Args:
        points: target name -> [N, 3] reconstructed points (world frame of the reconstruction).
        meshes: target name -> mesh in the reference world (e.g. URDF links at the joint state).
        with_scale: estimate the scale (else a rigid transform).
        iterations: maximum ICP iterations.
        samples: points sampled on each mesh for nearest-neighbour queries.
        exclude: targets that do not enter the fit nor the residual figures (their median
            distance after the fit is still reported), e.g. parts the mesh cannot resolve.

    Raises:
        InputError: no target has both points and a mesh.
    """
    usable = [n for n in sorted(points) if n in meshes and len(points[n]) > 0]
    names = [n for n in usable if n not in exclude]
    if not names:
        raise InputError(
            "no reconstructed points are labelled as a link with a mesh: nothing to align",
            hint="check the panoptic labels and the segments table",
        )
    trees, surf = {}, {}
    for k, n in enumerate(names):
        p, _ = trimesh.sample.sample_surface(meshes[n], samples, seed=seed + k)
        trees[n] = cKDTree(p)
        surf[n] = p
    src = np.concatenate([points[n] for n in names])
    owner = np.concatenate([np.full(len(points[n]), i) for i, n in enumerate(names)])

    def match(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.empty(len(x))
        y = np.empty_like(x)
        for i, n in enumerate(names):
            m = owner == i
            dd, j = trees[n].query(x[m], k=1)
            d[m], y[m] = dd, surf[n][j]
        return d, y

    d0, _ = match(src)
    total = _initial_guess([points[n] for n in names], [surf[n] for n in names], with_scale)
    x = total.apply(src)
    it = 0
    pairs = len(x)
    for k in range(1, iterations + 1):
        it = k
        d, y = match(x)
        keep = d <= 3.0 * max(float(np.median(d)), 1e-9)
        pairs = int(keep.sum())
        if pairs < 3:
            break
        step = umeyama(x[keep], y[keep], with_scale=with_scale)
        x = step.apply(x)
        total = step.compose(total)
        if (
            abs(step.scale - 1) < 1e-7
            and step.rotation_deg < 1e-5
            and np.linalg.norm(step.t) < 1e-8
        ):
            break
    d, _ = match(x)
    per = {n: float(np.median(d[owner == i]) * 1e3) for i, n in enumerate(names)}
    out = [n for n in usable if n not in names]
    for k, n in enumerate(out):
        p, _ = trimesh.sample.sample_surface(meshes[n], samples, seed=seed + len(names) + k)
        per[n] = float(np.median(cKDTree(p).query(total.apply(points[n]), k=1)[0]) * 1e3)
    return AlignmentResult(
        total,
        float(np.sqrt((d**2).mean()) * 1e3),
        float(np.median(d) * 1e3),
        float(np.percentile(d, 90) * 1e3),
        float(np.sqrt((d0**2).mean()) * 1e3),
        pairs,
        it,
        per,
        out,
    )

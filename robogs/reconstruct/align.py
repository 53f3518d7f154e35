"""Metric alignment of a reconstruction to the URDF: a similarity transform by Umeyama + ICP.

Robo-GS rescales and re-orients its reconstruction by hand (``compute_scale.py``,
``reorient.py``). Here the transform comes from the data: points of the reconstruction that the
labels assign to link L are matched to the nearest point of L's URDF visual mesh at the recorded
joint state, and ``x -> s R x + t`` is fitted in closed form (Umeyama 1991, "Least-squares
estimation of transformation parameters between two point patterns"), iterated as ICP with
correspondences restricted to the same link (Besl & McKay 1992), rejecting pairs farther than
3x the median distance (the median floored at the points' spacing, each step kept only if it
lowers the truncated squared distance; see the comment above ``_HALVINGS``). ICP starts from
Umeyama on the per-link centroids (the labels give the correspondence), so a capture in an
arbitrary world (an SfM frame, scale and orientation) needs no manual pre-alignment. A
point-to-plane refinement then fits one surface offset per link with the similarity, so a link
reconstructed uniformly fatter or thinner than its mesh (a thin link through a coarse TSDF)
does not become scale. The residual is the exact point-to-surface
distance after alignment (offsets not subtracted), in mm; before 2026-11-26 it was the distance
to the nearest of 20k samples per link, up to the sample spacing (3.6 mm on the UR5 upper arm)
too high.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from robogs.format.errors import InputError

__all__ = [
    "Similarity",
    "umeyama",
    "AlignmentResult",
    "align_to_meshes",
    "closest_points_on_triangles",
]


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
        rms_mm, median_mm, p90_mm: point-to-surface distances after alignment (the exact
            distance to the nearest triangle of the target's mesh, every point of every target
            fitted; not corrected by the offsets below).
        before_rms_mm: the same before alignment (identity).
        pairs: matched points used in the last iteration (weight > 0).
        iterations: iterations run (point-to-point ICP, then the offset-aware refinement).
        per_target_mm: median distance per target after alignment (excluded ones too).
        excluded: targets left out of the fit and of the RMS, median and p90.
        per_target_offset_mm: each fitted target's surface offset along its normals (positive:
            the part is fatter than its mesh), fitted with the transform; zeros without it.
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
    per_target_offset_mm: dict[str, float] = field(default_factory=dict)


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


def closest_points_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Closest point [N, 3] of triangle (a, b, c) [N, 3] to each point p [N, 3] (m).

    Ericson 2005, *Real-Time Collision Detection*, §5.1.5 (Voronoi regions of the vertices,
    edges and face, from barycentric dot products), vectorised.
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp, cp = p - b, p - c
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v_f, w_f = vb / den, vc / den
        v_ab = d1 / (d1 - d3)
        w_ac = d2 / (d2 - d6)
        w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    out = a + v_f[:, None] * ab + w_f[:, None] * ac  # inside the face
    regions = [  # later entries win: vertex regions over edges over the face
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + w_bc[:, None] * (c - b)),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + w_ac[:, None] * ac),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + v_ab[:, None] * ab),
        ((d6 >= 0) & (d5 <= d6), c),
        ((d3 >= 0) & (d4 <= d3), b),
        ((d1 <= 0) & (d2 <= 0), a),
    ]
    for m, q in regions:
        out = np.where(m[:, None], q, out)
    return out


class _Surface:
    """Nearest points on a mesh: candidate faces from the ``k`` nearest of dense area samples,
    then the closest point on each candidate triangle (:func:`closest_points_on_triangles`).

    Exact whenever the nearest triangle holds one of the ``k`` samples nearest to the point
    (points up to 6 cm from a 24-sided cylinder: within 0.03 mm of ``trimesh``'s exact
    distance); the nearest *sample* alone overstates the distance by up to the sample spacing
    (3.6 mm on the UR5 upper arm at 20k samples).
    """

    def __init__(self, mesh: trimesh.Trimesh, samples: int, seed: int, k: int = 8) -> None:
        p, f = trimesh.sample.sample_surface(mesh, samples, seed=seed)
        self.points = np.asarray(p)
        self.tree = cKDTree(self.points)
        self.face = np.asarray(f)
        self.tri = np.asarray(mesh.triangles, np.float64)
        self.normal = np.asarray(mesh.face_normals, np.float64)
        self.k = min(k, len(self.face))
        # below this distance x - y is rounding noise: the face normal gives the direction
        self.on_surface = 1e-9 * float(np.linalg.norm(np.ptp(self.tri.reshape(-1, 3), axis=0)))

    def query(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest surface points y [N, 3], distances [N] (m) and unit directions u [N, 3] from y
        to x, signed to point out of the mesh (the nearest face's normal where x lies on it)."""
        _, j = self.tree.query(x, k=self.k)
        cand = self.face[np.asarray(j).reshape(len(x), -1)]  # [N, k] face ids
        t = self.tri[cand.ravel()]
        X = np.repeat(x, cand.shape[1], 0)
        y = closest_points_on_triangles(X, t[:, 0], t[:, 1], t[:, 2]).reshape(len(x), -1, 3)
        d = np.linalg.norm(y - x[:, None], axis=2)
        best = d.argmin(1)
        rows = np.arange(len(x))
        y, d, n = y[rows, best], d[rows, best], self.normal[cand[rows, best]]
        diff = x - y
        u = np.where(d[:, None] > self.on_surface, diff / np.maximum(d, 1e-300)[:, None], n)
        u *= np.where((diff * n).sum(1) < 0, -1.0, 1.0)[:, None]
        return y, d, u


# The robust scales and the step acceptance of both ICP stages (h88).
#
# Scale floor. A robust scale taken from the residuals alone (the median distance of the first
# stage, the MAD of the refinement) collapses on exact or near-exact samples: where the pose is
# off along one axis, the faces parallel to it slide onto themselves at zero distance, the
# median is that zero, and the only points that hold the axis (on the faces across it, at the
# pose error) are rejected; the fit stops where it is (h82: a third of the points lost their
# weight and one refinement step moved 985 mm). Neither scale may fall below the resolution of
# the data: the median distance between neighbouring points of the reconstruction (per target),
# mapped into the reference world by the current scale. Like the threshold D of Zhang's
# adaptive ICP (Zhang 1994, "Iterative point matching for registration of free-form curves and
# surfaces", IJCV 13(2), Sec. 4.2), it comes from the sampling, not from a constant in metres,
# so the same scene in mm and in m gives the same fit. The two floors agree: the first stage
# keeps distances up to 3 spacings, where the refinement's Tukey weight (scale >= 1 spacing,
# c = 4.685) is still 0.35, so the refinement never starts by dropping what the first kept.
#
# Released pass. The floor also weights whatever lies within ~5 spacings of a surface: outliers
# near it, and points whose nearest face the 8 nearest mesh samples miss (by a box edge). On
# exact inliers with 30 % outliers uniform in the scene that held the fit 2e-5 of the scene off.
# So the last stage (the refinement, or the first stage where it is the last) runs a second pass
# from where the floored one stopped, with the scale from the residuals alone (floor 1e-12 of
# the scene, for rounding), as graduated robust fits shrink their scale once in the basin
# (Blake & Zisserman 1987, graduated non-convexity). The collapse that the floor guards against
# cannot run away there: the step acceptance refuses any step that raises the objective (on
# h82's fixture without the floor, a step taken regardless moved the fit 1.9 km).
#
# Step acceptance. Each step is a proposal: kept only if it does not raise the robust objective
# of its iteration (the scale held fixed), else halved, up to _HALVINGS times; if no fraction
# descends, the stage stops. Backtracking line search (Armijo 1966; Nocedal & Wright 2006,
# "Numerical Optimization", Alg. 3.1) with simple decrease. The objectives: the first stage's
# truncated squares sum(min(d, tau)^2), which an exact-correspondence ICP step never raises
# (Besl & McKay 1992, Thm. 1, with the truncation); the refinement's Tukey sum, which a
# Gauss-Newton step on moved correspondences can raise. The difference of the two sums is
# summed point by point, so points saturated at both poses cancel exactly and the test stays
# exact to rounding even at residuals of 1e-12 of the scene.
_HALVINGS = 12


def _spacing(points: list[np.ndarray]) -> float:
    """Median distance from a point to its nearest neighbour of the same target (units of the
    points); 0 if every target has fewer than 2 points or the points coincide."""
    nn = [cKDTree(p).query(p, k=2)[0][:, 1] for p in points if len(p) >= 2]
    return float(np.median(np.concatenate(nn))) if nn else 0.0


def _tukey_scale(r: np.ndarray, floor: float) -> float:
    """1.4826 MAD of residuals [N] (the normal-consistent robust scale), no less than ``floor``."""
    return max(1.4826 * float(np.median(np.abs(r - np.median(r)))), floor)


def _bisquare(r: np.ndarray, s: float, c: float = 4.685) -> np.ndarray:
    """Tukey's biweight weights of residuals [N] at scale ``s`` (Beaton & Tukey 1974)."""
    z = r / (c * s)
    return np.where(np.abs(z) < 1.0, (1.0 - z**2) ** 2, 0.0)


def _bisquare_rho(r: np.ndarray, s: float, c: float = 4.685) -> np.ndarray:
    """Tukey's biweight loss of residuals [N] at scale ``s``, in units of (c s)^2 / 6: 1 beyond
    c s, ``1 - (1 - z^2)^3`` inside (its derivative over r is the weight times r), written
    ``z^2 (3 - 3 z^2 + z^4)`` so that it keeps its relative precision at residuals of 1e-12 c s."""
    z2 = np.minimum((r / (c * s)) ** 2, 1.0)
    return z2 * (3.0 - 3.0 * z2 + z2 * z2)


def _fraction(step: Similarity, c: np.ndarray, alpha: float) -> Similarity:
    """The fraction ``alpha`` of ``step`` about the point ``c``: scale ``s^alpha``, rotation angle
    times ``alpha`` about the same axis, and ``alpha`` times the move of ``c``."""
    sc = step.scale**alpha
    R = Rotation.from_rotvec(alpha * Rotation.from_matrix(step.R).as_rotvec()).as_matrix()
    return Similarity(sc, R, c + alpha * (step.apply(c) - c) - sc * R @ c)


def _offset_refine(
    x: np.ndarray,
    owner: np.ndarray,
    n_targets: int,
    match: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
    with_scale: bool,
    iterations: int,
    spacing: float,
    extent: float,
    trace: list[tuple[int, float]] | None = None,
) -> tuple[Similarity, np.ndarray, int, int]:
    """Point-to-plane Gauss-Newton on ``x`` [N, 3] (already roughly aligned): a similarity and
    one surface offset per target, residual ``u . (x' - y) - offset[target]``, Tukey weights;
    each step kept only if it does not raise the Tukey objective, else halved. Two passes of
    up to ``iterations`` each: the scale floored at ``spacing``, then released (see the comment
    above ``_HALVINGS``).

    The point-to-plane step is Chen & Medioni 1992 with the scale added; the per-target offset
    absorbs a part reconstructed uniformly fatter or thinner than its mesh (a thin link through
    a coarse TSDF), which point-to-point ICP would otherwise turn into scale. ``spacing``: the
    points' neighbour spacing at entry and ``extent``: the scene's size, both in the units of
    ``x``. ``trace`` (tests) receives (pass, change of the objective) for each accepted step.
    Returns the step taken (composed over the iterations), the offsets [T], iterations and
    weighted pairs.
    """
    total = Similarity.identity()
    offs = np.zeros(n_targets)
    pairs = len(x)
    its = 0
    E = np.zeros((len(x), n_targets))
    E[np.arange(len(x)), owner] = -1.0
    y, _, u = match(x)
    r0 = ((x - y) * u).sum(1)  # signed distance, positive outside the mesh
    for npass, floor in enumerate((spacing, 0.0)):
        for _ in range(iterations):
            its += 1
            c = x.mean(0)
            q = x - c
            J = np.concatenate(
                [(u * q).sum(1, keepdims=True) * with_scale, np.cross(q, u), u, E], axis=1
            )
            s = _tukey_scale(r0 - offs[owner], max(floor * total.scale, 1e-12 * extent))
            w = _bisquare(r0 - offs[owner], s)
            pairs = int((w > 0).sum())
            sw = np.sqrt(w)[:, None]
            theta = np.linalg.lstsq(J * sw, -(r0[:, None] * sw)[:, 0], rcond=None)[0]
            # r0 + J theta = u . (x' - y) - offset: theta[7:] are the new offsets, not increments
            rho0 = _bisquare_rho(r0 - offs[owner], s)
            for h in range(_HALVINGS + 1):
                alpha = 0.5**h
                a, rv, v = alpha * theta[0], alpha * theta[1:4], alpha * theta[4:7]
                offs1 = offs + alpha * (theta[7:] - offs)
                R = Rotation.from_rotvec(rv).as_matrix()
                sc = 1.0 + a if with_scale else 1.0
                step = Similarity(sc, R, c + v - sc * R @ c)
                x1 = step.apply(x)
                y1, _, u1 = match(x1)
                r1 = ((x1 - y1) * u1).sum(1)
                change = float((_bisquare_rho(r1 - offs1[owner], s) - rho0).sum())
                if change <= 0.0:
                    break
            else:  # no fraction of the step descends: the pass ends where it is least
                break
            if trace is not None:
                trace.append((npass, change))
            x, y, u, r0, offs = x1, y1, u1, r1, offs1
            total = step.compose(total)
            if (
                abs(sc - 1) < 1e-8
                and np.linalg.norm(rv) < 1e-8
                and np.linalg.norm(v) < 1e-9 * extent
            ):
                break
    return total, offs, its, pairs


def _point_icp(
    x: np.ndarray,
    match: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
    with_scale: bool,
    iterations: int,
    floors: tuple[float, ...],
    extent: float,
    trace: list[tuple[int, float]] | None = None,
) -> tuple[Similarity, int, int]:
    """Point-to-point ICP on ``x`` [N, 3] (Besl & McKay 1992; Umeyama steps): pairs within
    ``tau = 3 max(median distance, floor)`` (``floor`` in the units of ``x`` at entry, scaled
    with the fit), each step kept only if it does not raise ``sum(min(d, tau)^2)``, else halved
    about the pairs' centroid. One pass of up to ``iterations`` per entry of ``floors``.
    ``trace`` (tests) receives (pass, change of the objective) for each accepted step. Returns
    the step taken (composed), the iterations and the pairs of the last one."""
    total = Similarity.identity()
    y, d, _ = match(x)
    its = 0
    pairs = len(x)
    for npass, floor in enumerate(floors):
        for _ in range(iterations):
            its += 1
            tau = 3.0 * max(float(np.median(d)), floor * total.scale, 1e-12 * extent)
            keep = d <= tau
            pairs = int(keep.sum())
            if pairs < 3:
                return total, its, pairs
            full = umeyama(x[keep], y[keep], with_scale=with_scale)
            c = x[keep].mean(0)
            before = np.minimum(d, tau) ** 2
            for h in range(_HALVINGS + 1):
                step = full if h == 0 else _fraction(full, c, 0.5**h)
                x1 = step.apply(x)
                y1, d1, _ = match(x1)
                change = float((np.minimum(d1, tau) ** 2 - before).sum())
                if change <= 0.0:
                    break
            else:  # no fraction of the step descends: the pass ends
                break
            if trace is not None:
                trace.append((npass, change))
            x, y, d = x1, y1, d1
            total = step.compose(total)
            if (
                abs(step.scale - 1) < 1e-7
                and step.rotation_deg < 1e-5
                and np.linalg.norm(step.t) < 1e-8 * extent
            ):
                break
    return total, its, pairs


def align_to_meshes(
    points: dict[str, np.ndarray],
    meshes: dict[str, trimesh.Trimesh],
    *,
    with_scale: bool = True,
    iterations: int = 100,
    samples: int = 20_000,
    seed: int = 0,
    exclude: Collection[str] = (),
    offsets: bool = True,
) -> AlignmentResult:
    """Fit a similarity taking labelled points onto the meshes of the same names (ICP + Umeyama).

    Each iteration matches every point to the exact nearest point of its target's surface
    (Besl & McKay 1992) and fits the Umeyama similarity to the pairs within 3x the median
    distance (no less than 3x the points' neighbour spacing), so a part reconstructed much
    fatter than its mesh does not pull the scale; a step that raises the robust objective is
    halved (:func:`_point_icp`). The scales come from the data, so the same scene in mm and in m
    gives the same fit (the reported figures, ``*_mm``, assume metres). With
    ``offsets`` and 3 or more targets, a point-to-plane refinement then fits one surface offset
    per target with the transform (:func:`_offset_refine`): parts reconstructed uniformly
    fatter or thinner than their meshes (a coarse TSDF) shift their offsets, not the scale.

    Args:
        points: target name -> [N, 3] reconstructed points (world frame of the reconstruction).
        meshes: target name -> mesh in the reference world (e.g. URDF links at the joint state).
        with_scale: estimate the scale (else a rigid transform).
        iterations: maximum iterations of each pass of each stage (a floored pass, then a
            released one for the last stage).
        samples: area samples per mesh that propose the candidate faces of a nearest point.
        exclude: targets that do not enter the fit nor the residual figures (their median
            distance after the fit is still reported), e.g. parts the mesh cannot resolve.
        offsets: refine with per-target surface offsets (needs 3 or more fitted targets).

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
    surf = {n: _Surface(meshes[n], samples, seed + k) for k, n in enumerate(usable)}
    src = np.concatenate([points[n] for n in names])
    owner = np.concatenate([np.full(len(points[n]), i) for i, n in enumerate(names)])
    # the scene's size (reference units): tolerances relative to it, not in metres
    extent = float(np.linalg.norm(np.ptp(np.concatenate([surf[n].points for n in names]), 0)))
    spacing = _spacing([np.asarray(points[n], np.float64) for n in names])  # source units

    def match(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = np.empty(len(x))
        y = np.empty_like(x)
        u = np.empty_like(x)
        for i, n in enumerate(names):
            m = owner == i
            y[m], d[m], u[m] = surf[n].query(x[m])
        return y, d, u

    d0 = match(src)[1]
    total = _initial_guess([points[n] for n in names], [surf[n].points for n in names], with_scale)
    x = total.apply(src)
    refine = offsets and len(names) >= 3
    h = spacing * total.scale  # the points' spacing in the reference world
    # the floor released in a last pass only where this stage is the last
    step, it, pairs = _point_icp(
        x, match, with_scale, iterations, (h, 0.0)[: 1 + (not refine)], extent
    )
    x = step.apply(x)
    total = step.compose(total)
    offs = np.zeros(len(names))
    if refine:
        step, offs, k2, pairs = _offset_refine(
            x, owner, len(names), match, with_scale, iterations, spacing * total.scale, extent
        )
        x = step.apply(x)
        total = step.compose(total)
        it += k2
    d = match(x)[1]
    per = {n: float(np.median(d[owner == i]) * 1e3) for i, n in enumerate(names)}
    for n in usable:
        if n not in names:
            per[n] = float(np.median(surf[n].query(total.apply(points[n]))[1]) * 1e3)
    return AlignmentResult(
        total,
        float(np.sqrt((d**2).mean()) * 1e3),
        float(np.median(d) * 1e3),
        float(np.percentile(d, 90) * 1e3),
        float(np.sqrt((d0**2).mean()) * 1e3),
        pairs,
        it,
        per,
        [n for n in usable if n not in names],
        {n: float(offs[i] * 1e3) for i, n in enumerate(names)},
    )

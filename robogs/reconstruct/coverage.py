"""Is a capture enough to reconstruct? View count, angular coverage, baseline and mask size.

Run before any training (milliseconds: camera poses, rest-state forward kinematics and the label
images only), so a capture the method cannot reconstruct stops at once with what is missing.

Per target (link or object), over the *training* views:

* **views**: views whose label image gives the target at least ``min_pixels`` pixels;
* **span**: the largest angle between two directions from the target's centre to the centres of
  those views (the centre is the link's visual mesh centroid at the rest forward kinematics, the
  object's rest pose, else the point nearest the rays through the mask centroids);
* **pixels**: the most pixels it covers in any view.

Globally: the **baseline**, the largest distance between two camera centres, against the median
camera-to-scene distance.

Thresholds (documented in ``docs/reconstruct.md``, "Coverage"):

* ``min_span_deg = 60``: the seeds start from the visual hull; for a convex section of radius r
  seen from directions spanning an angle θ, the hull reaches r / sin(θ/2) along the mean viewing
  direction (the slabs ``|n_i·x| <= r`` of the two extreme views): 2 r at 60°, 3.9 r at 30°,
  11.5 r at 10°. Past 2x the depth the photo-consistency carving and training have to move most
  of the surface instead of refining it.
* ``min_views = 8``: with 8 silhouettes spread over the span the hull polygon of a circle is
  within 2 % of it (r / cos(π / 2N) over a full turn), and every surface point keeps ≥ 2 views
  after one in 8 is held out; sparse-view splatting and NeRF studies (3-9 views) show the
  collapse below that range.
* ``min_pixels = 100``: a 10x10-px patch, about one 11-px window of the D-SSIM loss; below it
  a link's colour and shape come from a handful of pixels per view.
* baseline ratio ≥ 2 sin(min_span / 2) (= 1.0 at 60°): the chord of that span at the median
  distance; a single static camera has ratio 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from robogs.format.errors import InputError

from .segment import TargetMap
from .views import View

__all__ = [
    "CoverageThresholds",
    "TargetCoverage",
    "CoverageReport",
    "CoverageError",
    "angular_span_deg",
    "triangulate_rays",
    "assess_coverage",
]


class CoverageError(InputError):
    """The capture cannot support a reconstruction (too few views, angles or pixels)."""


@dataclass(frozen=True)
class CoverageThresholds:
    """What the method needs of every target (see the module docstring for the derivation).

    Attributes:
        min_views: training views that see the target with ``min_pixels`` or more.
        min_span_deg: angle spanned by those views' directions from the target centre, deg.
        min_pixels: pixels of the target in a view for that view to count.
    """

    min_views: int = 8
    min_span_deg: float = 60.0
    min_pixels: int = 100

    @property
    def min_baseline_ratio(self) -> float:
        """Largest camera distance over the median scene distance: 2 sin(min_span / 2)."""
        return 2.0 * math.sin(math.radians(self.min_span_deg) / 2.0)


@dataclass
class TargetCoverage:
    """Coverage of one link or object.

    Attributes:
        name: target name.
        kind: ``robot_link`` or ``object``.
        views: training views with at least ``min_pixels`` pixels of it.
        views_any: training views with at least one pixel of it.
        span_deg: angle spanned by the directions to the counted views (0 for fewer than 2).
        max_pixels: most pixels in one view.
        centre: its centre in the world, m (None if unknown).
        centre_from: ``fk``, ``pose``, ``rays`` or ``none``.
    """

    name: str
    kind: str
    views: int
    views_any: int
    span_deg: float
    max_pixels: int
    centre: list[float] | None
    centre_from: str

    def problem(self, th: CoverageThresholds) -> str | None:
        """One phrase on what is missing, or None when the target is covered."""
        what = "link" if self.kind == "robot_link" else "object"
        if self.views_any == 0:
            return f"{what} {self.name} is in no label image"
        if self.views == 0:
            return (
                f"{what} {self.name} covers at most {self.max_pixels} px in any view "
                f"(need ≥ {th.min_pixels} px in ≥ {th.min_views} views)"
            )
        if self.views < th.min_views or self.span_deg < th.min_span_deg:
            side = " from one side" if self.span_deg < th.min_span_deg else ""
            return (
                f"{what} {self.name} seen in {self.views} view{'s' * (self.views != 1)}{side} (over "
                f"{self.span_deg:.0f}°); need ≥ {th.min_views} over ≥ {th.min_span_deg:g}°"
            )
        return None


@dataclass
class CoverageReport:
    """Coverage of a capture's training views.

    Attributes:
        views: training views.
        baseline_m: largest distance between two camera centres, m.
        distance_m: median distance from the cameras to the scene centre, m (nan if unknown).
        targets: per link and object.
        thresholds: what was required.
    """

    views: int
    baseline_m: float
    distance_m: float
    targets: list[TargetCoverage]
    thresholds: CoverageThresholds = field(default_factory=CoverageThresholds)

    @property
    def baseline_ratio(self) -> float:
        """``baseline_m / distance_m`` (nan without a scene distance)."""
        return self.baseline_m / self.distance_m if self.distance_m > 0 else float("nan")

    def problems(self) -> list[str]:
        """What is missing, worst first (empty when the capture is enough)."""
        th = self.thresholds
        out: list[str] = []
        if self.views < th.min_views:
            out.append(f"only {self.views} training views (need ≥ {th.min_views})")
        r = self.baseline_ratio
        if math.isfinite(r) and r < th.min_baseline_ratio:
            out.append(
                f"all {self.views} views within {self.baseline_m * 1e3:.0f} mm of each other at "
                f"{self.distance_m:.2f} m from the scene (need a baseline ≥ "
                f"{th.min_baseline_ratio * self.distance_m:.2f} m)"
            )
        ranked = sorted(self.targets, key=lambda t: (t.views, t.span_deg, t.max_pixels))
        out += [p for t in ranked if (p := t.problem(th)) is not None]
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "views": self.views,
            "baseline_m": self.baseline_m,
            "distance_m": self.distance_m if math.isfinite(self.distance_m) else None,
            "baseline_ratio": self.baseline_ratio if math.isfinite(self.baseline_ratio) else None,
            "thresholds": asdict(self.thresholds),
            "targets": [asdict(t) for t in self.targets],
            "problems": self.problems(),
        }

    def raise_if_insufficient(self, *, limit: int = 4) -> None:
        """Raise :class:`CoverageError` naming the first ``limit`` problems, if any."""
        probs = self.problems()
        if not probs:
            return
        more = f"; and {len(probs) - limit} more" if len(probs) > limit else ""
        th = self.thresholds
        raise CoverageError(
            "the capture cannot be reconstructed: " + "; ".join(probs[:limit]) + more,
            hint=f"capture the scene at rest from ≥ {th.min_views} viewpoints spread over "
            f"≥ {th.min_span_deg:g}° around every link and object (walk around it: 30-60 photos "
            f"on a half orbit), each link ≥ {th.min_pixels} px in the image; --force "
            "reconstructs anyway",
        )


def angular_span_deg(directions: np.ndarray) -> float:
    """Largest angle between two of the unit vectors ``directions`` [N, 3], deg (0 if N < 2)."""
    d = np.asarray(directions, np.float64)
    if len(d) < 2:
        return 0.0
    c = np.clip(d @ d.T, -1.0, 1.0)
    return float(np.degrees(np.arccos(c.min())))


def triangulate_rays(origins: np.ndarray, dirs: np.ndarray) -> np.ndarray | None:
    """The point nearest (least squares) to the lines ``origins + s dirs``; None if they are parallel.

    Minimises ``Σ |(I − d dᵀ)(x − o)|²``: solve ``Σ (I − d dᵀ) x = Σ (I − d dᵀ) o``.
    """
    d = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    P = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
    A, b = P.sum(0), np.einsum("nij,nj->i", P, origins)
    w = np.linalg.eigvalsh(A)
    if len(origins) < 2 or w[0] < 1e-6 * max(w[-1], 1e-12):
        return None
    return np.linalg.solve(A, b)


def _camera_centres(views: list[View]) -> np.ndarray:
    return np.stack([v.camera.T_world_cam[:3, 3].double().cpu().numpy() for v in views])


def _mask_ray(view: View, mask: np.ndarray) -> np.ndarray:
    """World direction of the ray through the mask's pixel centroid."""
    ys, xs = np.nonzero(mask)
    c = view.camera
    u, v = xs.mean() + 0.5, ys.mean() + 0.5
    d_cam = np.array([(u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0])
    R = c.T_world_cam[:3, :3].double().cpu().numpy()
    return R @ d_cam


def _projects_into(views: list[View], masks: dict[int, np.ndarray], X: np.ndarray) -> bool:
    """Does ``X`` project inside the masks' boxes (25 % margin) in at least half the views?"""
    hits = 0
    for i, m in masks.items():
        c = views[i].camera
        T = c.T_world_cam.double().cpu().numpy()
        p = T[:3, :3].T @ (X - T[:3, 3])
        if p[2] <= 0:
            continue
        u, v = c.fx * p[0] / p[2] + c.cx, c.fy * p[1] / p[2] + c.cy
        ys, xs = np.nonzero(m)
        mx, my = 0.25 * (np.ptp(xs) + 1) + 2, 0.25 * (np.ptp(ys) + 1) + 2
        hits += bool(
            xs.min() - mx <= u <= xs.max() + 1 + mx and ys.min() - my <= v <= ys.max() + 1 + my
        )
    return 2 * hits >= len(masks) > 0


def assess_coverage(
    views: list[View],
    tmap: TargetMap,
    centres: dict[str, tuple[np.ndarray, str]],
    thresholds: CoverageThresholds = CoverageThresholds(),
) -> CoverageReport:
    """Coverage of ``views`` (with labels) for every target of ``tmap``.

    Args:
        views: the training views (their ``labels`` at the training scale).
        tmap: targets (label id -> target index).
        centres: target -> (world centre [3] m, source) where known (links from FK, objects
            from their rest pose). A centre that does not project into the target's masks in
            half the views (a capture in another frame, such as SfM's) is replaced, like a
            missing one, by the point nearest the rays through the mask centroids.
        thresholds: what is required.
    """
    C = _camera_centres(views) if views else np.zeros((0, 3))
    baseline = 0.0
    if len(C) > 1:
        baseline = float(np.max(np.linalg.norm(C[:, None] - C[None], axis=-1)))
    n_t = len(tmap.names)
    counts = np.zeros((len(views), n_t + 1), np.int64)
    for i, v in enumerate(views):
        if v.labels is not None:
            ids = tmap.lut[np.clip(v.labels, 0, len(tmap.lut) - 1)]
            counts[i] = np.bincount(ids.ravel(), minlength=n_t + 1)[: n_t + 1]
    targets: list[TargetCoverage] = []
    known: list[np.ndarray] = []
    for k, (name, kind) in enumerate(zip(tmap.names, tmap.kinds, strict=True), start=1):
        px = counts[:, k]
        seen = np.flatnonzero(px >= thresholds.min_pixels)
        centre, src = centres.get(name, (None, "none"))
        any_ = np.flatnonzero(px > 0)
        masks = {int(i): tmap.lut[views[i].labels] == k for i in any_}  # type: ignore[index]
        if centre is not None and not _projects_into(views, masks, np.asarray(centre)):
            centre, src = None, "none"  # the capture's frame is not the robot's (e.g. SfM)
        if centre is None and len(any_) >= 2:
            rays = np.stack([_mask_ray(views[i], masks[int(i)]) for i in any_])
            centre = triangulate_rays(C[any_], rays)
            src = "rays" if centre is not None else "none"
        span = 0.0
        if len(seen) >= 2:
            if centre is not None:
                d = C[seen] - np.asarray(centre)[None]
                span = angular_span_deg(d / np.linalg.norm(d, axis=1, keepdims=True).clip(1e-12))
            # without a centre the rays were parallel: no parallax, span 0
        if centre is not None:
            known.append(np.asarray(centre, np.float64))
        targets.append(
            TargetCoverage(
                name=name,
                kind=kind,
                views=int(len(seen)),
                views_any=int((px > 0).sum()),
                span_deg=span,
                max_pixels=int(px.max()) if len(px) else 0,
                centre=None if centre is None else [float(x) for x in centre],
                centre_from=src,
            )
        )
    distance = float("nan")
    if known and len(C):
        distance = float(np.median(np.linalg.norm(C - np.mean(known, axis=0)[None], axis=1)))
    return CoverageReport(len(views), baseline, distance, targets, thresholds)

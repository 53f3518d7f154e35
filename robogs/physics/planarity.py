"""Whether a recording's object stays flat on its support: roll and pitch measured from the data.

The planar model (and MuJoCo's planar joint set) moves a box on x, y and yaw: it has no roll
or pitch, and the residuals compare x, y, z and yaw only, so a box that tips or rolls over
would be fitted without a word. :func:`out_of_plane` measures the tilt of each trajectory's
object relative to its own rest attitude and says when it leaves the plane.

Tilt of a sample: the angle between world z and the support normal carried by the body, i.e.
``R_t n_b`` with ``n_b = R_rest^T e_z`` (the normal in the body frame, averaged over the
trajectory's rest samples). It does not depend on yaw, nor on which face the box rests on.
The threshold comes from the data: the tilt's two horizontal components at rest are the
tracker's roll/pitch noise (robust sigma from their median absolute deviation, pooled over
trajectories); a trajectory leaves the plane when its tilt stays above
``max(MAX_TILT_DEG, SIGMAS * sigma)`` for ``RUN`` consecutive samples outside grasps
(``MAX_TILT_DEG`` is the support tilt the planar engine already treats as horizontal).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robogs.physics.engines.planar import MAX_TILT_DEG
from robogs.physics.phases import PHASES, PhaseLabels
from robogs.physics.recording import Recording

__all__ = ["SIGMAS", "RUN", "TiltCheck", "tilt_components", "out_of_plane"]

SIGMAS = 8.0
"""Noise sigmas a tilt must exceed (a Gaussian's 8-sigma tail is ~1e-15 per sample)."""
RUN = 3
"""Consecutive samples the tilt must stay above its threshold (one outlier is not a tip)."""

_REST = PHASES.index("rest")
_GRASP = PHASES.index("grasp")


def _rot(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices [N, 3, 3] of (w, x, y, z) quaternions [N, 4] (normalised here)."""
    q = np.asarray(quat, float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def _first_run(mask: np.ndarray) -> np.ndarray:
    """The first run of at least ``RUN`` True samples of ``mask`` (else the first sample)."""
    m = np.asarray(mask, bool)
    out = np.zeros(len(m), bool)
    i = 0
    while i < len(m):
        if m[i]:
            j = i
            while j < len(m) and m[j]:
                j += 1
            if j - i >= RUN:
                out[i:j] = True
                return out
            i = j
        else:
            i += 1
    out[0] = True
    return out


def tilt_components(quat: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """World x, y components [N, 2] of the support normal carried by the body.

    Args:
        quat: T_world_object rotations [N, 4] (w, x, y, z).
        rest: [N] bool, the samples whose attitude is the trajectory's resting one (all
            samples when none is marked).

    The rest attitude is the component-wise median over the first run of at least ``RUN`` rest
    samples (the attitude the object starts from; the first sample when there is none). Their
    norm is ``sin`` of the tilt away from it.
    """
    r = _rot(quat)
    sel = _first_run(rest)
    n_b = np.median(r[sel][:, 2, :], axis=0)  # rows of R: R^T e_z per sample
    n_b /= np.linalg.norm(n_b)
    return np.einsum("nij,j->ni", r, n_b)[:, :2]


class TiltCheck:
    """The measured tilt of every trajectory and the verdict (see the module docstring).

    Attributes:
        sigma_deg: roll/pitch noise at rest [deg] (robust, pooled over trajectories).
        threshold_deg: the tilt a trajectory must exceed for ``RUN`` samples [deg].
        peak_deg: per trajectory, the largest tilt held for ``RUN`` samples [deg].
        names: the trajectories' names.
    """

    def __init__(self, names: Sequence[str], sigma_deg: float, peak_deg: Sequence[float]):
        self.names = list(names)
        self.sigma_deg = float(sigma_deg)
        self.threshold_deg = max(MAX_TILT_DEG, SIGMAS * self.sigma_deg)
        self.peak_deg = [float(p) for p in peak_deg]

    @property
    def tipped(self) -> list[str]:
        """Names of the trajectories whose object leaves the plane."""
        return [n for n, p in zip(self.names, self.peak_deg, strict=True) if p > self.threshold_deg]

    def reason(self) -> str | None:
        """One line for the engine choice, or None when every trajectory stays flat."""
        bad = self.tipped
        if not bad:
            return None
        worst = max(self.peak_deg)
        shown = ", ".join(bad[:3]) + (f" and {len(bad) - 3} more" if len(bad) > 3 else "")
        return (
            f"the object tilts out of the plane (roll/pitch up to {worst:.1f} deg against "
            f"{self.threshold_deg:.1f} deg, {SIGMAS:g} x the {self.sigma_deg:.2f} deg rest noise "
            f"or {MAX_TILT_DEG:g} deg) on {len(bad)} trajectory(ies): {shown}"
        )


def _held_peak(tilt: np.ndarray, ok: np.ndarray, run: int) -> float:
    """The largest value that ``tilt`` exceeds on ``run`` consecutive ``ok`` samples."""
    vals = np.where(ok, tilt, -np.inf)
    if len(vals) < run:
        return 0.0
    win = np.lib.stride_tricks.sliding_window_view(vals, run).min(axis=1)
    return float(max(win.max(), 0.0))


def out_of_plane(rec: Recording, labels: Sequence[PhaseLabels]) -> TiltCheck:
    """Measure every trajectory's tilt away from its rest attitude (grasps excluded)."""
    comps, rests, oks = [], [], []
    for tr, lab in zip(rec.trajectories, labels, strict=True):
        rest = np.asarray(lab.label) == _REST
        finite = np.all(np.isfinite(tr.object_quat), axis=1)
        c = np.full((len(finite), 2), np.nan)
        if finite.any():
            c[finite] = tilt_components(tr.object_quat[finite], rest[finite])
        comps.append(c)
        rests.append(rest & finite)
        oks.append(finite & (np.asarray(lab.label) != _GRASP))
    at_rest = np.concatenate(
        [c[r] for c, r in zip(comps, rests, strict=True)] or [np.zeros((0, 2))]
    )
    if len(at_rest) >= 2:
        dev = at_rest - np.median(at_rest, axis=0)
        sigma = float(np.degrees(1.4826 * np.median(np.abs(dev))))
    else:
        sigma = 0.0
    peaks = []
    for c, ok in zip(comps, oks, strict=True):
        tilt = np.degrees(np.arcsin(np.clip(np.linalg.norm(np.nan_to_num(c), axis=1), 0.0, 1.0)))
        peaks.append(_held_peak(tilt, ok, RUN))
    return TiltCheck([tr.name for tr in rec.trajectories], sigma, peaks)

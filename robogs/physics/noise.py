"""Measurement noise estimated from the data itself (never assumed).

* position / yaw noise: pooled scatter of the tracked pose about a straight line in quiet
  segments (on the table, no contact, slower than 5 cm/s), with a fallback on the second
  differences of the whole stream;
* stamp jitter: scatter of the pose stamps around a regular frame grid fitted per trajectory
  (frame numbers from the median period, so dropped frames do not count as jitter).

Jitter turns into position noise through the speed: the per-sample standard deviation of a
position residual is ``sqrt(sigma_pos^2 + (sigma_t v)^2)``. The *noise floor* is the residual
RMS the true model would leave, computed with these per-sample deviations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.physics.phases import PHASES, PhaseLabels, runs
from robogs.physics.recording import Recording, yaw_of

__all__ = ["NoiseModel", "estimate_noise", "second_difference_sigma"]


@dataclass
class NoiseModel:
    """Noise of the tracked object pose.

    Attributes:
        sigma_pos: planar position noise [m] (per axis).
        sigma_z: vertical position noise [m].
        sigma_yaw: yaw noise [rad].
        sigma_t: stamp jitter [s].
        source: ``"rest"`` (rest segments) or ``"high-frequency"`` (second differences).
        n_rest: number of rest samples used.
    """

    sigma_pos: float
    sigma_z: float
    sigma_yaw: float
    sigma_t: float
    source: str
    n_rest: int

    def per_sample(self, vel: np.ndarray, yaw_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample deviations: position [N, 3] m and yaw [N] rad, jitter included."""
        base = np.array([self.sigma_pos, self.sigma_pos, self.sigma_z])
        sp = np.sqrt(base**2 + (self.sigma_t * vel) ** 2)
        sy = np.sqrt(self.sigma_yaw**2 + (self.sigma_t * yaw_rate) ** 2)
        return sp, sy


def second_difference_sigma(x: np.ndarray) -> float:
    """Robust noise of a sampled smooth signal: 1.4826 MAD of second differences / sqrt(6)."""
    d2 = x[2:] - 2 * x[1:-1] + x[:-2]
    if d2.size == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))


def _rest_sigma(devs: list[np.ndarray], dof: int) -> float:
    if not devs or dof <= 0:
        return float("nan")
    d = np.concatenate(devs)
    mad = 1.4826 * np.median(np.abs(d))
    keep = np.abs(d) <= 4.0 * max(mad, 1e-12)
    frac = keep.mean() if keep.size else 1.0
    return float(np.sqrt(np.sum(d[keep] ** 2) / max(dof * frac, 1.0)))


def _stamp_jitter(t_ns: np.ndarray) -> np.ndarray:
    t = (t_ns - t_ns[0]) * 1e-9
    if len(t) < 4:
        return np.zeros(0)
    d = np.diff(t)
    period = float(np.median(d))
    # frame numbers from rounded gaps (a dropped frame is a gap of ~2 periods)
    k = np.concatenate([[0.0], np.cumsum(np.maximum(np.round(d / period), 1.0))])
    a = np.vstack([np.ones_like(k), k]).T
    coef, *_ = np.linalg.lstsq(a, t, rcond=None)
    return t - a @ coef


def estimate_noise(rec: Recording, labels: list[PhaseLabels] | None = None) -> NoiseModel:
    """Estimate the pose noise and stamp jitter of ``rec`` (labels: phases per trajectory)."""
    jit = np.concatenate([_stamp_jitter(tr.t_ns) for tr in rec.trajectories])
    if jit.size:
        mad = 1.4826 * np.median(np.abs(jit - np.median(jit)))
        keep = np.abs(jit) <= 5 * max(mad, 1e-9)
        sigma_t = float(np.std(jit[keep]))
    else:
        sigma_t = 0.0
    devs_xy: list[np.ndarray] = []
    devs_z: list[np.ndarray] = []
    devs_yaw: list[np.ndarray] = []
    dof = 0
    n_rest = 0
    if labels is not None:
        # "quiet" runs: on the table, no contact, smoothed speed < 5 cm/s. The threshold is far
        # above the speed noise so that the selection does not prefer low-noise samples; slow
        # creep is removed by a straight-line fit per run (2 dof lost per axis).
        ok_ids = [PHASES.index("rest"), PHASES.index("sliding")]
        for tr, lab in zip(rec.trajectories, labels, strict=True):
            yaw = np.unwrap(yaw_of(tr.object_quat))
            speed = np.hypot(lab.vel[:, 0], lab.vel[:, 1])
            quiet = np.isin(lab.label, ok_ids) & (speed < 0.05)
            t = (tr.t_ns - tr.t_ns[0]) * 1e-9
            for a, b in runs(quiet):
                if b - a < 6:
                    continue
                tt = t[a:b] - t[a:b].mean()
                basis = np.vstack([np.ones_like(tt), tt]).T
                proj = basis @ np.linalg.pinv(basis)
                seg = tr.object_pos[a:b]
                res = seg - proj @ seg
                devs_xy.append(res[:, :2].ravel())
                devs_z.append(res[:, 2])
                devs_yaw.append(yaw[a:b] - proj @ yaw[a:b])
                dof += b - a - 2
                n_rest += b - a
    if n_rest >= 8:
        return NoiseModel(
            sigma_pos=_rest_sigma(devs_xy, 2 * dof) if devs_xy else float("nan"),
            sigma_z=_rest_sigma(devs_z, dof),
            sigma_yaw=_rest_sigma(devs_yaw, dof),
            sigma_t=sigma_t,
            source="rest",
            n_rest=n_rest,
        )
    sx = [second_difference_sigma(tr.object_pos[:, i]) for tr in rec.trajectories for i in (0, 1)]
    sz = [second_difference_sigma(tr.object_pos[:, 2]) for tr in rec.trajectories]
    sy = [second_difference_sigma(np.unwrap(yaw_of(tr.object_quat))) for tr in rec.trajectories]
    return NoiseModel(
        sigma_pos=float(np.median(sx)),
        sigma_z=float(np.median(sz)),
        sigma_yaw=float(np.median(sy)),
        sigma_t=sigma_t,
        source="high-frequency",
        n_rest=0,
    )

"""Segment measured object trajectories into phases: free, contact, sliding, rest, impact, grasp.

Phases come from the measured data only (smoothed object velocity, height above the table,
distance of the measured end effector to the measured box, grasp flags), never from the model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.physics.recording import Trajectory, yaw_of

__all__ = ["PHASES", "PhaseLabels", "local_velocity", "segment_phases", "runs"]

PHASES = ("rest", "contact", "sliding", "free", "impact", "grasp")


@dataclass
class PhaseLabels:
    """Per-sample phase of one trajectory.

    Attributes:
        label: [N] index into :data:`PHASES`.
        vel: smoothed object velocity [N, 3] m/s; yaw_rate [N] rad/s.
        height: object height above its resting height [N] m.
        pusher_gap: distance from the pusher sphere to the box [N] m (inf if unknown).
        moving: [N] bool, smoothed speed above the noise-dependent threshold.
    """

    label: np.ndarray
    vel: np.ndarray
    yaw_rate: np.ndarray
    height: np.ndarray
    pusher_gap: np.ndarray
    moving: np.ndarray

    def names(self) -> list[str]:
        return [PHASES[i] for i in self.label]


def local_velocity(t: np.ndarray, x: np.ndarray, half: int = 3) -> np.ndarray:
    """Slope of a local least-squares line over +-``half`` samples (uses real stamps).

    Args:
        t: [N] s. x: [N, D]. Returns [N, D] per second.
    """
    n = len(t)
    x = x.reshape(n, -1)
    out = np.zeros_like(x, dtype=float)
    idx = np.arange(n)
    lo = np.clip(idx - half, 0, n - 1)
    hi = np.clip(idx + half, 0, n - 1)
    # vectorised over samples: window of fixed width with edge clamping
    win = np.stack([np.clip(idx + k, lo, hi) for k in range(-half, half + 1)], axis=1)  # [N, W]
    tw = t[win]
    tw = tw - tw.mean(axis=1, keepdims=True)
    den = (tw * tw).sum(axis=1)
    den = np.where(den > 0, den, np.inf)
    for d in range(x.shape[1]):
        xw = x[win, d]
        out[:, d] = (tw * (xw - xw.mean(axis=1, keepdims=True))).sum(axis=1) / den
    return out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges [a, b) where ``mask`` is True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _box_gap(
    tr: Trajectory, size: tuple[float, float, float], radius: float, length: float
) -> np.ndarray:
    ex = np.stack([np.interp(tr.t_ns, tr.ee_t_ns, tr.ee_pos[:, i]) for i in range(3)], axis=-1)
    psi = np.interp(tr.t_ns, tr.ee_t_ns, np.unwrap(yaw_of(tr.ee_quat)))
    yaw = yaw_of(tr.object_quat)
    c, s = np.cos(yaw), np.sin(yaw)
    hx, hy, hz = (0.5 * v for v in size)
    gaps = []
    for u in np.linspace(-0.5, 0.5, 5) if length > 0 else (0.0,):
        pt = ex + u * length * np.stack([-np.sin(psi), np.cos(psi), 0 * psi], axis=-1)
        d = pt - tr.object_pos
        lx, ly = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        qx, qy = np.clip(lx, -hx, hx), np.clip(ly, -hy, hy)
        gap = np.hypot(lx - qx, ly - qy) - radius
        gaps.append(np.where(np.abs(d[:, 2]) <= hz + radius, gap, np.inf))
    return np.min(gaps, axis=0)


def segment_phases(
    tr: Trajectory,
    *,
    size: tuple[float, float, float],
    table_z: float,
    pusher_radius: float,
    sigma_pos: float,
    pusher_length: float = 0.0,
    contact_margin: float = 0.004,
) -> PhaseLabels:
    """Label every object-pose sample of ``tr`` with a phase.

    Thresholds scale with the position noise ``sigma_pos`` [m]: a sample is moving when its
    smoothed planar speed exceeds ``max(0.02, 5 sigma_v)`` m/s, airborne when it is more than
    ``max(3 mm, 4 sigma_pos)`` above its resting height.
    """
    t = (tr.t_ns - tr.t_ns[0]) * 1e-9
    vel = local_velocity(t, tr.object_pos)
    yaw = np.unwrap(yaw_of(tr.object_quat))
    yaw_rate = local_velocity(t, yaw[:, None])[:, 0]
    dt_med = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    sig_v = sigma_pos / (dt_med * np.sqrt(28.0))  # slope std of a 7-point fit
    v_thr = max(0.02, 5.0 * sig_v)
    height = tr.object_pos[:, 2] - (table_z + 0.5 * size[2])
    z_thr = max(0.003, 4.0 * sigma_pos)
    grasp = np.interp(tr.t_ns, tr.ee_t_ns, tr.grasp.astype(float)) > 0.5
    gap = _box_gap(tr, size, pusher_radius, pusher_length)
    label = np.zeros(len(t), dtype=np.int64)  # rest
    moving = (np.hypot(vel[:, 0], vel[:, 1]) > v_thr) | (np.abs(vel[:, 2]) > v_thr)
    label[moving] = PHASES.index("sliding")
    label[gap < contact_margin + 2 * sigma_pos] = PHASES.index("contact")
    airborne = height > z_thr
    label[airborne] = PHASES.index("free")
    # impact: first samples back on the table after a free flight (and the last free one)
    for a, b in runs(airborne & ~grasp):
        lo, hi = max(a, b - 1), min(len(t), b + 2)
        label[lo:hi] = PHASES.index("impact")
    label[grasp] = PHASES.index("grasp")
    return PhaseLabels(
        label=label, vel=vel, yaw_rate=yaw_rate, height=height, pusher_gap=gap, moving=moving
    )

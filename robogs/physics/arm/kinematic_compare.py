"""End-effector pose residuals of the arm's kinematic model: per channel, per phase, worst windows.

The residual is the recorded pose minus the forward kinematics of the measured joint angles
with the effects already in physics.json (:mod:`robogs.physics.arm.kinematic_model`):
``x y z`` in mm and, when the poses carry an orientation, ``rx ry rz`` in degrees (world-frame
rotation vector). A pose sample's phase comes from the joint motion
(:func:`robogs.physics.arm.compare.label_phases` per joint): ``reversal`` if some
joint is near a velocity reversal, else ``rest`` if every joint rests, else ``accelerating``
if some joint is in its top quarter of accelerations, else ``cruising``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from robogs.physics.arm.compare import ARM_PHASES, label_phases
from robogs.physics.arm.kinematic_model import (
    POSITION_CHANNELS,
    KinProblem,
    base_residual,
    describe,
)

__all__ = ["pose_phases", "compare_kinematic", "position_rms_mm", "orientation_rms_deg"]


def pose_phases(kp: KinProblem) -> np.ndarray:
    """Phase index into :data:`ARM_PHASES` of every pose sample, [N]."""
    lab = label_phases(kp)  # [N, J]
    idx = {n: k for k, n in enumerate(ARM_PHASES)}
    per = np.full(len(lab), idx["cruising"])
    per[(lab == idx["accelerating"]).any(1)] = idx["accelerating"]
    per[(lab == idx["rest"]).all(1)] = idx["rest"]
    per[(lab == idx["reversal"]).any(1)] = idx["reversal"]
    return per


def position_rms_mm(res: np.ndarray) -> float:
    """RMS length of the position error, mm, of residual rows [N, K] (mm, deg)."""
    return float(np.sqrt(np.mean(np.sum(res[:, : len(POSITION_CHANNELS)] ** 2, axis=1))))


def orientation_rms_deg(res: np.ndarray) -> float | None:
    """RMS rotation angle, deg, of residual rows [N, K]; None without orientation."""
    if res.shape[1] <= len(POSITION_CHANNELS):
        return None
    return float(np.sqrt(np.mean(np.sum(res[:, len(POSITION_CHANNELS) :] ** 2, axis=1))))


def compare_kinematic(
    kp: KinProblem,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    window_s: float = 0.5,
    top: int = 5,
) -> dict[str, Any]:
    """Pose residuals of the model with the ``fixed`` effects.

    Returns:
        JSON-ready dict: ``link``, ``units``, ``rms_mm`` (RMS length of the position error),
        ``max_mm``, ``rms_deg`` / ``max_deg`` (rotation angle; None without orientation),
        ``channels`` (per channel rms, noise floor, bias, max and per-phase rms, in the
        channel's unit), ``rms_sigma``, ``worst_phases`` and ``worst_segments`` (windows of
        ``window_s`` ranked by their whitened RMS over all channels).
    """
    res = base_residual(kp, fixed)  # [N, K]
    sig = kp.sigma.cpu().numpy()
    z = res / sig
    info = describe(kp)
    lab = pose_phases(kp)
    d = kp.data
    channels: dict[str, Any] = {}
    for k, c in enumerate(kp.channels):
        r = res[:, k]
        phases = {
            name: {"rms": float(np.sqrt(np.mean(r[lab == p] ** 2))), "fraction": float(np.mean(lab == p))}
            for p, name in enumerate(ARM_PHASES)
            if (lab == p).any()
        }  # fmt: skip
        channels[c] = {
            "unit": info["units"][c],
            "rms": float(np.sqrt(np.mean(r**2))),
            "noise": float(sig[k]),
            "bias": float(np.mean(r)),
            "max_abs": float(np.max(np.abs(r))),
            "phases": phases,
        }
    pos_len = np.linalg.norm(res[:, : len(POSITION_CHANNELS)], axis=1)
    rot_len = np.linalg.norm(res[:, len(POSITION_CHANNELS) :], axis=1) if kp.oriented else None
    worst_phases = []
    for p, name in enumerate(ARM_PHASES):
        sel = lab == p
        if sel.any():
            worst_phases.append(
                {
                    "phase": name,
                    "rms_sigma": float(np.sqrt(np.mean(z[sel] ** 2))),
                    "rms_mm": position_rms_mm(res[sel]),
                    "fraction": float(sel.mean()),
                }
            )
    worst_phases.sort(key=lambda e: -e["rms_sigma"])
    worst = []
    t = d.t_ns.astype(np.int64)
    wn = max(int(window_s * 1e9), 1)
    for tr in range(d.num_traj):
        rows = np.flatnonzero(d.traj == tr)
        win = (t[rows] - t[rows[0]]) // wn
        for w in np.unique(win):
            sel = rows[win == w]
            per = np.sqrt(np.mean(z[sel] ** 2, axis=0))
            energy = np.bincount(lab[sel], weights=(z[sel] ** 2).sum(1), minlength=len(ARM_PHASES))
            worst.append(
                {
                    "trajectory": d.traj_names[tr],
                    "t_start_ns": int(t[sel[0]]),
                    "t_end_ns": int(t[sel[-1]]),
                    "channel": kp.channels[int(np.argmax(per))],
                    "rms_sigma": float(np.sqrt(np.mean(z[sel] ** 2))),
                    "rms_mm": position_rms_mm(res[sel]),
                    "rms_deg": orientation_rms_deg(res[sel]),
                    "phase": ARM_PHASES[int(np.argmax(energy))],
                }
            )
    worst.sort(key=lambda e: -e["rms_sigma"])
    return {
        "residual": "kinematic",
        "link": info["link"],
        "n_samples": kp.n,
        "n_trajectories": d.num_traj,
        "units": info["units"],
        "noise_floor": info["noise_floor"],
        "rms_mm": position_rms_mm(res),
        "max_mm": float(pos_len.max()),
        "rms_deg": orientation_rms_deg(res),
        "max_deg": None if rot_len is None else float(rot_len.max()),
        "channels": channels,
        "rms_sigma": float(np.sqrt(np.mean(z**2))),
        "worst_phases": worst_phases,
        "worst_segments": worst[:top],
        "notes": list(d.notes),
    }

"""Joint-torque residuals of the arm model: per joint, per motion phase, worst time windows.

Phases come from the measured joint motion only, per joint and sample:

* ``reversal``: within ``reversal_s`` (default 0.1 s) of a sign change of the joint velocity
  (where Coulomb friction, backlash and time offsets show most);
* ``rest``: joint speed below ``rest_speed`` (0.01 rad/s) away from reversals;
* ``accelerating``: |qdd| in the top quarter of the joint's accelerations;
* ``cruising``: everything else.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from robogs.physics.arm.torque_model import ArmProblem, predict
from robogs.physics.space import ParamSpace

__all__ = ["ARM_PHASES", "label_phases", "compare_torques", "base_prediction", "worst_phases"]

ARM_PHASES = ("rest", "reversal", "accelerating", "cruising")


def label_phases(
    pb: ArmProblem, *, reversal_s: float = 0.1, rest_speed: float = 0.01
) -> np.ndarray:
    """Phase index into :data:`ARM_PHASES` of every sample and joint, [N, J]."""
    d = pb.data
    qd, qdd = d.qd, d.qdd
    n, j = qd.shape
    lab = np.full((n, j), ARM_PHASES.index("cruising"), dtype=np.int64)
    thr = np.quantile(np.abs(qdd), 0.75, axis=0) if n else np.zeros(j)
    lab[np.abs(qdd) >= thr[None, :]] = ARM_PHASES.index("accelerating")
    lab[np.abs(qd) < rest_speed] = ARM_PHASES.index("rest")
    t = d.t_ns.astype(np.int64)
    for k in range(d.num_traj):
        rows = np.flatnonzero(d.traj == k)
        s = np.sign(qd[rows])
        flips = s[1:] * s[:-1] < 0  # [n-1, J]
        for jj in range(j):
            at = rows[1:][flips[:, jj]]
            if len(at) == 0:
                continue
            tt = t[rows]
            lo = np.searchsorted(tt, t[at] - int(reversal_s * 1e9))
            hi = np.searchsorted(tt, t[at] + int(reversal_s * 1e9), side="right")
            mark = np.zeros(len(rows) + 1, dtype=np.int64)
            np.add.at(mark, lo, 1)
            np.add.at(mark, hi, -1)
            near = np.cumsum(mark)[:-1] > 0
            lab[rows[near], jj] = ARM_PHASES.index("reversal")
    return lab


def base_prediction(pb: ArmProblem, fixed: dict[str, dict[str, float]] | None) -> torch.Tensor:
    """Model efforts [N, J] with only the ``fixed`` effects (physics.json)."""
    space = ParamSpace((), ())
    return predict(space.defaults(1, dtype=pb.Y.dtype, device=pb.Y.device), space, pb, fixed)[0]


def compare_torques(
    pb: ArmProblem,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    window_s: float = 0.5,
    top: int = 5,
) -> dict[str, Any]:
    """Residuals ``tau_meas - tau_model`` in N m.

    Args:
        pb: prepared data; fixed: effects held at physics.json values.
        window_s: length of the windows ranked as worst segments, s.
        top: number of worst windows reported.

    Returns:
        JSON-ready dict: ``joints`` (rms, noise floor, bias, max, per-phase rms),
        ``rms_sigma`` (overall RMS in noise units), ``worst_phases`` (:func:`worst_phases`) and
        ``worst_segments``: the ``top`` windows of ``window_s`` with the largest whitened RMS on
        one joint, each labelled with the phase that holds most of that joint's squared
        residual in the window.
    """
    res = (pb.tau - base_prediction(pb, fixed)).cpu().numpy()  # [N, J]
    sig = pb.sigma.cpu().numpy()
    lab = label_phases(pb)
    d = pb.data
    joints: dict[str, Any] = {}
    for k, jn in enumerate(d.joint_names):
        r = res[:, k]
        phases = {}
        for p, name in enumerate(ARM_PHASES):
            sel = lab[:, k] == p
            if sel.any():
                phases[name] = {
                    "rms_nm": float(np.sqrt(np.mean(r[sel] ** 2))),
                    "fraction": float(sel.mean()),
                }
        joints[jn] = {
            "rms_nm": float(np.sqrt(np.mean(r**2))),
            "noise_nm": float(sig[k]),
            "bias_nm": float(np.mean(r)),
            "max_abs_nm": float(np.max(np.abs(r))),
            "phases": phases,
        }
    worst = []
    t = d.t_ns.astype(np.int64)
    wn = int(window_s * 1e9)
    for tr in range(d.num_traj):
        rows = np.flatnonzero(d.traj == tr)
        win = (t[rows] - t[rows[0]]) // max(wn, 1)
        for w in np.unique(win):
            sel = rows[win == w]
            z = res[sel] / sig
            per_joint = np.sqrt(np.mean(z**2, axis=0))
            jj = int(np.argmax(per_joint))
            energy = np.bincount(lab[sel, jj], weights=z[:, jj] ** 2, minlength=len(ARM_PHASES))
            worst.append(
                {
                    "trajectory": d.traj_names[tr],
                    "t_start_ns": int(t[sel[0]]),
                    "t_end_ns": int(t[sel[-1]]),
                    "joint": d.joint_names[jj],
                    "rms_nm": float(np.sqrt(np.mean(res[sel, jj] ** 2))),
                    "rms_sigma": float(per_joint[jj]),
                    "phase": ARM_PHASES[int(np.argmax(energy))],
                }
            )
    worst.sort(key=lambda e: -e["rms_sigma"])
    return {
        "model": "arm",
        "n_samples": int(res.shape[0]),
        "n_trajectories": d.num_traj,
        "joints": joints,
        "rms_sigma": float(np.sqrt(np.mean((res / sig) ** 2))),
        "worst_phases": worst_phases(res / sig, lab, d.joint_names),
        "worst_segments": worst[:top],
    }


def worst_phases(
    z: np.ndarray, lab: np.ndarray, joint_names: tuple[str, ...] | list[str]
) -> list[dict[str, Any]]:
    """Phases ranked by their whitened residual RMS over all joints (largest first).

    Args:
        z: [N, J] residuals divided by each joint's noise floor.
        lab: [N, J] phase index of every sample and joint (:func:`label_phases`).
        joint_names: [J].

    Returns:
        ``[{"phase", "rms_sigma", "fraction", "joint", "joint_rms_sigma"}]``: ``fraction`` of
        the samples (over all joints) in the phase, and the joint where it is worst.
    """
    out = []
    for p, name in enumerate(ARM_PHASES):
        sel = lab == p
        if not sel.any():
            continue
        per_joint = [
            (float(np.sqrt(np.mean(z[sel[:, k], k] ** 2))), k)
            for k in range(z.shape[1])
            if sel[:, k].any()
        ]
        jr, jk = max(per_joint)
        out.append(
            {
                "phase": name,
                "rms_sigma": float(np.sqrt(np.mean(z[sel] ** 2))),
                "fraction": float(sel.mean()),
                "joint": joint_names[jk],
                "joint_rms_sigma": jr,
            }
        )
    out.sort(key=lambda e: -e["rms_sigma"])
    return out

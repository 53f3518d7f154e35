"""Synthetic arm datasets with recorded end-effector poses and one hidden kinematic effect.

Independent of the toolkit's kinematic model: the URDF is parsed by
:func:`robogs.synth.armlogs.dynamics.parse_arm`, the forward kinematics is a small numpy loop over
the URDF joints written here (:func:`urdf_fk`), gravity torques come from the world-frame
Newton-Euler of :mod:`robogs.synth.armlogs.dynamics`, rotations to quaternions from
``scipy.spatial.transform``.

Each segment is the sum-of-sines excitation of :func:`robogs.synth.armlogs.generate.excitation`
played through a time warp that stops the arm for 0.4 s every 2 s (cosine ramps of 0.5 s), so
joints rest and reverse (ramps long enough for the Savitzky-Golay accelerations of the torque
model to follow them: with 0.15 s ramps a spurious armature passed its gate). The motor-side angles ``q(t)`` are what the encoders log (125 Hz,
noise 1e-5 rad; velocities noise 2e-3 rad/s). The end effector ``ee_link`` is recorded at
``ee_rate_hz`` (default 50 Hz, stamps offset by 3 ms from the joint clock) at the link angles

* ``none``: ``theta = q``;
* ``joint_elasticity``: ``theta = q - c * ID(theta, 0, 0)`` (the static equilibrium of a
  torsion spring of compliance ``c`` [rad/(N m)] holding the link against gravity; solved by
  fixed-point iteration);
* ``backlash``: the play (dead-band) operator ``theta_k = clip(theta_{k-1}, q_k - b, q_k + b)``
  run at 1 kHz (the link rests while the motor crosses the band of half-width ``b`` [rad]);
* ``kinematic_offsets``: ``theta = q + dtheta``, and each joint frame translated by
  ``da * u + dd * axis`` before its rotation (``u``: the joint frame's x axis made
  perpendicular to the axis).

Noise on the recorded pose: ``ee_noise_mm`` (default 0.2 mm) per axis on the position and a
world-frame rotation vector of ``ee_noise_deg`` (default 0.05 deg) per axis on the orientation.
``orientation=False`` writes NaN quaternions (a position-only tracker). ``efforts=True`` also
logs joint torques of the rigid arm along the motor-side trajectory (effort noise as in
:class:`~robogs.synth.armlogs.generate.ArmLogSpec`), plus torque effects named in ``effect`` with
``+`` (keys of :data:`robogs.synth.armlogs.generate.DEFAULT_PARAMS`).

The dataset is written through the robogs writer; the truth goes beside it
(``<out>.truth.json``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from robogs.synth.armlogs.dynamics import ArmSpec, parse_arm, world_inverse_dynamics
from robogs.synth.armlogs.generate import DEFAULT_PARAMS, _torques, excitation

__all__ = ["KIN_PARAMS", "KinLogSpec", "generate_kinematic_dataset", "urdf_fk", "kin_truth_path"]

KIN_PARAMS: dict[str, dict[str, list[float]]] = {
    "none": {},
    "joint_elasticity": {"compliance": [5e-5, 5e-5, 8e-5, 2e-4, 2e-4, 2e-4]},
    "backlash": {"backlash": [6e-4, 8e-4, 8e-4, 1e-3, 1e-3, 1e-3]},
    "kinematic_offsets": {
        "dtheta": [2e-3, -1.5e-3, 2.5e-3, -2e-3, 1.5e-3, 1e-3],
        "dd": [1.5e-3, 1e-3, 0.0, 0.0, -1e-3, 1e-3],
        "da": [1e-3, -1e-3, 1.5e-3, -1e-3, 1e-3, 0.5e-3],
    },
}
"""Default hidden parameters per joint (UR5 joint order): compliance rad/(N m), backlash
half-width rad, offsets rad and m."""

_PAUSE_EVERY_S, _PAUSE_HALF_S = 2.0, 0.2
_FINE_HZ = 1000.0
_T0_NS = 1_700_000_000_000_000_000


@dataclass
class KinLogSpec:
    """What to generate (see the module docstring)."""

    effect: str = "none"
    params: dict[str, Any] | None = None
    segments: int = 4
    duration_s: float = 6.0
    rate_hz: float = 125.0
    ee_rate_hz: float = 50.0
    ee_link: str = "tool0"
    ee_noise_mm: float = 0.2
    ee_noise_deg: float = 0.05
    orientation: bool = True
    efforts: bool = False
    effort_noise: tuple[float, ...] = (0.2, 0.2, 0.15, 0.05, 0.05, 0.05)
    position_noise: float = 1e-5
    velocity_noise: float = 2e-3
    pauses: bool = True
    ramp_s: float = 0.5
    seed: int = 0


def kin_truth_path(out: str | Path) -> Path:
    """``<out>.truth.json``: where the truth of the dataset at ``out`` is written."""
    out = Path(out)
    return out.with_name(out.name + ".truth.json")


def _perpendicular(axis: np.ndarray) -> np.ndarray:
    for e in np.eye(3)[:2]:
        u = e - (e @ axis) * axis
        if np.linalg.norm(u) > 1e-6:
            return u / np.linalg.norm(u)
    raise ValueError("degenerate axis")


def _rodrigues(axis: np.ndarray, ang: np.ndarray) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def urdf_fk(
    arm: ArmSpec,
    theta: np.ndarray,
    link: str,
    da: np.ndarray | None = None,
    dd: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Pose of ``link`` in the root frame for link angles ``theta`` [N, J] (actuated order).

    Each actuated joint's frame is translated by ``da[j] u + dd[j] axis`` (m) before its motion.

    Returns:
        position [N, 3] m, rotation [N, 3, 3].
    """
    n, nj = theta.shape
    da = np.zeros(nj) if da is None else np.asarray(da, float)
    dd = np.zeros(nj) if dd is None else np.asarray(dd, float)
    col = {name: k for k, name in enumerate(arm.actuated)}
    R = {arm.root: np.repeat(np.eye(3)[None], n, 0)}
    p = {arm.root: np.zeros((n, 3))}
    for j in arm.joints:
        rp, pp = R[j.parent], p[j.parent]
        ro, to = j.origin[:3, :3], j.origin[:3, 3].copy()
        k = col.get(j.name)
        if k is not None:
            to = to + ro @ (da[k] * _perpendicular(j.axis) + dd[k] * j.axis)
        if j.type in ("revolute", "continuous"):
            R[j.child] = rp @ ro @ _rodrigues(j.axis, theta[:, k])
            p[j.child] = pp + rp @ to
        elif j.type == "prismatic":
            R[j.child] = rp @ ro
            p[j.child] = pp + rp @ to + (rp @ ro @ j.axis) * theta[:, k, None]
        else:
            R[j.child] = rp @ ro
            p[j.child] = pp + rp @ to
    return p[link], R[link]


def _warp(t: np.ndarray, duration: float, ramp: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time warp ``w(t)`` with ``w' = 1 - sum of pause bumps`` (cosine ramps of ``ramp`` s);
    returns w, w', w'' at ``t``."""
    fine = np.arange(0.0, duration + 1.0, 1.0 / _FINE_HZ)

    def bumps(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        g, dg = np.zeros_like(x), np.zeros_like(x)
        for c in np.arange(_PAUSE_EVERY_S / 2, duration, _PAUSE_EVERY_S):
            d = np.abs(x - c)
            on = (d > _PAUSE_HALF_S) & (d < _PAUSE_HALF_S + ramp)
            arg = np.pi * (d - _PAUSE_HALF_S) / ramp
            g += np.where(d <= _PAUSE_HALF_S, 1.0, 0.0) + np.where(on, 0.5 * (1 + np.cos(arg)), 0)
            dg += np.where(on, -np.sign(x - c) * 0.5 * np.pi / ramp * np.sin(arg), 0.0)
        return g, dg

    gf, _ = bumps(fine)
    wd = 1.0 - gf
    w_fine = np.concatenate([[0.0], np.cumsum(0.5 * (wd[1:] + wd[:-1]) / _FINE_HZ)])
    g, dg = bumps(t)
    return np.interp(t, fine, w_fine), 1.0 - g, -dg


def _motion(traj, t: np.ndarray, duration: float, ramp: float | None):
    """q, qd, qdd [N, J] of the excitation at ``t``, warped by pauses unless ``ramp`` is None."""
    if ramp is None:
        return traj(t)
    w, w1, w2 = _warp(t, duration, ramp)
    q, qd, qdd = traj(w)
    return q, qd * w1[:, None], qdd * (w1**2)[:, None] + qd * w2[:, None]


def _play(q: np.ndarray, qd0: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Play operator (dead band of half-width ``b``) along the rows of ``q`` [N, J]."""
    out = np.empty_like(q)
    x = q[0] - b * np.sign(qd0)
    for k in range(len(q)):
        x = np.clip(x, q[k] - b, q[k] + b)
        out[k] = x
    return out


def _cycle(x, n: int) -> np.ndarray:
    return np.resize(np.atleast_1d(np.asarray(x, dtype=float)), n)


def _link_angles(
    arm: ArmSpec,
    kin: str | None,
    p: dict[str, Any],
    traj,
    t_ee: np.ndarray,
    duration: float,
    ramp: float | None,
) -> np.ndarray:
    nj = len(arm.actuated)
    q, _, _ = _motion(traj, t_ee, duration, ramp)
    if kin == "joint_elasticity":
        c = _cycle(p["compliance"], nj)
        theta = q.copy()
        zero = np.zeros_like(q)
        for _ in range(4):
            theta = q - c * world_inverse_dynamics(arm, theta, zero, zero)
        return theta
    if kin == "backlash":
        fine = np.arange(0.0, t_ee[-1] + 2.0 / _FINE_HZ, 1.0 / _FINE_HZ)
        qf, qdf, _ = _motion(traj, fine, duration, ramp)
        lf = _play(qf, qdf[0], _cycle(p["backlash"], nj))
        return np.stack([np.interp(t_ee, fine, lf[:, k]) for k in range(nj)], axis=1)
    if kin == "kinematic_offsets":
        return q + _cycle(p["dtheta"], nj)
    return q


def generate_kinematic_dataset(
    out: str | Path, urdf: str | Path, spec: KinLogSpec | None = None
) -> dict[str, Any]:
    """Write the dataset at ``out`` and its truth at :func:`kin_truth_path`; return the truth."""
    from robogs.format.dataset import Dataset

    spec = spec or KinLogSpec()
    names = [e.strip() for e in spec.effect.split("+")]
    kins = [e for e in names if e in KIN_PARAMS and e != "none"]
    torque = [e for e in names if e in DEFAULT_PARAMS and e != "none"]
    if len(kins) > 1 or set(names) - set(kins) - set(torque) - {"none"}:
        raise ValueError(
            f"{spec.effect!r}: at most one of {sorted(KIN_PARAMS)} plus torque effects of "
            f"{sorted(DEFAULT_PARAMS)}, joined by '+'"
        )
    kin = kins[0] if kins else None
    params: dict[str, Any] = {}
    for e in kins + torque:
        params.update(KIN_PARAMS.get(e) or DEFAULT_PARAMS[e])
    params.update(spec.params or {})
    arm = parse_arm(urdf)
    nj = len(arm.actuated)
    last = next(jt.child for jt in reversed(arm.joints) if jt.type != "fixed")
    rng = np.random.default_rng(spec.seed)
    da = _cycle(params.get("da", 0.0), nj) if kin == "kinematic_offsets" else None
    dd = _cycle(params.get("dd", 0.0), nj) if kin == "kinematic_offsets" else None
    n = int(round(spec.duration_s * spec.rate_hz))
    t = np.arange(n) / spec.rate_hz
    t_ee = np.arange(0.003, spec.duration_s - 2.0 / spec.rate_hz, 1.0 / spec.ee_rate_hz)
    period_ns = int(round(1e9 / spec.rate_hz))
    sig_e = _cycle(spec.effort_noise, nj)
    ramp = spec.ramp_s if spec.pauses else None
    out = Path(out)
    w = Dataset.create(out, overwrite=True, name=out.name)
    with w:
        w.copy_file("robot/robot.urdf", urdf)
        w.set_robot("robot/robot.urdf", base_link=arm.root, ee_link=spec.ee_link)
        for s in range(spec.segments):
            traj = excitation(arm, rng)
            q, qd, qdd = _motion(traj, t, spec.duration_s, ramp)
            t0 = _T0_NS + s * (n * period_ns + 10_000_000_000)
            js: dict[str, Any] = {"t_ns": t0 + np.arange(n, dtype=np.int64) * period_ns}
            qm = q + rng.normal(0, spec.position_noise, q.shape)
            qdm = qd + rng.normal(0, spec.velocity_noise, qd.shape)
            for k, j in enumerate(arm.actuated):
                js[f"position.{j}"] = qm[:, k]
                js[f"velocity.{j}"] = qdm[:, k]
            if spec.efforts:
                tau = _torques(arm, torque, params, q, qd, qdd, last)
                tau = tau + rng.normal(0, 1, tau.shape) * sig_e
                for k, j in enumerate(arm.actuated):
                    js[f"effort.{j}"] = tau[:, k]
            theta = _link_angles(arm, kin, params, traj, t_ee, spec.duration_s, ramp)
            pos, rot = urdf_fk(arm, theta, spec.ee_link, da, dd)
            pos = pos + rng.normal(0, spec.ee_noise_mm * 1e-3, pos.shape)
            noise = Rotation.from_rotvec(rng.normal(0, np.radians(spec.ee_noise_deg), pos.shape))
            quat = (noise * Rotation.from_matrix(rot)).as_quat()[:, [3, 0, 1, 2]]  # wxyz
            quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
            if not spec.orientation:
                quat[:] = np.nan
            ee_t = t0 + np.round(t_ee * 1e9).astype(np.int64)
            ee = {"t_ns": ee_t, "link": pa.array([spec.ee_link] * len(ee_t), pa.string())}
            ee |= dict(zip(("x", "y", "z"), pos.T, strict=True))
            ee |= dict(zip(("qw", "qx", "qy", "qz"), quat.T, strict=True))
            eid = f"seg{s:02d}"
            w.write_table(f"episodes/{eid}/joint_states.parquet", pa.table(js), kind="joint_states")
            w.write_table(f"episodes/{eid}/ee_poses.parquet", pa.table(ee), kind="ee_poses")
            streams = {
                kind: {
                    "kind": kind,
                    "path": f"episodes/{eid}/{kind}.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                    "nominal_rate_hz": rate,
                }
                for kind, rate in (("joint_states", spec.rate_hz), ("ee_poses", spec.ee_rate_hz))
            }
            w.add_episode(
                eid, start_ns=int(js["t_ns"][0]), end_ns=int(js["t_ns"][-1]), streams=streams
            )
        w.set_physics(
            {"objects": {}, "gravity_mps2": [0.0, 0.0, -9.81]}, note="nominal (the URDF alone)"
        )
        w.manifest["provenance"] = {"generator": "robogs.synth.armlogs.kinematic"}
        w.commit()
    truth = {
        "effect": spec.effect,
        "kinematic_effect": kin,
        "torque_effects": torque,
        "params": {k: (list(_cycle(v, nj)) if k != "com" else v) for k, v in params.items()},
        "joints": list(arm.actuated),
        "ee_link": spec.ee_link,
        "ee_noise_mm": spec.ee_noise_mm,
        "ee_noise_deg": spec.ee_noise_deg,
        "spec": {k: v for k, v in asdict(spec).items() if k != "params"},
    }
    kin_truth_path(out).write_text(json.dumps(truth, indent=2))
    return truth

"""Synthetic joint logs of an arm with hidden effects, written as UR RTDE-style CSV.

Each segment is an exciting trajectory (a sum of sines per joint, Swevers et al. 1997 style
periodic excitation, random phases and amplitudes inside the joint limits) sampled at
``rate_hz``. Torques come from :func:`robogs.synth.armlogs.dynamics.world_inverse_dynamics` (an
implementation independent of the toolkit's) plus the hidden effect:

* ``none``: rigid-body torques only (null case);
* ``joint_friction``: ``fc tanh(qd / v_s) + fv qd`` per joint;
* ``payload``: a point mass ``mass`` at ``com`` in the frame of the last moving link;
* ``armature``: ``ia qdd`` per joint;
* ``mass_scale``: every link mass and inertia of the URDF times ``s``;
* ``effort_time_offset``: effort samples stamped ``delta`` s late.

Several effects are hidden together when ``effect`` joins their names with ``+`` (e.g.
``payload+joint_friction``); their parameters share one dictionary (the names do not collide).

Measurement noise: Gaussian on positions, velocities and efforts. The CSV holds ``timestamp``
(s), ``actual_q_i`` (rad), ``actual_qd_i`` (rad/s), ``actual_current_i`` (A, effort divided by a
torque constant) and ``target_moment_i`` (N m), i = 0..J-1 in URDF joint order. The truth is
returned and written to ``truth.json`` next to the logs.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robogs.synth.armlogs.dynamics import ArmSpec, LinkSpec, parse_arm, world_inverse_dynamics

__all__ = ["ArmLogSpec", "generate_armlog", "DEFAULT_PARAMS", "SMOOTHING_VELOCITY", "excitation"]

SMOOTHING_VELOCITY = 0.02
"""``v_s`` [rad/s] of the Coulomb friction of the generator."""

DEFAULT_PARAMS: dict[str, dict[str, Any]] = {
    "none": {},
    "joint_friction": {"fc": [4.0, 4.0, 3.0, 1.0, 1.0, 1.0], "fv": [3.0, 3.0, 2.0, 0.6, 0.6, 0.6]},
    "payload": {"mass": 1.5, "com": [0.01, 0.02, 0.06]},
    "armature": {"ia": [0.6, 0.6, 0.3, 0.08, 0.08, 0.08]},
    "mass_scale": {"s": 1.15},
    "effort_time_offset": {"delta": 0.008},
}


@dataclass
class ArmLogSpec:
    """What to generate.

    Attributes:
        effect: hidden effect name (keys of :data:`DEFAULT_PARAMS`), or several joined by ``+``.
        params: effect parameters (default :data:`DEFAULT_PARAMS`; per-joint lists cycle).
        segments: number of trajectories (one CSV each, or one file with time gaps).
        duration_s: length of each segment, s.
        rate_hz: sampling rate.
        effort_noise: per-joint effort noise, N m (cycled).
        position_noise: rad. velocity_noise: rad/s.
        torque_constant: N m / A used for ``actual_current`` (cycled).
        single_file: write all segments into ``log.csv`` separated by ``gap_s``.
        gap_s: time gap between segments in the single file, s.
        seed: random seed.
        t0_s: controller time of the first sample, s.
    """

    effect: str = "none"
    params: dict[str, Any] | None = None
    segments: int = 4
    duration_s: float = 8.0
    rate_hz: float = 125.0
    effort_noise: tuple[float, ...] = (0.2, 0.2, 0.15, 0.05, 0.05, 0.05)
    position_noise: float = 1e-5
    velocity_noise: float = 2e-3
    torque_constant: tuple[float, ...] = (13.5, 13.5, 13.5, 9.0, 9.0, 9.0)
    single_file: bool = False
    gap_s: float = 5.0
    seed: int = 0
    t0_s: float = 1234.5
    payload_link: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _cycle(x, n: int) -> np.ndarray:
    a = np.atleast_1d(np.asarray(x, dtype=float))
    return np.resize(a, n)


def excitation(
    arm: ArmSpec, rng: np.random.Generator, n_harm: int = 4
) -> Callable[[np.ndarray], tuple]:
    """Draw a sum-of-sines trajectory inside the joint limits.

    Returns:
        ``traj(t)`` giving q, qd, qdd [N, J] (rad, rad/s, rad/s^2) at times ``t`` [N] s
        (analytic derivatives).
    """
    j = len(arm.actuated)
    lower = np.array([jt.lower for jt in arm.joints if jt.name in arm.actuated])
    upper = np.array([jt.upper for jt in arm.joints if jt.name in arm.actuated])
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    centre = 0.5 * (lower + upper)
    half = 0.5 * (upper - lower)
    home = np.clip(np.resize([0.0, -1.3, 1.5, -1.6, -1.5, 0.0], j), lower + 0.3, upper - 0.3)
    q0 = home + rng.uniform(-0.3, 0.3, j)
    freqs = rng.uniform(0.1, 0.6, (j, n_harm))
    phases = rng.uniform(0, 2 * np.pi, (j, n_harm))
    amp = rng.uniform(0.3, 1.0, (j, n_harm))
    total = np.minimum(0.9, 0.8 * (half - np.abs(q0 - centre)))
    amp = amp / amp.sum(axis=1, keepdims=True) * total[:, None]
    w = 2 * np.pi * freqs

    def traj(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        arg = w[None] * t[:, None, None] + phases[None]
        q = q0 + (amp[None] * np.sin(arg)).sum(-1)
        qd = (amp[None] * w[None] * np.cos(arg)).sum(-1)
        qdd = -(amp[None] * w[None] ** 2 * np.sin(arg)).sum(-1)
        return q, qd, qdd

    return traj


def _hidden(effect: str) -> list[str]:
    """The effect names of ``a+b+...`` (validated)."""
    names = [e.strip() for e in effect.split("+")]
    bad = [e for e in names if e not in DEFAULT_PARAMS]
    if bad or len(set(names)) != len(names) or ("none" in names and len(names) > 1):
        raise ValueError(
            f"unknown or repeated hidden effect in {effect!r}; choose from {sorted(DEFAULT_PARAMS)}"
            " (several joined by '+', 'none' alone)"
        )
    return names


def _torques(
    arm: ArmSpec, effects: list[str], params: dict[str, Any], q, qd, qdd, payload_link: str
) -> np.ndarray:
    j = q.shape[1]
    extra = None
    if "payload" in effects:
        extra = (payload_link, float(params["mass"]), np.asarray(params["com"], dtype=float))
    if "mass_scale" in effects:
        s = float(params["s"])
        links = {
            k: LinkSpec(lk.name, lk.mass * s, lk.com.copy(), lk.inertia * s)
            for k, lk in arm.links.items()
        }
        arm = ArmSpec(links, arm.joints, arm.actuated, arm.root)
    tau = world_inverse_dynamics(arm, q, qd, qdd, extra_mass=extra)
    if "joint_friction" in effects:
        tau += (
            _cycle(params["fc"], j) * np.tanh(qd / SMOOTHING_VELOCITY)
            + _cycle(params["fv"], j) * qd
        )
    if "armature" in effects:
        tau += _cycle(params["ia"], j) * qdd
    return tau


def generate_armlog(
    out_dir: str | Path, urdf: str | Path, spec: ArmLogSpec | None = None
) -> dict[str, Any]:
    """Write the synthetic logs and ``truth.json`` into ``out_dir``; return the truth.

    Args:
        out_dir: folder to create (``segment_XX.csv`` files, or ``log.csv``).
        urdf: robot URDF (with inertials).
        spec: what to generate.
    """
    spec = spec or ArmLogSpec()
    effects = _hidden(spec.effect)
    params: dict[str, Any] = {}
    for e in effects:
        params.update(DEFAULT_PARAMS[e])
    params.update(spec.params or {})
    arm = parse_arm(urdf)
    j = len(arm.actuated)
    last = next(jt.child for jt in reversed(arm.joints) if jt.type != "fixed")
    payload_link = spec.payload_link or last
    rng = np.random.default_rng(spec.seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dt = 1.0 / spec.rate_hz
    n = int(round(spec.duration_s * spec.rate_hz))
    t = np.arange(n) * dt
    sig_e = _cycle(spec.effort_noise, j)
    kt = _cycle(spec.torque_constant, j)
    header = (
        ["timestamp"]
        + [f"actual_q_{i}" for i in range(j)]
        + [f"actual_qd_{i}" for i in range(j)]
        + [f"actual_current_{i}" for i in range(j)]
        + [f"target_moment_{i}" for i in range(j)]
    )
    blocks = []
    t_start = spec.t0_s
    for _ in range(spec.segments):
        traj = excitation(arm, rng)
        q, qd, qdd = traj(t)
        # the effort stamped t shows the torque of time t - delta
        tau_src = (
            traj(t - float(params["delta"])) if "effort_time_offset" in effects else (q, qd, qdd)
        )
        tau = _torques(arm, effects, params, *tau_src, payload_link)
        tau_meas = tau + rng.normal(0, 1, tau.shape) * sig_e
        q_meas = q + rng.normal(0, spec.position_noise, q.shape)
        qd_meas = qd + rng.normal(0, spec.velocity_noise, qd.shape)
        stamps = t_start + t
        block = np.column_stack([stamps, q_meas, qd_meas, tau_meas / kt, tau_meas])
        blocks.append(block)
        t_start = stamps[-1] + (spec.gap_s if spec.single_file else dt)
    fmt = ["%.6f"] + ["%.9f"] * (4 * j)
    files = []
    if spec.single_file:
        path = out / "log.csv"
        np.savetxt(
            path, np.vstack(blocks), delimiter=",", header=",".join(header), comments="", fmt=fmt
        )
        files.append(path.name)
    else:
        for s, block in enumerate(blocks):
            path = out / f"segment_{s:02d}.csv"
            np.savetxt(path, block, delimiter=",", header=",".join(header), comments="", fmt=fmt)
            files.append(path.name)
    truth = {
        "effect": spec.effect,
        "effects": effects,
        "params": {
            k: (list(_cycle(v, j)) if isinstance(v, list) and k != "com" else v)
            for k, v in params.items()
        },
        "joints": list(arm.actuated),
        "payload_link": payload_link,
        "effort_noise": list(sig_e),
        "smoothing_velocity": SMOOTHING_VELOCITY,
        "files": files,
        "spec": {k: v for k, v in asdict(spec).items() if k != "params"},
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2))
    return truth

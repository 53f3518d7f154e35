"""Joint effects of the arm's kinematic model, judged on recorded end-effector poses.

The measured joint angle ``q_j`` is the motor side (the encoder behind the gear); the link
angle the forward kinematics needs is

    theta_j = q_j + dtheta_j + c_j tau_g,j(q) - b_j s_j(t)

and each joint frame may be displaced before its rotation by ``da_j`` along the declared
perpendicular ``u_j`` and ``dd_j`` along the axis ``z_j`` (see
:mod:`robogs.physics.arm.kinematic_model` for the frames). Three effects:

* ``joint_elasticity`` - compliance ``c_j`` [rad/(N m)] of the joint and gear: the link
  droops by ``c_j tau_g,j`` under the *gravity* torque ``tau_g = -ID(q, 0, 0)`` (recursive
  Newton-Euler at zero velocity and acceleration with the URDF inertials plus any payload or
  mass scale already in physics.json). The dynamic torques are left out: the quasi-static
  droop is what a pose measurement sees (Khalil & Dombre, *Modeling, Identification and
  Control of Robots*, 2002, on joint compliance in geometric calibration).
* ``backlash`` - half-width ``b_j`` [rad] of the dead band: once engaged the link lags the
  motor by ``b_j`` against the last direction of motion ``s_j``, ``theta_j = q_j - b_j s_j``,
  and ``s_j`` is held while the joint is still. The model is the play (dead-band) operator
  ``theta_k = clip(theta_{k-1}, q_k - b, q_k + b)`` run on the measured joint angles at the
  joint-log rate (Nordin & Gutman 2002, "Controlling mechanical systems with backlash - a
  survey", Automatica 38): after a reversal the link rests until the motor has crossed the
  band (``2 b_j`` of travel), then follows at ``q - b s``. The direction therefore switches
  on position, not on a velocity threshold: a joint slower than any speed keeps its side, and
  encoder noise (1e-5 rad on the synthetic logs) far below ``b`` cannot flip it. The start
  is ``q_0 - b s_0`` with ``s_0`` the sign of the first velocity if it exceeds
  ``REST_SPEED`` (0.01 rad/s, the rest threshold of the phase labels), else 0. The output
  is piecewise linear in ``b`` (continuous, exact forward differences away from the kinks);
  a negative ``b`` mirrors it (``sign(b) play(|b|)``) so the null distribution of the fit is
  symmetric.
* ``kinematic_offsets`` - joint-zero offset ``dtheta_j`` [rad], ``dd_j`` [m] along the joint
  axis and ``da_j`` [m] along the perpendicular ``u_j`` (modified-DH ``d_j`` and
  ``a_{j-1}`` on MDH-framed URDFs; Khalil & Kleinfinger 1986). ``dalpha`` and Hayati's
  ``dbeta`` (Hayati & Mirmirani 1985, for parallel axes) are not modelled. Groups of
  parameters that act only together (``dd`` of parallel axes, ``dtheta`` of the last joint
  when only positions are measured) are reported unidentifiable by the fit
  (:func:`robogs.physics.arm.identify.identifiable_columns`).

On a prismatic joint ``dtheta``, ``c`` and ``b`` act on its displacement (m, m/N, m). A mimic
joint follows its source's link angle (times its multiplier); ``da`` and ``dd`` move only the
frame of the actuated joint itself. The torque model ignores these effects (their change of
the gravity torque is second order).

physics.json: ``joints.<j>.compliance_rad_per_nm``, ``joints.<j>.backlash_rad`` and
``joints.<j>.offsets = {dtheta_rad, dd_m, da_m}``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch

from robogs.format.kinematics.offsets import OFFSET_KEYS  # parameter -> joints.<j>.offsets key
from robogs.physics.arm.effects import ArmEffect, KinState
from robogs.physics.effects import Param, register_effect

__all__ = ["JointElasticity", "Backlash", "KinematicOffsets", "REST_SPEED", "OFFSET_KEYS"]

REST_SPEED = 0.01
"""rad/s; a joint slower than this at the start of a log has no direction of motion yet."""


def _read_scalar(eff: ArmEffect, doc: dict[str, Any], pname: str, key: str) -> dict | None:
    joints = doc.get("joints") or {}
    vals = {f"{pname}.{j}": float((joints.get(j) or {}).get(key, 0.0)) for j in eff.joints}
    return vals if any(v != 0.0 for v in vals.values()) else None


def _write_scalar(values: dict[str, float], doc: dict[str, Any], pname: str, key: str) -> None:
    """``joints.<j>.<key>`` for the parameters in ``values`` (others untouched), at least 0."""
    joints = {k: dict(v) for k, v in (doc.get("joints") or {}).items()}
    for name, v in values.items():
        p, _, j = name.partition(".")
        if p == pname:
            joints.setdefault(j, {})[key] = max(0.0, float(v))
    doc["joints"] = joints


@dataclass(frozen=True)
class JointElasticity(ArmEffect):
    """Joint compliance: ``theta_j = q_j + c_j tau_g,j(q)`` (gravity droop)."""

    name: str = "joint_elasticity"
    params: tuple[Param, ...] = (Param("c", "rad/(N m)", -1e-3, 1e-2, 0.0, 1e-5),)
    needs: tuple[str, ...] = ("ee_poses",)
    per_joint: bool = True
    residual: str = "kinematic"
    uses_gravity: bool = True
    separate_by: str = (
        "poses that load each joint differently under gravity (arm stretched out and folded, "
        "pointing up and down): droop follows the load, a joint-zero offset does not"
    )
    description: str = "joint and gear compliance: the links droop under their own weight"

    def joint_offset(self, th, ks: KinState):
        assert ks.tau_g is not None
        return self.per_joint_values(th, "c").unsqueeze(1) * ks.tau_g

    def read_physics(self, doc):
        return _read_scalar(self, doc, "c", "compliance_rad_per_nm")

    def write_physics(self, values, doc):
        _write_scalar(values, doc, "c", "compliance_rad_per_nm")


@dataclass(frozen=True)
class Backlash(ArmEffect):
    """Dead band (play operator): ``theta_j = q_j - b_j s_j`` once the motor has crossed it."""

    name: str = "backlash"
    params: tuple[Param, ...] = (Param("b", "rad", -0.02, 0.05, 0.0, 1e-3),)
    needs: tuple[str, ...] = ("ee_poses",)
    per_joint: bool = True
    residual: str = "kinematic"
    separate_by: str = (
        "reaching the same poses from both directions: the error flips sign with the "
        "direction of motion, a droop or an offset does not"
    )
    description: str = "backlash: the link lags the motor by a dead band that flips with the motion"

    def joint_offset(self, th, ks: KinState):
        return ks.play(self.per_joint_values(th, "b"))

    def read_physics(self, doc):
        return _read_scalar(self, doc, "b", "backlash_rad")

    def write_physics(self, values, doc):
        _write_scalar(values, doc, "b", "backlash_rad")


@dataclass(frozen=True)
class KinematicOffsets(ArmEffect):
    """Modified-DH offsets per joint: ``dtheta`` (joint zero), ``dd`` (axis), ``da`` (normal)."""

    name: str = "kinematic_offsets"
    params: tuple[Param, ...] = (
        Param("dtheta", "rad", -0.2, 0.2, 0.0, 1e-3),
        Param("dd", "m", -0.05, 0.05, 0.0, 1e-3),
        Param("da", "m", -0.05, 0.05, 0.0, 1e-3),
    )
    needs: tuple[str, ...] = ("ee_poses",)
    per_joint: bool = True
    residual: str = "kinematic"
    separate_by: str = (
        "many poses spread over the workspace with the full end-effector pose (position and "
        "orientation): offsets neither flip with the motion nor follow the gravity load"
    )
    description: str = "kinematic (MDH) offsets: joint zeros and link lengths differ from the URDF"

    def joint_offset(self, th, ks: KinState):
        return self.per_joint_values(th, "dtheta").unsqueeze(1).expand(-1, ks.q.shape[0], -1)

    def frame_offset(self, th):
        return torch.stack(
            [self.per_joint_values(th, "da"), self.per_joint_values(th, "dd")], dim=-1
        )

    def read_physics(self, doc):
        joints = doc.get("joints") or {}
        vals: dict[str, float] = {}
        for p, key in OFFSET_KEYS.items():
            for j in self.joints:
                off = (joints.get(j) or {}).get("offsets") or {}
                vals[f"{p}.{j}"] = float(off.get(key, 0.0))
        return vals if any(v != 0.0 for v in vals.values()) else None

    def write_physics(self, values, doc):
        joints = {k: dict(v) for k, v in (doc.get("joints") or {}).items()}
        for name, v in values.items():
            p, _, j = name.partition(".")
            if p in OFFSET_KEYS:
                entry = joints.setdefault(j, {})
                entry["offsets"] = {**(entry.get("offsets") or {}), OFFSET_KEYS[p]: float(v)}
        doc["joints"] = joints


for _e in (JointElasticity, Backlash, KinematicOffsets):
    register_effect(_e(), replace=True)

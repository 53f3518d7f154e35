"""Effects of the robot-arm torque model (``model="arm"``), registered in the physics registry.

The torque model is ``tau_model(t) = [Y(q, qd, qdd) pi + sum of joint torques](t - delta)``,
with ``Y`` the inverse-dynamics regressor and ``pi`` the inertial parameters of the URDF links
plus any payload (see :mod:`robogs.physics.arm.torque_model`). An arm effect overrides
one or more of these hooks:

* ``inertial(th, links, extra, ctx)``: change the link parameters ``links`` [M, B, 10] or add
  to ``extra`` [M, B, 10] (payload);
* ``joint_torque(th, st)``: extra joint torque [M, N, J] from the measured joint state;
* ``time_shift(th)``: lag [M, 1] s of the effort stamps behind the position stamps.

Effects of the *kinematic* model (``residual="kinematic"``, judged on recorded end-effector
poses, see :mod:`robogs.physics.arm.kinematic_model` and
:mod:`robogs.physics.arm.kinematic_effects`) override instead:

* ``joint_offset(th, ks)``: link angle minus measured (motor-side) joint angle [M, N, J] rad;
* ``frame_offset(th)``: translations ``(da, dd)`` [M, J, 2] m of each joint frame before the
  joint's rotation (along the declared perpendicular and along the axis).

Per-joint effects declare their parameters once (``fc``, ``fv``...) and are expanded for a
robot by :meth:`ArmEffect.for_robot` into ``fc.<joint>`` etc. Parameter dictionaries ``th``
map names to [M, 1] tensors (M parameter sets).

Each effect also says how it is stored in ``physics.json`` (:meth:`ArmEffect.read_physics`,
:meth:`ArmEffect.write_physics`): friction into ``joints.<j>.friction`` (Coulomb, N m) and
``joints.<j>.damping`` (viscous, N m s/rad), armature into ``joints.<j>.armature`` (kg m^2),
the payload into ``payload`` (``link``, ``mass_kg``, ``com_m`` in the link frame), a mass
correction of the arm's last link into ``distal_mass`` (same fields, a separate body whose
inertial parameters add to the payload's), and the rest
as entries of ``effects``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import torch

from robogs.physics.effects import Effect, Param, register_effect

__all__ = [
    "ArmEffect",
    "ArmState",
    "KinState",
    "InertialContext",
    "JointFriction",
    "Armature",
    "Payload",
    "DistalMass",
    "MassScale",
    "EffortTimeOffset",
    "SMOOTHING_VELOCITY",
    "MIN_INERTIA_MASS",
    "payload_com",
]

SMOOTHING_VELOCITY = 0.02
"""Default ``v_s`` [rad/s] of the Coulomb term ``Fc tanh(qd / v_s)``."""

MIN_INERTIA_MASS = 0.05
"""kg; floor of the mass dividing the payload's point-mass inertia (see :class:`Payload`)."""


@dataclass
class ArmState:
    """Measured joint state the hooks see: q, qd, qdd [N, J] (rad, rad/s, rad/s^2)."""

    q: torch.Tensor
    qd: torch.Tensor
    qdd: torch.Tensor
    joint_names: tuple[str, ...]


@dataclass
class KinState:
    """Measured state the kinematic hooks see, at the end-effector stamps.

    Attributes:
        q, qd: [N, J] measured joint angles (rad) and rates (rad/s).
        tau_g: [M, N, J] gravity torque acting on each joint, N m (``-ID(q, 0, 0)`` with the
            model's inertials), or None when no active effect needs it.
        joint_names: [J].
        play: ``play(b [M, J]) -> [M, N, J]``: link minus motor angle of a dead band of
            half-width ``b`` rad driven by the measured joint angles (see
            :func:`robogs.physics.arm.kinematic_model.play_offset`).
    """

    q: torch.Tensor
    qd: torch.Tensor
    tau_g: torch.Tensor | None
    joint_names: tuple[str, ...]
    play: Callable[[torch.Tensor], torch.Tensor]


@dataclass
class InertialContext:
    """Where an added body goes: the payload link's body index and ``T_body_link`` [4, 4]."""

    payload_link: str
    payload_body: int
    T_body_link: np.ndarray
    num_bodies: int


@dataclass(frozen=True)
class ArmEffect(Effect):
    """Base class of the arm effects.

    Attributes:
        per_joint: parameters are repeated for every joint (``<param>.<joint>``).
        joints: the joints the expanded instance covers (empty for the template).
        residual: the residual the effect is judged on: ``"torque"`` (joint efforts) or
            ``"kinematic"`` (end-effector poses).
        uses_gravity: ``joint_offset`` reads ``KinState.tau_g``.
        candidate: a default candidate of diagnose (False: fitted only when named).
        refit: ``fit --add`` refits the stored values jointly with the added effects (False:
            a correction of the arm model itself, held at its stored value as part of the base).
    """

    family: str = "joint"
    model: str = "arm"
    needs: tuple[str, ...] = ("efforts",)
    per_joint: bool = False
    joints: tuple[str, ...] = field(default=(), compare=False)
    residual: str = "torque"
    uses_gravity: bool = False
    candidate: bool = True
    refit: bool = True

    # --- expansion -------------------------------------------------------------------------
    def for_robot(self, joint_names: tuple[str, ...] | list[str]) -> ArmEffect:
        """The instance whose parameters are expanded for these joints (no-op if global)."""
        if not self.per_joint or self.joints:
            return self
        params = tuple(replace(p, name=f"{p.name}.{j}") for p in self.params for j in joint_names)
        return replace(self, params=params, joints=tuple(joint_names))

    def per_joint_values(self, th: dict[str, torch.Tensor], name: str) -> torch.Tensor:
        """Stack ``name.<joint>`` values into [M, J]."""
        return torch.cat([th[f"{name}.{j}"] for j in self.joints], dim=-1)

    # --- hooks (no-ops) --------------------------------------------------------------------
    def inertial(
        self,
        th: dict[str, torch.Tensor],
        links: torch.Tensor,
        extra: torch.Tensor,
        ctx: InertialContext,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Changed link and extra inertial parameters, both [M, B, 10]."""
        return links, extra

    def joint_torque(self, th: dict[str, torch.Tensor], st: ArmState) -> torch.Tensor | None:
        """Extra joint torques [M, N, J] in N m."""
        return None

    def time_shift(self, th: dict[str, torch.Tensor]) -> torch.Tensor | None:
        """Lag of the effort stamps, [M, 1] s (the effort stamped t measures the model at t - lag)."""
        return None

    def joint_offset(self, th: dict[str, torch.Tensor], ks: KinState) -> torch.Tensor | None:
        """Link angle minus measured joint angle, [M, N, J] rad (kinematic model)."""
        return None

    def frame_offset(self, th: dict[str, torch.Tensor]) -> torch.Tensor | None:
        """Joint-frame translations ``(da, dd)`` [M, J, 2] m before the joint rotation."""
        return None

    # --- physics.json ----------------------------------------------------------------------
    def read_physics(self, doc: dict[str, Any]) -> dict[str, float] | None:
        """Parameter values stored in ``doc`` (None when the effect is absent)."""
        for e in doc.get("effects", []) or []:
            if e.get("name") == self.name:
                vals = {p.name: float(e.get("params", {}).get(p.name, p.zero)) for p in self.params}
                return vals
        return None

    def write_physics(self, values: dict[str, float], doc: dict[str, Any]) -> None:
        """Store fitted values in ``doc`` (in place)."""
        effects = [e for e in doc.get("effects", []) or [] if e.get("name") != self.name]
        effects.append(
            {
                "name": self.name,
                "target": "robot",
                "params": {k: float(v) for k, v in values.items()},
            }
        )
        doc["effects"] = effects


def _joint_field(
    self: ArmEffect, doc: dict[str, Any], mapping: dict[str, str]
) -> dict[str, float] | None:
    joints = doc.get("joints") or {}
    found = False
    vals: dict[str, float] = {}
    for pname, key in mapping.items():
        for j in self.joints:
            v = (joints.get(j) or {}).get(key)
            if v is not None:
                found = found or float(v) != 0.0
            vals[f"{pname}.{j}"] = float(v) if v is not None else 0.0
    return vals if found else None


def _write_joint_field(
    self: ArmEffect, values: dict[str, float], doc: dict[str, Any], mapping: dict[str, str]
) -> None:
    joints = {k: dict(v) for k, v in (doc.get("joints") or {}).items()}
    for pname, key in mapping.items():
        for j in self.joints:
            joints.setdefault(j, {})[key] = max(0.0, float(values[f"{pname}.{j}"]))
    doc["joints"] = joints


@dataclass(frozen=True)
class JointFriction(ArmEffect):
    """Coulomb + viscous joint friction ``Fc tanh(qd / v_s) + Fv qd`` per joint.

    The tanh replaces ``sign(qd)`` so the torque stays continuous through a velocity reversal
    (``v_s`` = :data:`SMOOTHING_VELOCITY`); see e.g. Kermani, Patel & Moallem (2005) and
    research notes section 2.1. Linear in ``(Fc, Fv)``.
    """

    name: str = "joint_friction"
    params: tuple[Param, ...] = (
        Param("fc", "N m", -50.0, 200.0, 0.0, 1.0),
        Param("fv", "N m s/rad", -50.0, 200.0, 0.0, 1.0),
    )
    per_joint: bool = True
    v_s: float = SMOOTHING_VELOCITY
    separate_by: str = (
        "slow and fast passes of each joint (Coulomb is constant in speed, viscous grows with it)"
    )
    description: str = "Coulomb and viscous friction in the joints (largest at velocity reversals)"

    def joint_torque(self, th, st: ArmState):
        fc = self.per_joint_values(th, "fc").unsqueeze(1)  # [M, 1, J]
        fv = self.per_joint_values(th, "fv").unsqueeze(1)
        return fc * torch.tanh(st.qd / self.v_s).unsqueeze(0) + fv * st.qd.unsqueeze(0)

    def read_physics(self, doc):
        return _joint_field(self, doc, {"fc": "friction", "fv": "damping"})

    def write_physics(self, values, doc):
        _write_joint_field(self, values, doc, {"fc": "friction", "fv": "damping"})


@dataclass(frozen=True)
class Armature(ArmEffect):
    """Reflected rotor inertia per joint: ``tau += Ia qdd`` (MuJoCo's ``armature``)."""

    name: str = "armature"
    params: tuple[Param, ...] = (Param("ia", "kg m^2", -10.0, 50.0, 0.0, 0.1),)
    per_joint: bool = True
    separate_by: str = "fast accelerations at low speed (armature acts on qdd only, not on gravity)"
    description: str = "rotor (armature) inertia, torque proportional to joint acceleration"

    def joint_torque(self, th, st: ArmState):
        return self.per_joint_values(th, "ia").unsqueeze(1) * st.qdd.unsqueeze(0)

    def read_physics(self, doc):
        return _joint_field(self, doc, {"ia": "armature"})

    def write_physics(self, values, doc):
        _write_joint_field(self, values, doc, {"ia": "armature"})


@dataclass(frozen=True)
class Payload(ArmEffect):
    """A point mass rigidly attached to the payload link (a tool or a grasped object).

    Parameters are the mass ``m`` and its first moment ``h = m c`` (``c`` the CoM in the
    payload link frame), in which the torques are linear, except for the point mass's own
    inertia about the body origin ``(|h|^2 I - h h^T) / m``; that term uses ``max(m,
    MIN_INERTIA_MASS)`` in the denominator so that it stays bounded for a vanishing payload
    (a payload under 50 g has a negligible rotational inertia). The CoM is reported as
    ``h / m`` (:func:`payload_com`).
    """

    name: str = "payload"
    params: tuple[Param, ...] = (
        Param("mass", "kg", -5.0, 50.0, 0.0, 1.0),
        Param("mx", "kg m", -5.0, 5.0, 0.0, 0.05),
        Param("my", "kg m", -5.0, 5.0, 0.0, 0.05),
        Param("mz", "kg m", -5.0, 5.0, 0.0, 0.05),
    )
    separate_by: str = (
        "poses with the last links pointing in several directions (gravity torque of the load)"
    )
    description: str = "an unmodelled load (tool, grasped object) on the last link"
    slot: str = "payload"

    def inertial(self, th, links, extra, ctx: InertialContext):
        h_link = torch.cat([th["mx"], th["my"], th["mz"]], dim=-1)  # [M, 3] kg m
        m = th["mass"][:, 0]
        t = torch.as_tensor(ctx.T_body_link, dtype=h_link.dtype, device=h_link.device)
        h = h_link @ t[:3, :3].T + m[:, None] * t[:3, 3]  # first moment about the body origin
        m_eff = m.clamp(min=MIN_INERTIA_MASS)
        hh = (h * h).sum(-1)
        x, y, z = h[:, 0], h[:, 1], h[:, 2]
        iu = (
            torch.stack([hh - x * x, -x * y, -x * z, hh - y * y, -y * z, hh - z * z], dim=-1)
            / m_eff[:, None]
        )
        add = torch.cat([m[:, None], h, iu], dim=-1)  # [M, 10]
        onehot = torch.zeros(ctx.num_bodies, dtype=h.dtype, device=h.device)
        onehot[ctx.payload_body] = 1.0
        return links, extra + add[:, None, :] * onehot[None, :, None]

    def read_physics(self, doc):
        p = doc.get(self.slot)
        if not p or "mass_kg" not in p:
            return None
        m = float(p["mass_kg"])
        c = [float(v) for v in p.get("com_m", [0.0, 0.0, 0.0])]
        return {"mass": m, "mx": m * c[0], "my": m * c[1], "mz": m * c[2]}

    def write_physics(self, values, doc):
        m = float(values["mass"])
        com = [float(values[k]) / m if m > 0 else 0.0 for k in ("mx", "my", "mz")]
        out: dict[str, Any] = {"mass_kg": max(0.0, m), "com_m": com}
        link = (doc.get(self.slot) or {}).get("link")
        if link:
            out["link"] = link
        doc[self.slot] = out


@dataclass(frozen=True)
class DistalMass(Payload):
    """A mass correction of the arm's own last link: a point mass ``m`` at ``h / m``, a body of
    its own, stored in ``distal_mass`` (``mass_kg``, ``com_m``), separate from ``payload``.

    Both bodies act on the payload link and their inertial parameters add, so a carried payload
    fitted on top of a stored correction is the payload alone (in kg), not the sum. The
    correction belongs to the arm model: it is not a default diagnose candidate (it is the
    exact look-alike of a payload) and ``fit --add`` of other effects holds it at its stored
    value (``refit=False``); fit it by naming it (``fit --add distal_mass``).
    """

    name: str = "distal_mass"
    description: str = "mass correction of the arm's last link (a second body, not the payload)"
    slot: str = "distal_mass"
    candidate: bool = False
    refit: bool = False


def payload_com(
    values: dict[str, float], cov: np.ndarray | None = None
) -> dict[str, tuple[float, float]]:
    """CoM ``h / m`` of a fitted payload and its standard deviation (delta method).

    Args:
        values: ``mass, mx, my, mz``.
        cov: [4, 4] covariance of ``(mass, mx, my, mz)``.

    Returns:
        ``{"cx": (value m, sd m), "cy": ..., "cz": ...}``.
    """
    m = values["mass"]
    out = {}
    for k, name in enumerate(("cx", "cy", "cz")):
        h = values["m" + name[1]]
        c = h / m if m != 0 else float("nan")
        sd = float("nan")
        if cov is not None and m != 0 and np.all(np.isfinite(cov)):
            g = np.zeros(4)
            g[0], g[1 + k] = -h / m**2, 1.0 / m
            sd = float(np.sqrt(max(g @ cov @ g, 0.0)))
        elif cov is not None:
            sd = float("inf")
        out[name] = (c, sd)
    return out


@dataclass(frozen=True)
class MassScale(ArmEffect):
    """All link masses and inertias times ``s`` (a wrong mass scale in the URDF)."""

    name: str = "mass_scale"
    params: tuple[Param, ...] = (Param("s", "-", 0.1, 10.0, 1.0, 0.1),)
    separate_by: str = "slow poses (gravity) against fast motion (inertia) of the links; a payload acts on the last link only"
    description: str = "every link heavier or lighter than the URDF says"

    def inertial(self, th, links, extra, ctx):
        return links * th["s"][:, :, None], extra


@dataclass(frozen=True)
class EffortTimeOffset(ArmEffect):
    """Effort stamps late by ``delta`` against the position stamps (measurement effect)."""

    name: str = "effort_time_offset"
    family: str = "sensor"
    params: tuple[Param, ...] = (Param("delta", "s", -0.2, 0.2, 0.0, 0.004),)
    separate_by: str = (
        "sharp accelerations (the torque leads or lags the motion by a constant delay)"
    )
    description: str = "clock offset between the effort and the position samples"

    def time_shift(self, th):
        return th["delta"]


for _e in (JointFriction, Armature, Payload, DistalMass, MassScale, EffortTimeOffset):
    register_effect(_e(), replace=True)

# the kinematic effects (elasticity, backlash, kinematic offsets) register with the others
from robogs.physics.arm import kinematic_effects as _kinematic  # noqa: E402, F401

"""Catalogue effects on the MuJoCo engine: which MuJoCo quantity carries each effect.

Every rigid-model effect plugs into the torch model through hooks (``body``, ``accel``,
``friction``, the sensor hooks; :mod:`robogs.physics.effects`). On MuJoCo the same hooks are
translated, so a user-written effect works on both engines without MuJoCo code:

* ``body`` hooks -> **model parameters** of each parameter set: the changed
  :class:`~robogs.physics.model.Body` (mass, yaw inertia, CoM, dynamic friction, restitution,
  linear damping) is written into a copy of the ``MjModel`` (:func:`apply_body`);
* ``accel`` hooks -> **per-step applied forces**: the hook is called on the MuJoCo state of
  every rollout each step and its acceleration enters as ``xfrc_applied`` = m a (force at the
  CoM) and I_z alpha (torque about world z) (:func:`step_forces`);
* ``friction`` hooks -> **per-step applied forces**: the change of the dynamic coefficient,
  ``mu_d' - mu_d``, times the normal force m g (object on the table), opposing the planar CoM
  velocity, limited so that it cannot reverse the velocity within a step;
* sensor hooks (``sample_times``, ``to_sensor``, ``from_sensor``) act on the sampled poses, as on
  the planar engine.

Built-in effects with a native MuJoCo counterpart bypass the generic path (:data:`NATIVE`):
viscous damping is the DOF damping of the object's translational free-joint DOFs
(``c m`` N s/m), the table tilt is the gravity vector ``(g_x, g_y, -g)`` (the pusher body is
gravity compensated, so only the objects feel it); both maps are
:data:`robogs.format.mjcf.NATIVE_EFFECTS`, shared with ``robogs export mjcf``. The full table is
:data:`MAPPING` (and ``docs/physics.md``, section "Engines").

Why not MuJoCo's fluid model for quadratic drag: its inertia-box drag is quadratic per body
axis (``|v_i| v_i``), not ``|v| v`` along the velocity; they agree only along body axes, so the
drag is a per-step force. Anisotropic friction: a contact pair's two tangential coefficients
act along the contact frame's tangent axes, which MuJoCo chooses (not the table grain), so it is
a per-step force too. Restitution: the object-table pair's ``solref`` damping ratio is set to
``zeta = -ln e / sqrt(pi^2 + ln^2 e)``, the damping ratio of a linear spring-damper with
coefficient of restitution ``e``, with a constant impedance and a 20 ms time constant on that
pair (:data:`BOUNCE_SOLIMP`, :data:`BOUNCE_TIMECONST`; the test drops check the bounce).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from robogs.format.mjcf import NATIVE_EFFECTS, ballast_contact
from robogs.physics.effects import Effect, overrides
from robogs.physics.model import Body, FreeState, Slip

__all__ = [
    "MAPPING",
    "NATIVE",
    "ObjectSlots",
    "apply_body",
    "classify",
    "principal",
    "restitution_damping_ratio",
    "BOUNCE_SOLIMP",
    "BOUNCE_TIMECONST",
    "step_forces",
]

MAPPING: dict[str, tuple[str, str]] = {
    "viscous_damping": ("model", "dof_damping of the object's x, y, z DOFs = c m [N s/m]"),
    "quadratic_drag": ("force", "xfrc_applied = -k m |v| v at the CoM, each step"),
    "stribeck": ("force", "xfrc_applied = -(mu(v) - mu_d) m g v/|v| on the table, each step"),
    "table_tilt": ("model", "opt.gravity = (g_x, g_y, -g); the pusher is gravity compensated"),
    "anisotropic_friction": (
        "force",
        "xfrc_applied = -(mu(phi) - mu_d) m g v/|v| on the table, each step",
    ),
    "restitution": ("model", "object-table pair solref damping ratio from e"),
    "com_offset": ("model", "body_ipos (x, y) of the object"),
    "mass": ("model", "body_mass, body_inertia scaled with it"),
    "time_offset": ("sensor", "sample times shifted (as on the planar engine)"),
    "camera_extrinsics": ("sensor", "sampled poses mapped into the camera frame"),
}
"""Built-in effect -> (kind, MuJoCo quantity): ``model`` (a parameter of the compiled model per
parameter set), ``force`` (per-step applied force), ``sensor`` (applied to sampled poses)."""


@dataclass
class ObjectSlots:
    """Where the fitted object lives in the compiled model (indices into ``MjModel`` arrays).

    Attributes:
        body: body id; dof: first DOF address of its joints (free joint or planar joint set:
        x, y, z come first either way); table_pairs: contact-pair rows
        object-table; nominal_mass [kg], nominal_inertia [3] kg m^2 (principal, body frame),
        nominal_ipos [3] m: the compiled values; nominal_iquat [4] (w, x, y, z): the rotation
        from the principal axes to the body frame (MuJoCo sorts the principal moments, so
        ``nominal_inertia[2]`` is not the body-z moment in general: a 8 x 6 x 5 cm box compiles
        to (I_zz, I_yy, I_xx) with a 90 deg ``iquat`` about y); tilt_inertia_scale: factor on the
        roll and pitch inertia (see ``robogs.physics.engines.mujoco_fit.MujocoFit``);
        table_torsion: torsional friction radius [m] of each ``table_pairs`` row (0: none).
        ballast: the z ballast factor k (``robogs.format.mjcf.ContactSettings.z_ballast``;
        0: none) and ballast_actuator its bias actuator's id: the z DOF (``dof + 2``) carries
        armature k m and the force k m g_z, the support pairs mu_d / (1 + k).
    """

    body: int
    dof: int
    table_pairs: list[int]
    nominal_mass: float
    nominal_inertia: np.ndarray
    nominal_ipos: np.ndarray
    nominal_iquat: np.ndarray | None = None
    tilt_inertia_scale: float = 1.0
    table_torsion: list[float] | None = None
    ballast: float = 0.0
    ballast_actuator: int = -1

    def body_tensor(self) -> np.ndarray:
        """[3, 3] nominal inertia tensor about the CoM in the body frame [kg m^2]."""
        q = np.array([1.0, 0, 0, 0]) if self.nominal_iquat is None else self.nominal_iquat
        r = np.empty(9)
        mujoco.mju_quat2Mat(r, np.asarray(q, dtype=float))
        r = r.reshape(3, 3)
        return r @ np.diag(self.nominal_inertia) @ r.T


def principal(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(principal moments [3], ``iquat`` (w, x, y, z)) of a symmetric [3, 3] inertia tensor:
    the body_inertia / body_iquat pair MuJoCo stores."""
    vals, vecs = np.linalg.eigh(0.5 * (tensor + tensor.T))
    if np.linalg.det(vecs) < 0:
        vecs[:, 0] *= -1.0
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(vecs).ravel())
    return vals, q / np.linalg.norm(q)


BOUNCE_TIMECONST = 0.02
"""Contact time constant [s] of an underdamped (bouncing) object-table pair: with the 4 ms of
the plastic contacts, damping ratios below about 0.2 (e > 0.5) made the semi-implicit Euler
contact unstable (a 5 cm drop at e = 0.7 rose 11 cm); at 20 ms the bounce follows the
closed-form ratio within 0.03 (drops of 2 and 5 cm, e = 0.3-0.7)."""

BOUNCE_SOLIMP = (0.9, 0.9, 0.001, 0.5, 2.0)
"""solimp of a bouncing pair: a constant impedance, so the contact is the linear spring-damper
whose damping ratio the closed form assumes (the plastic pairs' impedance rises from 0.95 to
0.99 within 1 mm, which made the bounce depend on the drop height)."""


def restitution_damping_ratio(e: float) -> float:
    """Damping ratio of a linear spring-damper whose impact restitution is ``e`` (0 -> 1)."""
    e = min(max(float(e), 0.0), 0.98)
    if e <= 1e-6:
        return 1.0
    le = math.log(e)
    return -le / math.sqrt(math.pi**2 + le * le)


NATIVE: dict[str, Callable[[mujoco.MjModel, dict[str, float], ObjectSlots], None]] = NATIVE_EFFECTS
"""Built-in ``accel`` effects mapped onto model parameters instead of per-step forces (applied
after the body, so viscous damping uses the set's mass). The table and its functions live in
:data:`robogs.format.mjcf.NATIVE_EFFECTS`, which ``robogs export mjcf`` applies to the exported
scene too: one mapping for the fitted model and the exported file."""


def classify(effects: Sequence[Effect]) -> tuple[list[Effect], list[Effect], list[Effect]]:
    """Split rigid effects into (body hooks, native model maps, per-step force effects)."""
    body, native, force = [], [], []
    for e in effects:
        if e.model != "rigid" or e.family == "sensor":
            continue
        if overrides(e, "body"):
            body.append(e)
        if e.name in NATIVE and type(e).__module__ == "robogs.physics.catalogue":
            native.append(e)
        elif overrides(e, "accel") or overrides(e, "friction"):
            force.append(e)
    return body, native, force


def apply_body(
    base: mujoco.MjModel,
    body: Body,
    m: int,
    slots: ObjectSlots,
    *,
    timeconst: float,
) -> mujoco.MjModel:
    """A copy of ``base`` carrying row ``m`` of ``body`` (mass, inertia, CoM, mu_d,
    restitution, linear damping); ``timeconst`` [s] is the contact pairs' solref time constant
    (a bouncing pair gets :data:`BOUNCE_TIMECONST` and :data:`BOUNCE_SOLIMP`). With a z ballast
    (``slots.ballast``) its armature and weight follow the set's mass, and the support pairs'
    coefficients are mu_d / (1 + k) (a bouncing pair's solref and
    solimp corrected by :func:`robogs.format.mjcf.ballast_contact`)."""
    model = copy.copy(base)
    b = slots.body
    mass = float(body.mass[m, 0])
    # the tensor in the body frame: scaled with the mass, the yaw moment set, roll and pitch
    # scaled (congruence diag(k, k, 1)^1/2 keeps it positive definite), re-diagonalised
    tensor = slots.body_tensor() * (mass / slots.nominal_mass)
    tensor[2, 2] = float(body.inertia_z[m, 0])
    k = np.sqrt([slots.tilt_inertia_scale, slots.tilt_inertia_scale, 1.0])
    tensor = tensor * np.outer(k, k)
    model.body_mass[b] = mass
    model.body_inertia[b], model.body_iquat[b] = principal(tensor)
    model.body_ipos[b, :2] = body.com[m, 0].numpy()
    kb = slots.ballast
    mu = max(float(body.mu_d[m, 0]), 1e-5) / (1.0 + kb)
    e = float(body.restitution[m, 0])
    zeta = restitution_damping_ratio(e)
    rho = slots.table_torsion or [0.0] * len(slots.table_pairs)
    for k, r in zip(slots.table_pairs, rho, strict=True):
        model.pair_friction[k, :2] = mu
        if r > 0:
            model.pair_friction[k, 2] = mu * r
        if zeta < 1.0:
            sr, si, _ = ballast_contact(
                (max(timeconst, BOUNCE_TIMECONST), zeta), BOUNCE_SOLIMP, kb, vertical=True
            )
            model.pair_solref[k], model.pair_solimp[k] = sr, si
    z = np.array([1.0, 1.0, 1.0 + kb])  # the z DOF's inertia is (1 + k) m
    model.dof_damping[slots.dof : slots.dof + 3] = float(body.damping[m, 0]) * mass * z
    if kb > 0:
        model.dof_armature[slots.dof + 2] = kb * mass
        model.actuator_biasprm[slots.ballast_actuator, 0] = kb * mass * model.opt.gravity[2]
    return model


def step_forces(
    effects: Sequence[tuple[Effect, dict[str, torch.Tensor]]],
    body: Body,
    v: np.ndarray,
    w: np.ndarray,
    yaw: np.ndarray,
    on_table: np.ndarray,
    gravity: float,
    dt: float,
) -> np.ndarray:
    """Per-step applied wrench [M, T, 6] (force N, torque N m; world, at the CoM) of effects
    with ``accel`` or ``friction`` hooks.

    Args:
        effects: (effect, its parameters [M, 1]) pairs.
        body: the parameter sets' bodies ([M, 1] tensors).
        v: [M, T, 3] CoM velocity [m/s]; w: [M, T] yaw rate [rad/s]; yaw: [M, T] rad.
        on_table: [M, T] bool, the object rests on or slides over the table.
        gravity: |g| [m/s^2] (the normal force of a resting object is m g).
        dt: step [s] (friction changes are limited to stop the object, not reverse it).
    """
    f64 = torch.float64
    vt = torch.as_tensor(v, dtype=f64)
    wt = torch.as_tensor(w, dtype=f64)
    yt = torch.as_tensor(yaw, dtype=f64)
    acc = torch.zeros_like(vt)
    alpha = torch.zeros_like(wt)
    state = FreeState(v=vt, w=wt, yaw=yt, on_table=torch.as_tensor(on_table), body=body)
    speed = torch.sqrt(vt[..., 0] ** 2 + vt[..., 1] ** 2 + 1e-18)
    slip = Slip(vx=vt[..., 0], vy=vt[..., 1], speed=speed, yaw=yt)
    dmu = torch.zeros_like(wt)
    for e, th in effects:
        if overrides(e, "accel"):
            out = e.accel(th, state)
            if out is not None:
                if out[0] is not None:
                    acc = acc + out[0]
                if out[1] is not None:
                    alpha = alpha + out[1]
        if overrides(e, "friction"):
            _, mu_d = e.friction(th, body.mu_s, body.mu_d, slip)
            dmu = dmu + (mu_d - body.mu_d)
    # extra Coulomb deceleration, capped at the speed it can remove in one step
    dec = dmu * gravity
    dec = torch.minimum(dec.abs(), speed / dt) * torch.sign(dec)
    dec = torch.where(torch.as_tensor(on_table) & (speed > 1e-6), dec, torch.zeros_like(dec))
    acc = acc.clone()
    acc[..., 0] = acc[..., 0] - dec * vt[..., 0] / speed
    acc[..., 1] = acc[..., 1] - dec * vt[..., 1] / speed
    out = np.zeros(v.shape[:2] + (6,))
    out[..., :3] = (body.mass.unsqueeze(-1) * acc).numpy()
    out[..., 5] = (body.inertia_z * alpha).numpy()
    return out

"""Catalogue effects on the MuJoCo engine: which MuJoCo quantity carries each effect.

Every rigid-model effect plugs into the torch model through hooks (``body``, ``accel``,
``friction``, the sensor hooks; :mod:`robogs.physics.effects`). On MuJoCo the same hooks are
translated, so a user-written effect works on both engines without MuJoCo code:

* ``body`` hooks -> **model parameters** of each parameter set: the changed
  :class:`~robogs.physics.model.Body` (mass, yaw inertia, CoM, dynamic friction, restitution,
  linear damping) is written into a copy of the ``MjModel`` (:func:`apply_body`, by
  :func:`robogs.format.mjcf.write_body`: ``robogs export mjcf`` writes the exported object's
  body, its fitted mass, CoM offset and restitution included, with the same function);
* ``accel`` hooks -> **per-step applied forces**: the hook is called on the MuJoCo state of
  every rollout each step and its acceleration enters as ``xfrc_applied`` = m a (force at the
  CoM) and I_z alpha (torque about world z) (:func:`step_forces`);
* ``friction`` hooks -> **per-step applied wrenches**: the change of the dynamic coefficient,
  ``mu_d' - mu_d``, times the table's Coulomb wrench on the planar twist ``(v, c_r w)`` with
  the ellipsoidal limit surface (Howe & Cutkosky 1996, the planar model's and the generator's
  friction; MuJoCo's own table contacts carry the same surface through their torsional friction,
  :func:`robogs.format.mjcf.torsion_radius`): force ``-dmu m g v/|xi|`` at the CoM and torque
  ``-dmu m g c_r^2 w/|xi|`` about z, ``|xi| = sqrt(|v|^2 + (c_r w)^2)``, each limited so that
  it cannot reverse its velocity within a step; ``m g`` stands for the table's normal force,
  taken from the object's vertical acceleration over the last step, ``m (g + a_z)``, so that a
  landing's friction impulse changes with the coefficient as well (a box carried 2.6 mm up
  and dropped at 0.95 m/s loses 0.1 m/s to its landing's friction). The torque matters: a
  friction change applied as a force alone leaves a turning box spinning on at the unchanged
  rate, which on design A's hidden Stribeck (seed 0) multiplied the yaw misfit at the planar
  engine's fit by 28 (30260 against 1086 sigma^2; with the torque 1102);
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
a per-step force too. Restitution: on the planar joint set (a flat box) the support pairs stay
plastic and :class:`~robogs.physics.engines.mujoco_fit.MujocoFit` takes Newton impacts as events
(its module docstring, "Restitution"); on free joints the object-table pair's ``solref`` damping
ratio is set to ``zeta = -ln e / sqrt(pi^2 + ln^2 e)``, the damping ratio of a linear
spring-damper with coefficient of restitution ``e``, with a constant impedance and a 20 ms time
constant on that pair (:data:`BOUNCE_SOLIMP`, :data:`BOUNCE_TIMECONST`), which is also how
``robogs export mjcf`` writes it: that soft bounce keeps the apex (e within 0.03) but stays
10-14 ms in contact, so its rebound runs 4-7 mm behind the rigid one.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from robogs.format.mjcf import (  # one map for the engine and `robogs export mjcf`
    BOUNCE_SOLIMP,
    BOUNCE_TIMECONST,
    NATIVE_EFFECTS,
    BodyValues,
    inertia_tensor,
    principal,
    restitution_damping_ratio,
    write_body,
)
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
    "stribeck": (
        "force",
        "xfrc_applied = -(mu(v) - mu_d) m g (v, c_r^2 w)/|(v, c_r w)| on the table, each step",
    ),
    "table_tilt": ("model", "opt.gravity = (g_x, g_y, -g); the pusher is gravity compensated"),
    "anisotropic_friction": (
        "force",
        "xfrc_applied = -(mu(phi) - mu_d) m g (v, c_r^2 w)/|(v, c_r w)| on the table, each step",
    ),
    "restitution": (
        "model",
        "Newton impact events, plastic support (planar joint set); free joints: the "
        "object-table pair's solref damping ratio from e",
    ),
    "com_offset": (
        "model",
        "body_ipos (x, y) of the object and its planar footprint (the friction centre) with it",
    ),
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
        com_feet: ``(geom id, x, y)`` of the footprint geoms that follow the CoM, x, y [m]
        relative to it (the planar joint set's; :func:`robogs.format.mjcf.com_feet`).
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
    com_feet: tuple[tuple[int, float, float], ...] = ()

    def body_tensor(self) -> np.ndarray:
        """[3, 3] nominal inertia tensor about the CoM in the body frame [kg m^2]."""
        return inertia_tensor(self.nominal_inertia, self.nominal_iquat)


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
    bounce_solref: bool = True,
) -> mujoco.MjModel:
    """A copy of ``base`` carrying row ``m`` of ``body`` (mass, inertia, CoM, mu_d,
    restitution, linear damping), written by :func:`robogs.format.mjcf.write_body` (the
    function ``robogs export mjcf`` writes the exported body with); ``timeconst`` [s] is the
    contact pairs' solref time constant; ``bounce_solref``: restitution as the support pairs'
    solref (False: they stay plastic, the caller bounces the object by impact events)."""
    model = copy.copy(base)
    values = BodyValues(
        mass=float(body.mass[m, 0]),
        inertia_z=float(body.inertia_z[m, 0]),
        com=(float(body.com[m, 0, 0]), float(body.com[m, 0, 1])),
        mu_d=float(body.mu_d[m, 0]),
        restitution=float(body.restitution[m, 0]),
        damping=float(body.damping[m, 0]),
    )
    write_body(model, values, slots, timeconst=timeconst, bounce_solref=bounce_solref)
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
    c_r: float = 0.0,
    az: np.ndarray | None = None,
) -> np.ndarray:
    """Per-step applied wrench [M, T, 6] (force N, torque N m; world, at the CoM) of effects
    with ``accel`` or ``friction`` hooks (module docstring).

    Args:
        effects: (effect, its parameters [M, 1]) pairs.
        body: the parameter sets' bodies ([M, 1] tensors).
        v: [M, T, 3] CoM velocity [m/s]; w: [M, T] yaw rate [rad/s]; yaw: [M, T] rad.
        on_table: [M, T] bool, the object rests on or slides over the table.
        gravity: |g| [m/s^2] (the normal force of a resting object is m g).
        dt: step [s] (friction changes are limited to stop the object, not reverse it).
        c_r: the footprint's mean distance from its centre [m] (``Scene.friction_radius``):
            the limit surface's torque arm; 0: friction changes act on the translation only.
        az: [M, T] the object's vertical acceleration over the last step [m/s^2]: the table's
            normal force is then ``m (g + az)`` (at least 0), the force a landing presses with
            (a friction change scales the landing's friction impulse too, as in the planar
            model and the generator); None: ``m g``, a resting or sliding object.
    """
    # the hooks get torch tensors (they are the planar model's); the rest is numpy, whose
    # per-call cost on a few rows is a fraction of torch's (this runs every step)
    v = np.asarray(v, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    on_table = np.asarray(on_table, dtype=bool)
    vt, wt = torch.from_numpy(v), torch.from_numpy(w)
    yt = torch.as_tensor(yaw, dtype=torch.float64)
    speed = np.sqrt(v[..., 0] ** 2 + v[..., 1] ** 2 + 1e-18)
    acc = np.zeros(v.shape)
    alpha = np.zeros(w.shape)
    dmu = np.zeros(w.shape)
    state = slip = None
    for e, th in effects:
        if overrides(e, "accel"):
            if state is None:
                state = FreeState(
                    v=vt, w=wt, yaw=yt, on_table=torch.from_numpy(on_table), body=body
                )
            out = e.accel(th, state)
            if out is not None:
                if out[0] is not None:
                    acc = acc + out[0].detach().numpy()
                if out[1] is not None:
                    alpha = alpha + out[1].detach().numpy()
        if overrides(e, "friction"):
            if slip is None:
                slip = Slip(vx=vt[..., 0], vy=vt[..., 1], speed=torch.from_numpy(speed), yaw=yt)
            _, mu_d = e.friction(th, body.mu_s, body.mu_d, slip)
            dmu = dmu + (mu_d - body.mu_d).detach().numpy()
    # the extra Coulomb wrench on the twist (v, c_r w): rates -dmu g / |xi| on v and
    # -dmu g (m c_r^2 / I) / |xi| on w, each capped at what stops its velocity in one step
    xi = np.sqrt(speed * speed + (c_r * w) ** 2)
    live = on_table & (xi > 1e-6)
    xi = np.where(live, xi, 1.0)
    kr = body.mass.numpy() * c_r * c_r / body.inertia_z.numpy()
    normal = gravity if az is None else np.maximum(gravity + np.asarray(az, float), 0.0)
    rate_v = np.where(live, dmu * normal / xi, 0.0)
    rate_w = np.where(live, dmu * normal * kr / xi, 0.0)
    rate_v = np.minimum(np.abs(rate_v), 1.0 / dt) * np.sign(rate_v)
    rate_w = np.minimum(np.abs(rate_w), 1.0 / dt) * np.sign(rate_w)
    acc[..., 0] = acc[..., 0] - rate_v * v[..., 0]
    acc[..., 1] = acc[..., 1] - rate_v * v[..., 1]
    alpha = alpha - rate_w * w
    out = np.zeros(v.shape[:2] + (6,))
    out[..., :3] = body.mass.unsqueeze(-1).numpy() * acc
    out[..., 5] = body.inertia_z.numpy() * alpha
    return out

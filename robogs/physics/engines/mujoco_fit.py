"""MuJoCo rollouts for the fitting engine: ``simulate`` over a parameter space, as the planar
:func:`robogs.physics.model.simulate` does, so residuals, finite-difference Jacobians, fits and
the diagnosis run unchanged on MuJoCo (:class:`robogs.physics.engine.Engine` with
``backend="mujoco"``).

Per call, ``theta [M, Q]`` becomes one model per distinct set of dynamics parameters: a copy of
the compiled ``MjModel`` with the set's values written into its arrays (base friction and every
effect with a MuJoCo counterpart, :mod:`robogs.physics.engines.mujoco_effects`; nothing is
recompiled). Of the M x T rollouts, those that would repeat another exactly (the same dynamics
columns and the same start in the same trajectory: the finite-difference rows of sensor
parameters, the trajectories a local-offset column leaves alone, the shared start of several
fits) are run once. The rollouts run on one ``mujoco.batch.Batch`` of ``threads`` threads, each
keeping its ``MjData`` state, solver warm start included, between calls. Stretches where nothing
has to be changed from Python run as one multi-step call; a step is taken alone when an effect
applies a state-dependent force (``xfrc_applied`` computed from the state; only the rollouts of
sets that switch a force effect on) or a trajectory starts, holds or ends a grasp. Without ``mujoco.batch`` (MuJoCo before 3.17) the same schedule
runs on ``mujoco.rollout`` (``stepper="rollout"``), whose calls each start with a cold solver
warm start, so its single steps and chunk boundaries differ from the batch's within the solver
tolerance (bounded in ``tests/physics/test_mujoco_speed_equiv.py``).

Grasps: while the drive grasps, the object follows the end effector rigidly (its pose in the
EE yaw frame is frozen at the onset, as in the planar model; velocity from ``carry_vel``).
From the onset on, the pusher geometry of that trajectory is moved 10 m up (it sits inside
the grasped object, and after a release it must not strike it: the planar model skips pusher
contact while grasping, and its pushes never follow a grasp).

Pusher force (when the drive carries wrench bins): the force the objects exert on the pusher,
from the pusher's own dynamics, ``F_c = M (v[k+1] - v[k]) / dt - F_servo[k]`` per step (the
servo forces are explicit and the pusher is gravity compensated, so the rest of its
acceleration is contact), averaged over each wrench bin as in the planar model.

Pusher friction: the base slot :data:`PUSHER_FRICTION` (:func:`pusher_friction_param`), an
engine-only base parameter: a space that holds it sets the Coulomb coefficient of every
object-pusher pair per parameter set (the planar model has a frictionless pusher and ignores it).
Likewise a base slot ``objects.<name>.friction_dynamic`` (:func:`object_friction_param`) sets the
table friction of another object of the scene (two boxes, one pushed into the other).

Other tracked objects (``tracked``: :attr:`robogs.physics.prepare.Prepared.tracked`, e.g. a
box the pushed one strikes): each starts per trajectory at its measured start pose (on the
support at the contacts' equilibrium when measured within :data:`SETTLE_TOL_M` of resting, as
the fitted object), its poses are returned at its own stamps
(:class:`~robogs.physics.residuals.SceneSimResult`, no sensor effects: those model the fitted
object's tracker), and :meth:`MujocoFit.extra_params` gives its table friction as a base slot.

Restitution (planar joint set, a flat box: :attr:`MujocoFit.bounce_events`): the object-table
pairs stay plastic whatever ``e``, and impacts are events between steps (:meth:`MujocoFit.
_bounce`), the rule of the planar model's table contact and of the generator: an approach faster
than the scene's ``bounce_min_speed`` (5 cm/s) that would close the gap within the step leaves at
``e`` times it, from the time of impact in the step, and the normal impulse ``(1 + e)`` times the
approach speed takes ``mu_d`` times it off the CoM's planar twist (force effects see that impulse
through the vertical acceleration their normal force is computed from). ``e = 0`` is the same
event, so a landing's friction impulse is the rigid one and the objective is continuous at zero.
While an object is off the table (not resting within 0.1 mm, or moving vertically) its rollouts
step one at a time. Why not MuJoCo's soft bounce (a ``solref`` damping ratio from ``e``, kept for
free joints and for ``robogs export mjcf``): at a 1 ms step it needs a 20 ms time constant to be
stable below damping ratio 0.2, so a 5 cm drop stays 13 ms in contact and 3 mm deep and its
rebound runs 6 mm behind the rigid one; on design A seed 0 it fitted e 0.31 for 0.5 (the
underdamped support also moved the other trajectories' chi^2 over a range of 57 with e), with
events 0.502 (planar 0.502; ``bench/RESULTS.md``, stop 54). A plastic landing on the soft
support took 3.9 mm less friction at 5 cm / 0.6 m/s; as an event it is within 0.43 mm of the
closed form (``tests/physics/test_mujoco_effects.py``).

Strikes (planar joint set, a flat box, a sphere or capsule pusher: :attr:`MujocoFit.
strike_events`): where an end sphere of the pusher closes on the box faster than
:data:`STRIKE_MIN_SPEED` (5 cm/s) and would reach it within the step, the box takes the planar
model's contact impulse as an event before the step (:meth:`MujocoFit._strike`:
:func:`~robogs.physics.model._pusher_impulse`, frictionless, inelastic and speculative, both end
spheres at once), so a strike is rigid and plastic as in the planar model and the generator; the
soft pusher pair takes the slower approaches and the steady push that follows. The runners check
for strikes only from a horizon on (:meth:`MujocoFit._strike_horizon`, a bound on how fast each
sphere can close its gap), and give the same poses as a check at every step
(``tests/physics/test_mujoco_speed_equiv.py``); the events' impulses enter the pusher force.
Why: the soft pair (5 steps x 1.2) threw a struck box at 1.07-1.09x the pusher's speed, and a
short tap left it with 7-39 % of the rigid impulse's speed (``tests/physics/
test_mujoco_strike.py``: within 1 % with events); on design A's off-centre pushes the box turned
0.25-0.31 deg more than the planar model's (0.11-0.15 deg with events) and the pushes alone
fitted friction 1.7 % high (0.3558 for 0.35; 0.3519 with events), which the table tilt's
fit read as 8 % more tilt (``bench/RESULTS.md``, stops 54-55). The pusher's friction does not
act in the event (the planar model's contact is frictionless); it acts through the soft pair
from the next step on.

Not modelled here: ``friction_static`` (MuJoCo has one Coulomb coefficient).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields
from typing import Any

import mujoco
import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.format.mjcf import com_feet
from robogs.format.mjcf_pusher import pusher_geometry
from robogs.physics.effects import Param, overrides
from robogs.physics.engines.base import quat_yaw
from robogs.physics.engines.mujoco_effects import (
    NATIVE,
    ObjectSlots,
    apply_body,
    classify,
    step_forces,
)
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.model import (
    Drive,
    SimResult,
    _base_body,
    _lift,
    _pusher_impulse,
    _pusher_points,
    _steps,
    pusher_contacts,
)
from robogs.physics.residuals import SceneSimResult
from robogs.physics.space import BASE, ParamSpace

__all__ = [
    "MujocoFit",
    "PUSHER_FRICTION",
    "PUSHER_PARK_M",
    "SETTLE_TOL_M",
    "STEPPERS",
    "TILT_INERTIA_SCALE",
    "object_friction_param",
    "pusher_friction_param",
]

PUSHER_FRICTION = "pusher_friction"
"""Name of the base slot of the pusher's Coulomb coefficient (MuJoCo engine only)."""


def object_friction_param(physics: Mapping[str, Any], name: str) -> Param:
    """Base parameter ``objects.<name>.friction_dynamic``: the table friction of another
    object of the scene than the fitted one (MuJoCo engine only; zero at its physics.json
    value, bounds 0.02-2)."""
    mu = float(((physics.get("objects") or {}).get(name) or {}).get("friction_dynamic", 0.4))
    return Param(f"objects.{name}.friction_dynamic", "-", 0.02, 2.0, min(max(mu, 0.02), 2.0), mu)


def pusher_friction_param(physics: Mapping[str, Any], upper: float = 1.5) -> Param:
    """The pusher-friction base parameter, its zero at ``objects.pusher.friction_dynamic``
    (default 0) and bounds [0, ``upper``]: add it to a space's base parameters to fit it."""
    mu = float(((physics.get("objects") or {}).get("pusher") or {}).get("friction_dynamic") or 0)
    return Param(PUSHER_FRICTION, "-", 0.0, upper, min(max(mu, 0.0), upper), max(mu, 0.05))


TILT_INERTIA_SCALE = 1.0
"""Factor on the fitted object's roll and pitch inertia (default 1: the physical body).
A box released at 0.95 m/s 4 mm above the table lands in 3-D: the friction impulse pitches it
and it rocks for ~200 ms, chaotically (a 1 % change of a damping coefficient moved its height by
0.6 mm and its yaw by 0.4 deg), which breaks the finite-difference Jacobians of slide fits.
A factor of 1e4 keeps the box flat and fixes the slides (null clean, viscous c 1.871 vs planar
1.857), but off-centre pushes then turn 14-20 deg away from the generator (1e2: 14-17 deg). Part
of that was a bug (MuJoCo sorts the principal moments, and the factor scaled yaw and pitch, not
roll and pitch; fixed in :func:`~robogs.physics.engines.mujoco_effects.apply_body`); with the
axes right the pushes still turn 6.3 deg off (against 0.3-1.6 deg at 1: the footprint's normal
loads shift with micro-tilts), and the slides no longer need it (the landing chaos came from the
collision box's corners carrying load), so it stays an option, off."""

SETTLE_TOL_M = 3e-3
"""A measured start within this height [m] of the resting height is a box at rest on the
support: it starts there, at the contacts' equilibrium penetration (measured, not assumed: a
measured start 0.1 mm high dropped the box, and the landing's bounce and rocking entered every
finite-difference Jacobian)."""

PUSHER_PARK_M = 10.0
"""How far up [m] a grasping trajectory's pusher geometry is moved from the grasp onset on."""

_MAX_CHUNK = 256  # steps per multi-step rollout call (bounds the state buffer)
_REST_CHUNK = 50  # steps per call where a rollout may come to rest (the rest check's stride)
_CARRY_BLOCK = 256  # steps of held states made at once (_Carry)
_PROBE = 2  # steps taken before the start of the rest cut: a box that starts to move is seen
REST_SPEED = 1e-5
"""Speed [m/s, rad/s] under which every DOF of a resting object counts as still (the batch
runner's rest cut, :meth:`MujocoFit._still`)."""

STRIKE_MIN_SPEED = 0.05
"""Closing speed [m/s] of a pusher end sphere on the box above which its contact is a strike
event (:meth:`MujocoFit._strike`); slower approaches are left to the soft pusher pair."""
_BOX_ACCEL = 2.0  # [m/s^2] bound on what accelerates a box other than friction (_strike_horizon)
_STRIKE_WINDOW = 64  # steps a strike horizon looks ahead

STEPPERS = ("batch", "rollout")
"""Rollout runners: ``mujoco.batch`` (persistent states; MuJoCo >= 3.17) or ``mujoco.rollout``."""


class MujocoFit:
    """MuJoCo ``simulate`` for one prepared recording's scene.

    Args:
        physics: the physics.json document; object_name: the fitted object.
        threads: rollout threads (1: the calling thread).
        engine: an already built :class:`MujocoEngine` of this scene (else one is built).
        tilt_inertia_scale: see :data:`TILT_INERTIA_SCALE`.
        stepper: one of :data:`STEPPERS` (default ``batch`` where MuJoCo has it).
        tracked: other tracked objects (:class:`~robogs.physics.prepare.TrackedObject`: name,
            ``init_pos`` [T, 3] m, ``init_yaw`` [T] rad, ``obs_t`` [T, K] s), see :meth:`track`.
        pusher_speed: m/s, the recording's fastest pusher speed, given to the engine it builds
            (sizes the pusher onset ramp where the settings turn it on; None: not known).
        joints: the engine's joint set (``auto``, ``free``, ``planar``): ``free`` where the
            recorded object leaves the plane (:mod:`robogs.physics.planarity`).
        meshes: object name -> mesh (object frame, m) of the objects with a mesh shape
            (:meth:`robogs.physics.recording.Recording.shapes`), given to the engine it builds
            (collided as convex hulls, on the free joint).

    Attributes:
        last_rollouts: distinct rollouts the last :meth:`simulate` call ran (of its M x T).
        last_steps: MuJoCo steps those rollouts took in all (batch runner; the rest cut
            leaves out the steps that repeat the rest pose).
        distinct: run a rollout that repeats another once (default; False runs all M x T).
    """

    def __init__(
        self,
        physics: Mapping[str, Any],
        object_name: str,
        *,
        dt: float = 1e-3,
        threads: int = 1,
        engine: MujocoEngine | None = None,
        tilt_inertia_scale: float = TILT_INERTIA_SCALE,
        stepper: str | None = None,
        tracked: Sequence[Any] = (),
        pusher_speed: float | None = None,
        joints: str = "auto",
        meshes: Mapping[str, Any] | None = None,
    ) -> None:
        stepper = stepper or ("batch" if _has_batch() else "rollout")
        if stepper not in STEPPERS or (stepper == "batch" and not _has_batch()):
            raise InputError(
                f"stepper {stepper!r} is not available",
                where="stepper",
                hint=f"one of {', '.join(STEPPERS)}; 'batch' needs mujoco >= 3.17",
            )
        self.stepper = stepper
        self.last_rollouts = 0
        self.last_steps = 0
        self.distinct = True  # run each distinct rollout once (False: all M x T, for benches)
        self.eng = engine or MujocoEngine(
            physics,
            object_name=object_name,
            meshes=meshes,
            dt=dt,
            threads=threads,
            pusher_speed=pusher_speed,
            joints=joints,
        )
        m = self.eng.model
        self.nq, self.nv = m.nq, m.nv
        b = self.eng._bid[object_name]
        self.obj = object_name
        pairs = list(self.eng.scene.table_pairs.get(object_name, []))
        self.slots = ObjectSlots(
            body=b,
            dof=self.eng._vadr[object_name],
            table_pairs=pairs,
            nominal_mass=float(m.body_mass[b]),
            nominal_inertia=np.array(m.body_inertia[b]),
            nominal_ipos=np.array(m.body_ipos[b]),
            nominal_iquat=np.array(m.body_iquat[b]),
            table_torsion=[self.eng.scene.pair_torsion[k] for k in pairs],
            tilt_inertia_scale=float(tilt_inertia_scale),
            ballast=self.eng.scene.ballast,
            ballast_actuator=mujoco.mj_name2id(
                m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{object_name}_ballast"
            ),
            com_feet=com_feet(m, self.eng.scene, object_name),
        )
        self.lay = self.eng.layout[object_name]  # free joint or planar joint set
        self.qa, self.va = self.lay.q, self.lay.v  # state columns of its qpos and DOFs
        self.pq = None if self.eng._pusher_q is None else 1 + self.eng._pusher_q[0]
        # state columns of the pusher's x, y, z DOF velocities; object-pusher contact pairs
        self.pv = None if self.eng._pusher_q is None else 1 + self.nq + self.eng._pusher_q[1]
        self._pcols = (
            []
            if self.pv is None
            else [self.pq, self.pq + 1, self.pq + 2, self.pv, self.pv + 1, self.pv + 2]
        )
        self.pusher_pairs = [
            k for k, pr in enumerate(self.eng.scene.pairs) if set(self.eng.pusher_geoms) & set(pr)
        ]
        self.gravity = float(-m.opt.gravity[2])
        self.nbody = m.nbody
        gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, object_name)
        half = np.array(m.geom_size[gid])
        half[2] += m.geom_pos[gid][2]  # the top face: a footprint box's collision face is raised
        self.z_rest_gap = 1e-3  # [m] above the resting height still counts as on the table
        self.c_r = 0.0  # [m] the footprint's mean radius, from the scene each simulate
        self.table_z = float(physics.get("objects", {}).get("table", {}).get("plane_z_m", 0.0))
        self.half_z = float(half[2]) if half.shape[0] >= 3 else 0.0
        # lowest height of the object frame that does not penetrate a horizontal table: a
        # measured start or carried pose a fraction of a millimetre into the table would make
        # the stiff soft contact throw the box up at the release (a chaotic hop that broke the
        # finite-difference Jacobians of fast slides); a mesh hull's from its lowest vertex
        box = m.geom_type[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, object_name)]
        if box != mujoco.mjtGeom.mjGEOM_BOX:
            self.half_z = _below(m, gid)  # -inf where unknown
        self.rest_z = self.table_z + self.half_z
        self.settled_z = self._settle() if np.isfinite(self.rest_z) else -np.inf
        # restitution by impact events (module docstring, "Restitution"): a flat box
        self.bounce_events = bool(
            self.lay.planar and box == mujoco.mjtGeom.mjGEOM_BOX and np.isfinite(self.rest_z)
        )
        self.bounce_min = 0.05  # [m/s] the scene's bounce_min_speed, each simulate
        # pusher strikes by events (module docstring, "Strikes"): a flat box and a pusher
        self.strike_events = bool(
            self.bounce_events
            and self.pq is not None
            and pusher_geometry(physics) == "primitive"
            and self.eng.settings.capsule_ends
        )
        self._strike_ctx: tuple | None = None  # per simulate: (scene, points, velocities, impulses)
        # [m] the farthest box point from the body origin (box point speeds, _strike_horizon)
        self._lever = float(np.linalg.norm(half[:2])) if half.shape[0] >= 2 else 0.0
        self._full_cols, self._int_cols = _state_map(m)
        self.physics = physics
        self.track(tracked)

    def notes(self, effects: Sequence[str]) -> list[str]:
        """What this engine plays another way than the rigid rule for the named effects, one
        line each (said in the fit's revision note): restitution where a box's impacts are not
        events (:attr:`bounce_events`: a free joint, a mesh), MuJoCo's soft bounce."""
        out = []
        if "restitution" in effects and not self.bounce_events:
            out.append(
                f"restitution of {self.obj!r} by MuJoCo's soft bounce (the support pairs' solref; "
                "a free joint or a mesh has no impact events): its rebound runs 4-7 mm behind a "
                "rigid impact's (docs/exports.md)"
            )
        return out

    def track(self, tracked: Sequence[Any]) -> None:
        """Set the other tracked objects (module docstring): their layouts, starts and resting
        heights; :meth:`simulate` then also returns their poses.

        Raises:
            InputError: an object that is not another rigid object of the scene.
        """
        self.tracked = list(tracked)
        self._rest = {}
        for o in self.tracked:
            if o.name == self.obj or o.name not in self.eng._bid:
                raise InputError(
                    f"tracked object {o.name!r} is not another object of the MuJoCo scene",
                    where="tracked",
                    hint=f"objects: {', '.join(n for n in self.eng._bid if n != self.obj)}",
                )
            gid = mujoco.mj_name2id(self.eng.model, mujoco.mjtObj.mjOBJ_GEOM, o.name)
            box = self.eng.model.geom_type[gid] == mujoco.mjtGeom.mjGEOM_BOX
            hz = float(self.eng.model.geom_size[gid][2] + self.eng.model.geom_pos[gid][2])
            rest = self.table_z + (hz if box else _below(self.eng.model, gid))
            known = np.isfinite(rest)
            self._rest[o.name] = (rest, self._settle(name=o.name, rest_z=rest) if known else rest)
        lays = [self.lay] + [self.eng.layout[o.name] for o in self.tracked]
        # state columns up to the last pose the runners record (every object's qpos)
        self._width = max(ly.q + (4 if ly.planar else 7) for ly in lays)

    @property
    def fd_rel_step(self) -> float | None:
        """Finite-difference step (fraction of each slot's scale) the fits of this scene need:
        0.1 with tracked objects, else None (the fitter's default). Box-on-box impacts make
        the objective rough at a finer scale: on the two-box scenario (seed 0, from 0.35 / 0.35)
        1 % steps stopped at mu_a 0.356 (truth 0.45), 10 % at 0.471 / 0.255 (truth 0.25)."""
        return 0.1 if self.tracked else None

    def extra_params(self) -> list[Param]:
        """Base parameters of the tracked objects: each one's table friction
        (:func:`object_friction_param`)."""
        return [object_friction_param(self.physics, o.name) for o in self.tracked]

    def _poses(self, x: np.ndarray) -> np.ndarray:
        """[..., 7 (1 + tracked)] poses of the fitted object, then each tracked one."""
        if not self.tracked:
            return self.lay.pose(x)
        lays = [self.lay] + [self.eng.layout[o.name] for o in self.tracked]
        return np.concatenate([ly.pose(x) for ly in lays], axis=-1)

    def _settle(
        self, seconds: float = 0.3, name: str | None = None, rest_z: float | None = None
    ) -> float:
        """Height [m] of the object frame of the box ``name`` (default the fitted one, resting
        height ``rest_z``) resting flat on a horizontal support: the nominal resting height
        less the soft contacts' equilibrium penetration (under a micrometre with the default
        settings), from a settle with the pusher parked away."""
        m = self.eng.model
        d = mujoco.MjData(m)
        name = name or self.obj
        rest_z = self.rest_z if rest_z is None else rest_z
        qa = self.eng.layout[name].q - 1
        row = np.zeros(1 + m.nq)
        for other, lay in self.eng.layout.items():  # other objects far away
            far = 0.0 if other == name else 1e3 * (1 + lay.qpos)
            lay.set_pose(row, (far, 0.0, rest_z), (1.0, 0.0, 0.0, 0.0))
        d.qpos[:] = row[1:]
        if self.pq is not None:
            d.qpos[self.pq - 1 + 2] = rest_z + PUSHER_PARK_M
        g = m.opt.gravity.copy()
        m.opt.gravity[:2] = 0.0  # a flat, untilted settle (the model's own copy is restored)
        try:
            if self.pq is not None:
                d.ctrl[:] = 0.0
                d.ctrl[2] = d.qpos[self.pq - 1 + 2]
            for _ in range(int(round(seconds / m.opt.timestep))):
                mujoco.mj_step(m, d)
        finally:
            m.opt.gravity[:] = g
        z = float(d.qpos[qa + 2])
        return z if abs(z - rest_z) < 1e-4 else rest_z  # a settle that went wrong

    # ------------------------------------------------------------------ models per set
    def _physics(self, theta: torch.Tensor, space: ParamSpace, scene: Any) -> tuple:
        """(bodies [M, 1], native model effects, {effect: parameters [M, 1]}, active per-step
        force effects with their parameters) of ``theta`` [M, Q]."""
        effects = [
            (e, space.theta_dict(theta, e.name)) for e in space.effects if e.model == "rigid"
        ]
        body_fx, native_fx, force_fx = classify([e for e, _ in effects])
        ths = dict((e.name, th) for e, th in effects)
        body = _base_body(scene, theta, space)
        for e in body_fx:
            body = e.body(ths[e.name], body)
        force = [(e, ths[e.name]) for e in force_fx if _active(e, ths[e.name])]
        return body, native_fx, ths, force

    @staticmethod
    def dynamics_columns(space: ParamSpace) -> list[int]:
        """Columns of ``space`` that enter the dynamics: all but those of sensor effects and of
        other models' effects (a sensor effect maps the sampled poses and the start; the start
        is compared on its own)."""
        skip = {e.name for e in space.effects if e.model != "rigid" or e.family == "sensor"}
        return [i for i, s in enumerate(space.slots) if s.owner not in skip]

    def models(self, theta: torch.Tensor, space: ParamSpace, scene: Any) -> tuple[list, Any, list]:
        """(M models: copies of the compiled one with each set's values written in, bodies
        [M, 1], per-step force effects with their parameters)."""
        body, native_fx, ths, force = self._physics(theta, space, scene)
        tc = float(self.eng.settings.solref[0])
        base = space.theta_dict(theta, BASE)
        mu_p = base.get(PUSHER_FRICTION)
        others = {k: v for k, v in base.items() if k.startswith("objects.")}
        rows = {k: self._other_rows(k) for k in others}
        out = []
        for i in range(theta.shape[0]):
            mi = apply_body(
                self.eng.model,
                body,
                i,
                self.slots,
                timeconst=tc,
                bounce_solref=not self.bounce_events,
            )
            if mu_p is not None:
                mi.pair_friction[self.pusher_pairs, :2] = max(float(mu_p[i, 0]), 1e-5)
            for k, v in others.items():  # another object's table friction (and torsion)
                r, rho = rows[k]
                mu = max(float(v[i, 0]), 1e-5) / (1.0 + self.eng.scene.ballast)  # z ballast
                mi.pair_friction[r, :2] = mu
                mi.pair_friction[r, 2] = np.where(rho > 0, mu * rho, mi.pair_friction[r, 2])
            for e in native_fx:
                NATIVE[e.name](mi, {k: float(v[i, 0]) for k, v in ths[e.name].items()}, self.slots)
            out.append(mi)
        return out, body, force

    def _other_rows(self, key: str) -> tuple[list[int], np.ndarray]:
        """Table-pair rows and torsion radii [m] of the object named in a base slot
        ``objects.<name>.friction_dynamic`` (:func:`object_friction_param`)."""
        parts = key.split(".")
        name = parts[1] if len(parts) == 3 else ""
        if parts[-1] != "friction_dynamic" or name == self.obj or name not in self.eng._bid:
            raise InputError(
                f"base parameter {key!r} is not another object's table friction",
                where="space",
                hint=f"objects.<name>.friction_dynamic, name one of "
                f"{', '.join(n for n in self.eng._bid if n != self.obj)}",
            )
        r = list(self.eng.scene.table_pairs.get(name, []))
        return r, np.array([self.eng.scene.pair_torsion[k] for k in r])

    # ------------------------------------------------------------------ simulate
    def simulate(
        self,
        theta: torch.Tensor,
        space: ParamSpace,
        drive: Drive,
        scene: Any,
        init_offset: torch.Tensor | None = None,
    ) -> SimResult:
        """Object poses at the measurement stamps for M parameter sets x T trajectories
        (see :func:`robogs.physics.model.simulate`; ``SimResult.force``: the pusher force per
        wrench bin when the drive has ``wrench_bin``, else None). Rollouts that would repeat
        another exactly run once (module docstring; :attr:`last_rollouts`)."""
        theta = torch.as_tensor(theta, dtype=torch.float64)
        m_sets, n_t, n_s, dt = theta.shape[0], drive.n_traj, drive.n_steps, drive.dt
        sensor_fx = [
            (e, space.theta_dict(theta, e.name))
            for e in space.effects
            if e.model == "rigid" and e.family == "sensor"
        ]
        # initial pose: measured (sensor frame) + nuisance offset -> world
        ipos = drive.init_pos.to(torch.float64).unsqueeze(0).expand(m_sets, n_t, 3)
        iyaw = drive.init_yaw.to(torch.float64).unsqueeze(0).expand(m_sets, n_t)
        if init_offset is not None:
            off = torch.as_tensor(init_offset, dtype=torch.float64)
            ipos = ipos + torch.nn.functional.pad(off[..., :2], (0, 1))
            iyaw = iyaw + off[..., 2]
        for e, th in reversed(sensor_fx):
            if overrides(e, "from_sensor"):
                ipos, iyaw = e.from_sensor(th, ipos, iyaw)
        x0 = self.eng._initial_states(drive, None, n_t)  # [T, nstate], pusher set
        n_r = m_sets * n_t
        x = np.repeat(x0[None], m_sets, 0).reshape(n_r, -1)
        ip = ipos.numpy().reshape(n_r, 3)
        iy = iyaw.numpy().reshape(n_r)
        x[:, self.qa : self.qa + 3] = ip
        # a box measured at rest on the support starts resting on it (SETTLE_TOL_M); never
        # inside the table
        z0 = np.maximum(ip[:, 2], self.rest_z)
        on = np.abs(ip[:, 2] - self.rest_z) < SETTLE_TOL_M
        x[:, self.qa + 2] = np.where(on, self.settled_z, z0)
        self.lay.set_pose(x, quat=_yaw_quat(iy))
        self.lay.set_vel(x, np.zeros((n_r, 3)), np.zeros((n_r, 3)))
        if drive.init_vel is not None:
            x[:, self.va : self.va + 3] = np.tile(drive.init_vel.numpy(), (m_sets, 1))
        if drive.init_rate is not None:
            rate = np.tile(drive.init_rate.numpy(), m_sets)
            self.lay.set_vel(x, omega=np.stack([0.0 * rate, 0.0 * rate, rate], -1))
        self._place_tracked(x, m_sets, n_t, sensor_fx)
        ctrl = self.eng._controls(drive)  # [T, S-1, nu]
        grasp = drive.grasp.numpy()
        park = np.zeros((n_t, n_s))
        if grasp.any():
            first = np.where(grasp.any(1), np.argmax(grasp, 1), n_s)
            park = (np.arange(n_s)[None] >= first[:, None]) * PUSHER_PARK_M
            if self.pq is not None:
                ctrl[..., 2] += park[:, :-1]
                x[:, self.pq + 2] += np.tile(park[:, 0], m_sets)  # grasped from the start
        # distinct rollouts: (dynamics columns, trajectory, start state); a model per distinct
        # set of dynamics columns, bodies and force parameters per rollout
        dyn = theta.numpy()[:, self.dynamics_columns(space)]
        seen: dict[bytes, int] = {}
        which = np.array(
            [
                seen.setdefault(dyn[r // n_t].tobytes() + (r % n_t).to_bytes(8) + x[r].tobytes(), r)
                for r in range(n_r)
            ]
            if self.distinct
            else range(n_r)
        )
        rows, which = np.unique(which, return_inverse=True)  # first row of each distinct rollout
        sets, set_of = np.unique(rows // n_t, return_inverse=True)
        models, _, _ = self.models(theta[sets], space, scene)
        body, _, _, force_fx = self._physics(theta[rows // n_t], space, scene)
        self.c_r = float(scene.friction_radius)  # friction hooks' torque arm (step_forces)
        self.bounce_min = float(scene.bounce_min_speed)
        self.last_rollouts = len(rows)
        want_force = drive.wrench_bin is not None and self.pv is not None
        pstate = np.zeros((len(rows), n_s, 6)) if want_force else None
        self._strike_begin(drive, scene, len(rows), want_force)
        run = self._run_batch if self.stepper == "batch" else self._run
        dense = run(
            [models[j] for j in set_of.reshape(-1)],
            x[rows],
            ctrl,
            rows % n_t,
            drive,
            body,
            force_fx,
            grasp,
            park,
            pstate,
        )
        which = which.reshape(-1)
        dense = dense[which].reshape(m_sets, n_t, n_s, -1)
        pstate = None if pstate is None else pstate[which]
        dpos = torch.as_tensor(dense[..., :3])
        dyaw = torch.as_tensor(np.unwrap(quat_yaw(dense[..., 3:7]), axis=-1))
        res = _observe(dpos, dyaw, drive.obs_t, sensor_fx, dt)
        if self.tracked:
            others = {}
            for j, o in enumerate(self.tracked, start=1):
                d = dense[..., 7 * j : 7 * j + 7]
                yaw = torch.as_tensor(np.unwrap(quat_yaw(d[..., 3:]), axis=-1))
                o_res = _observe(torch.as_tensor(d[..., :3]), yaw, o.obs_t, sensor_fx, dt)
                others[o.name] = (o_res.pos, o_res.yaw)  # the same sensor as the fitted object
            res = SceneSimResult(
                **{f.name: getattr(res, f.name) for f in fields(res)}, others=others
            )
        if pstate is not None:
            imp = None if self._strike_ctx is None else self._strike_ctx[3][which]
            res.force = self._pusher_force(pstate, ctrl, drive, m_sets, imp)
        self._strike_ctx = None
        return res

    def _place_tracked(
        self, x: np.ndarray, m_sets: int, n_t: int, sensor_fx: Sequence[tuple[Any, Any]] = ()
    ) -> None:
        """Write the tracked objects' measured start poses (row r: set r // T, trajectory
        r % T) into the state rows ``x``, at rest, mapped from the sensor frame to the world by
        the sensor effects (as the fitted object's start: one camera sees every object); a box
        measured within :data:`SETTLE_TOL_M` of its resting height starts settled on the
        support, and never inside it."""
        for o in self.tracked:
            ip, iy = np.asarray(o.init_pos, float), np.asarray(o.init_yaw, float)
            if len(ip) != n_t:
                raise InputError(
                    f"tracked object {o.name!r} has starts for {len(ip)} trajectories, the drive "
                    f"{n_t}",
                    where="tracked",
                    hint="prepare the drive and the tracked objects from one recording",
                )
            rest, settled = self._rest[o.name]
            pos = torch.as_tensor(ip).unsqueeze(0).expand(m_sets, n_t, 3)
            yaw = torch.as_tensor(iy).unsqueeze(0).expand(m_sets, n_t)
            for e, th in reversed(sensor_fx):
                if overrides(e, "from_sensor"):
                    pos, yaw = e.from_sensor(th, pos, yaw)
            p = pos.numpy().reshape(m_sets * n_t, 3).copy()
            p[:, 2] = np.where(
                np.abs(p[:, 2] - rest) < SETTLE_TOL_M, settled, np.maximum(p[:, 2], rest)
            )
            lay = self.eng.layout[o.name]
            lay.set_pose(x, p, _yaw_quat(yaw.numpy().reshape(m_sets * n_t)))
            lay.set_vel(x, np.zeros((len(x), 3)), np.zeros((len(x), 3)))

    def _pusher_force(
        self,
        pstate: np.ndarray,
        ctrl: np.ndarray,
        drive: Drive,
        m_sets: int,
        strikes: np.ndarray | None = None,
    ) -> torch.Tensor:
        """Force the objects exert on the pusher [M, T, W, 3] N (world), averaged per wrench
        bin, from the pusher's dense positions and velocities ``pstate`` [M*T, S, 6]: contact =
        mass x acceleration - servo force (the servos' gain and bias from the model), plus the
        strike events' impulses ``strikes`` [M*T, S, 2] N s (:meth:`_strike`) over the step.

        The vertical component is left at 0, as in the planar model: with pusher friction it is
        the share of the object's weight that the sticking vertical friction of the pusher
        contact carries, statically indeterminate and set by the soft contacts' regularisation
        (0.13-0.2 N of a 0.4 kg box in the pusher-friction scenario), not a quantity the model
        predicts."""
        m = self.eng.model
        n_t, n_s, dt = drive.n_traj, drive.n_steps, drive.dt
        t_of = np.tile(np.arange(n_t), m_sets)
        p, v = pstate[:, :-1, :3], pstate[:, :-1, 3:]
        f_servo = np.zeros_like(v)
        dof0 = self.pv - 1 - self.nq  # the x, y, z slides are the pusher's first three DOFs
        for a in range(m.nu):
            axis = int(m.jnt_dofadr[m.actuator_trnid[a, 0]]) - dof0
            if not 0 <= axis < 3:
                continue
            g, b = m.actuator_gainprm[a, 0], m.actuator_biasprm[a, :3]
            u = ctrl[t_of, :, a]
            f_servo[..., axis] += g * u + b[0] + b[1] * p[..., axis] + b[2] * v[..., axis]
        mass = float(m.body_mass[m.dof_bodyid[dof0]])
        f_c = mass * np.diff(pstate[:, :, 3:], axis=1) / dt - f_servo  # [M*T, S-1, 3]
        if strikes is not None:
            f_c[..., :2] += strikes[:, :-1] / dt
        f_c = f_c.reshape(m_sets, n_t, n_s - 1, 3)
        f_c[..., 2] = 0.0  # the planar model's force: in the table plane (see the docstring)
        bins = drive.wrench_bin.numpy()[:, : n_s - 1]
        width = np.maximum(drive.wrench_width.numpy(), dt)
        out = np.zeros((m_sets, n_t, width.shape[1], 3))
        for t in range(n_t):
            ok = bins[t] >= 0
            np.add.at(out[:, t], (slice(None), bins[t][ok]), f_c[:, t][:, ok] * dt)
        return torch.as_tensor(out / width[None, :, :, None])

    def _run(
        self,
        models_r: list,
        x: np.ndarray,
        ctrl: np.ndarray,
        t_of: np.ndarray,
        drive: Drive,
        body: Any,
        force_fx: list,
        grasp: np.ndarray,
        park: np.ndarray,
        pstate: np.ndarray | None = None,
    ) -> np.ndarray:
        """Dense object poses [R, S, 7] (position, quaternion w x y z) of R rollouts (model
        ``models_r[r]``, full physics start state ``x[r]``, trajectory ``t_of[r]``; ``body`` and
        the force effects' parameters one row per rollout) on ``mujoco.rollout``; fills
        ``pstate`` [R, S, 6] with the pusher's x, y, z positions and velocities when given."""
        n_s = drive.n_steps
        n_r = len(t_of)
        pool = self.eng._pool_get()
        datas = [mujoco.MjData(self.eng.model) for _ in range(self.eng.threads)]
        dense = np.empty((n_r, n_s, 7 * (1 + len(self.tracked))))
        dense[:, 0] = self._poses(x)
        if pstate is not None:
            pstate[:, 0] = x[:, self._pcols]
        g_any = grasp.any(0)
        onset = np.zeros_like(grasp)
        onset[:, 1:] = grasp[:, 1:] & ~grasp[:, :-1]
        onset[:, 0] = grasp[:, 0]
        # steps k whose transition k -> k+1 must be taken alone (a grasp holds or starts at k+1,
        # or the park jump happens at k+1)
        single = np.zeros(n_s, bool)
        single[:-1] = g_any[1:] | (np.diff(park, axis=1) != 0).any(0)
        bounce = self._bounce_rows(body)
        if force_fx:
            single[:] = True
        nu = ctrl.shape[-1]
        spec = mujoco.mjtState.mjSTATE_CTRL.value
        if force_fx:
            spec |= mujoco.mjtState.mjSTATE_XFRC_APPLIED.value
        carry = _Carry(self, drive, t_of, grasp)
        carry.start(x, 0, onset[:, 0], 0)
        vz_prev = x[:, self.va + 2].copy()  # the force effects' normal force (_forces)
        next_strike = 0  # no strike can fire before this step (_strike_horizon)
        k = 0
        while k < n_s - 1:
            if single[k]:
                n = 1
            else:
                nxt = np.flatnonzero(single[k:])
                n = int(nxt[0]) if nxt.size else n_s - 1 - k
                n = max(1, min(n, _MAX_CHUNK, n_s - 1 - k))
            if bounce is not None and n > 1 and self._airborne(x).any():
                n = 1  # an impact event may come at any step
            carry.start(x, k, onset[:, k + 1], k + 1)
            c = ctrl[t_of, k : k + n]
            if bounce is not None and self._bounce(x, bounce, body, grasp[t_of, k]).any():
                next_strike = k  # a landing's friction impulse changes the closing speeds
            if self._strike_ctx is not None:
                if k >= next_strike:
                    off = grasp[t_of, k] | (park[t_of, k] != 0)  # held, or the pusher parked
                    self._strike(x, k, t_of, body, off)
                    next_strike = self._strike_horizon(x, k, t_of, body, off)
                n = min(n, next_strike - k)
                c = ctrl[t_of, k : k + n]
            if force_fx:
                xf = self._forces(x, body, force_fx, vz_prev)
                vz_prev = x[:, self.va + 2].copy()
                full = np.zeros((n_r, n, nu + 6 * self.nbody))
                full[..., :nu] = c
                full[:, 0, nu + 6 * self.slots.body : nu + 6 * self.slots.body + 6] = xf
                c = full
            state, _ = pool.rollout(
                models_r, datas, x, c if c.shape[-1] else None, control_spec=spec, nstep=n
            )
            dense[:, k + 1 : k + 1 + n] = self._poses(state)
            if pstate is not None:
                pstate[:, k + 1 : k + 1 + n] = state[:, :, self._pcols]
            x = np.array(state[:, -1])
            k += n
            if self.pq is not None:
                jump = (park[:, k] - park[:, k - 1])[t_of] if k >= 1 else 0.0
                x[:, self.pq + 2] += jump
            if g_any[k]:
                hold = grasp[t_of, k]
                carry.attach(x, hold, k)
                dense[hold, k] = self._poses(x[hold])
                if (grasp[:, k] != grasp[:, k - 1]).any():
                    next_strike = k  # a grasp starts or ends: its pusher comes or goes
        return dense

    def _run_batch(
        self,
        models_r: list,
        x: np.ndarray,
        ctrl: np.ndarray,
        t_of: np.ndarray,
        drive: Drive,
        body: Any,
        force_fx: list,
        grasp: np.ndarray,
        park: np.ndarray,
        pstate: np.ndarray | None = None,
    ) -> np.ndarray:
        """:meth:`_run` on one ``mujoco.batch.Batch``. Every rollout keeps its state, solver
        warm start included, from call to call, so it is the same whether its steps are taken
        in one call or one at a time (bit-identical to an ``mj_step`` loop). So the rollouts
        whose set switches a force effect on step alone throughout, and the others run apart,
        in multi-step calls between the steps their grasps need (a set with every force effect
        at its zero value gets no applied force; the ``rollout`` path computes it as 0). A call
        costs Python time whatever its size, so there are a few groups, not one per trajectory:
        force effect on or off, times grasping or not (only a group without grasps takes the
        rest cut: the steps before the pusher comes within reach of the resting object and
        after it rests for good repeat the rest pose, :meth:`_still`)."""
        from mujoco import batch as mj_batch

        n_r = len(t_of)
        self.last_steps = 0
        b = mj_batch.Batch(self.eng.model, nsim=n_r, nthread=self.eng.threads)
        b.set_models(models_r)
        b.state[:] = 0.0
        b.state[:, self._int_cols] = x[:, self._full_cols]
        dense = np.empty((n_r, drive.n_steps, 7 * (1 + len(self.tracked))))
        force = _active_rows(force_fx, n_r)
        bounce = self._bounce_rows(body)
        held = grasp.any(1)[t_of]  # grasping trajectories apart: they take no rest cut
        for on, hold in ((True, True), (True, False), (False, True), (False, False)):
            ids = np.flatnonzero((force == on) & (held == hold))
            if not len(ids):
                continue
            fx = [(e, {k: v[ids] for k, v in th.items()}) for e, th in force_fx] if on else []
            self._batch_group(
                b,
                ids,
                x[ids],
                ctrl,
                t_of[ids],
                drive,
                _take(body, ids),
                fx,
                grasp,
                park,
                dense,
                pstate,
                None if bounce is None else bounce[ids],
            )
        return dense

    def _batch_group(
        self, b, ids, x, ctrl, t_of, drive, body, force_fx, grasp, park, dense, pstate, bounce
    ):
        """Run rollouts ``ids`` of batch ``b`` (start states ``x``, trajectories ``t_of``) on
        their common schedule; fills ``dense`` and ``pstate`` rows ``ids``; ``bounce``: the
        rows' restitution for the impact events (:meth:`_bounce`; None: no events)."""
        n_s = drive.n_steps
        full = mujoco.mjtState.mjSTATE_FULLPHYSICS
        xfrc = b.bind("xfrc_applied") if force_fx else None
        x = np.array(x)
        # the state columns up to the object's pose, every step; poses from them at the end
        # (one vectorised conversion instead of one per call)
        w = min(x.shape[1], self._width)
        raw = np.empty((len(ids), n_s, w))
        raw[:, 0] = x[:, :w]
        if pstate is not None:
            pstate[ids, 0] = x[:, self._pcols]
        mine = np.unique(t_of)
        single, _, g_any = _schedule(grasp[mine], park[mine], bool(force_fx))
        _, onset, _ = _schedule(grasp, park, False)
        carry = _Carry(self, drive, t_of, grasp)
        pusher, ee_yaw = carry.arrays[:2]  # the drive's arrays, read once
        carry.start(x, 0, onset[:, 0], 0)
        k = 0
        # nothing moves while every object rests, no two are within 2 mm and the pusher is out
        # of reach of all: those steps repeat the rest pose (_first_reach, _still). Not cut:
        # grasps (the held object follows the end effector: no rest pose) and a wanted pusher
        # force (it comes from the pusher's own simulated dynamics, M dv/dt - servo force, at
        # every step; a cut would leave its states out and re-place the pusher with the
        # servo's ideal velocity, a jump in the force of the first stepped bin)
        cut = pstate is None and not grasp[mine].any() and self._cut_ok()
        # the "rests for good" check looks at every step left (_gaps): it runs every
        # _REST_CHUNK steps, also where a force effect steps the group one step at a time
        # (checked every step, it cost a Stribeck set 60 % of its rollout time)
        next_still = 0
        next_strike = 0  # no strike can fire before this step (_strike_horizon)
        vz_prev = x[:, self.va + 2].copy()  # the force effects' normal force (_forces)
        while k < n_s - 1:
            if cut and k == _PROBE:  # still at rest: on to the step before the pusher's reach
                k0 = self._first_reach(x, t_of, k, pusher, ee_yaw, body, force_fx)
                if k0 > k:
                    raw[:, k + 1 : k0 + 1] = x[:, None, :w]
                    self._place_pusher(x, t_of, k0, pusher, ee_yaw)
                    b.state[np.ix_(ids, self._int_cols)] = x[:, self._full_cols]
                    k = k0
            n = _span(single, k, n_s)
            if cut:
                n = min(n, _REST_CHUNK if k >= _PROBE else _PROBE - k)
            if bounce is not None and n > 1 and self._airborne(x).any():
                n = 1  # an impact event may come at any step
            carry.start(x, k, onset[:, k + 1], k + 1)
            if bounce is not None and self._bounce(x, bounce, body, grasp[t_of, k]).any():
                b.state[np.ix_(ids, self._int_cols)] = x[:, self._full_cols]
                next_strike = k  # a landing's friction impulse changes the closing speeds
            if self._strike_ctx is not None:
                if k >= next_strike:
                    off = grasp[t_of, k] | (park[t_of, k] != 0)  # held, or the pusher parked
                    if self._strike(x, k, t_of, body, off, ids).any():
                        b.state[np.ix_(ids, self._int_cols)] = x[:, self._full_cols]
                    next_strike = self._strike_horizon(x, k, t_of, body, off)
                n = min(n, next_strike - k)
            if xfrc is not None:
                xfrc[ids, self.slots.body] = self._forces(x, body, force_fx, vz_prev)
                vz_prev = x[:, self.va + 2].copy()
            c = ctrl[t_of, k : k + n] if ctrl.shape[-1] else None
            state = b.rollout(n, control=c, record=(full,), ids=ids)[full]
            self.last_steps += n * len(ids)
            raw[:, k + 1 : k + 1 + n] = state[:, :, :w]
            if pstate is not None:
                pstate[ids, k + 1 : k + 1 + n] = state[:, :, self._pcols]
            x = np.array(state[:, -1])
            k += n
            edit = False
            if self.pq is not None and (park[mine, k] != park[mine, k - 1]).any():
                x[:, self.pq + 2] += (park[:, k] - park[:, k - 1])[t_of]
                edit = True
            if g_any[k]:
                hold = grasp[t_of, k]
                carry.attach(x, hold, k)
                raw[hold, k] = x[hold, :w]
                edit = True
                if (grasp[:, k] != grasp[:, k - 1]).any():
                    next_strike = k  # a grasp starts or ends: its pusher comes or goes
            if edit:
                b.state[np.ix_(ids, self._int_cols)] = x[:, self._full_cols]
            if cut and k < n_s - 1 and k >= next_still:
                if self._still(x, t_of, k, pusher, ee_yaw, body, force_fx):
                    raw[:, k + 1 :] = x[:, None, :w]  # at rest for good: the rest pose repeats
                    break
                next_still = k + _REST_CHUNK
        dense[ids] = self._poses(raw)

    # ------------------------------------------------------------------ rest cut
    def _cut_ok(self) -> bool:
        """The rest cut applies: a pusher, and every object of the scene is the fitted one or a
        tracked one, each a box on a horizontal support (its settled height known). Caches per
        object (layout, half sizes of the collision box [m], settled height [m], velocity
        columns) and the pusher geoms' centres (pusher frame) and bounding radii [m] for
        :meth:`_gaps` and :meth:`_apart`."""
        if self.pq is None or self.eng.pusher_dofs:  # geoms off the pusher body: no cut
            return False
        names = [self.obj] + [o.name for o in self.tracked]
        settled = [self.settled_z] + [self._rest[o.name][1] for o in self.tracked]
        m = self.eng.model
        boxes = [
            m.geom_type[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, n)]
            == mujoco.mjtGeom.mjGEOM_BOX
            for n in names
        ]
        if set(self.eng.layout) != set(names) or not np.isfinite(settled).all() or not all(boxes):
            return False  # an untracked object (its state unchecked) or a mesh
        if not hasattr(self, "_pgeoms"):
            pb = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "pusher")
            g = np.flatnonzero(m.geom_bodyid == pb)
            self._pgeoms = (np.array(m.geom_pos[g]), np.array(m.geom_rbound[g]))
        self._cut_objs = []
        for name, z in zip(names, settled, strict=True):
            gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
            lay = self.eng.layout[name]
            # the collision box (its face raised over the footprint) grown by its offset
            half = np.array(m.geom_size[gid]) + np.abs(m.geom_pos[gid])
            self._cut_objs.append((lay, half, float(z), lay.v + np.arange(4 if lay.planar else 6)))
        return True

    def _gaps(self, x, t_of, pusher, ee_yaw, k: int) -> np.ndarray:
        """[R, S - k] clearance [m] between the pusher's geoms (bounding spheres) and the
        nearest object (box) of state rows ``x`` at the steps k on, less a 2 mm margin (<= 0:
        it may touch)."""
        pos, rad = self._pgeoms
        c, s = np.cos(ee_yaw[t_of, k:]), np.sin(ee_yaw[t_of, k:])  # pusher frame -> world
        gx = c[..., None] * pos[:, 0] - s[..., None] * pos[:, 1]
        gy = s[..., None] * pos[:, 0] + c[..., None] * pos[:, 1]
        pts = pusher[t_of, k:, None, :] + np.stack(
            [gx, gy, np.broadcast_to(pos[:, 2], gx.shape)], -1
        )
        best = np.full(pts.shape[:2], np.inf)
        for lay, half, _, _ in self._cut_objs:
            d = pts - lay.pos(x)[:, None, None, :]
            yaw = quat_yaw(lay.quat(x))[:, None, None]
            cy, sy = np.cos(yaw), np.sin(yaw)  # world -> box frame
            q = np.stack(
                [cy * d[..., 0] + sy * d[..., 1], -sy * d[..., 0] + cy * d[..., 1], d[..., 2]], -1
            )
            out = np.linalg.norm(np.maximum(np.abs(q) - half, 0.0), axis=-1) - rad
            best = np.minimum(best, out.min(-1))
        return best - 2e-3

    def _apart(self, x) -> bool:
        """Every two objects of every state row ``x`` are more than 2 mm apart, by a lower
        bound of their distance: the largest gap between their boxes projected on the world z
        axis and on either box's two horizontal axes (separating axes; each projection's gap
        is at most the distance; Gottschalk, Lin & Manocha 1996, OBBTree)."""
        objs = self._cut_objs
        for i, (la, ha, _, _) in enumerate(objs):
            for lb, hb, _, _ in objs[i + 1 :]:
                d = lb.pos(x) - la.pos(x)  # [R, 3]
                ya, yb = quat_yaw(la.quat(x)), quat_yaw(lb.quat(x))
                gap = np.abs(d[:, 2]) - ha[2] - hb[2]
                for yaw in (ya, ya + 0.5 * np.pi, yb, yb + 0.5 * np.pi):
                    u = np.stack([np.cos(yaw), np.sin(yaw)], -1)  # [R, 2] unit axis
                    sep = np.abs(np.sum(d[:, :2] * u, -1)) - _reach(ha, ya, u) - _reach(hb, yb, u)
                    gap = np.maximum(gap, sep)
                if (gap <= 2e-3).any():
                    return False
        return True

    def _resting(self, x, body, force_fx, v_scale_z: float = 1.0) -> bool:
        """Every object of state rows ``x`` at rest: every DOF slower than :data:`REST_SPEED`
        (the vertical one than ``v_scale_z`` times it), within 20 um of its settled height, no
        applied force of a force effect on the fitted object, and no two objects within 2 mm
        of each other (:meth:`_apart`: no contact between them can start)."""
        for lay, _, z, vcols in self._cut_objs:
            v = np.abs(x[:, vcols])
            v[:, 2] /= v_scale_z
            if v.max() >= REST_SPEED or np.abs(x[:, lay.q + 2] - z).max() >= 2e-5:
                return False
        if force_fx and np.abs(self._forces(x, body, force_fx)).max() > 1e-12:
            return False
        return self._apart(x)

    def _still(self, x, t_of, k, pusher, ee_yaw, body, force_fx) -> bool:
        """Every rollout's objects rest from step ``k`` on (:meth:`_resting`) and the pusher is
        out of reach of every object for the steps left. Then the state is an equilibrium the
        rest of the rollout would keep (friction holds a box below its friction angle; the
        planar model's box, too, stays)."""
        if not self._resting(x, body, force_fx):
            return False
        return bool((self._gaps(x, t_of, pusher, ee_yaw, k) > 0).all())

    def _first_reach(self, x, t_of, k, pusher, ee_yaw, body, force_fx) -> int:
        """The last step before the pusher first comes within reach of any object of a
        rollout, from step ``k`` on, when every object is still at rest there
        (:meth:`_resting`: its first steps show a box that starts to move, e.g. on a table
        tilted beyond its friction angle); else ``k``. The vertical speed may reach 100x
        :data:`REST_SPEED`: a set whose mass differs from the compiled one settles by a few
        micrometres (MuJoCo's contact impedance uses the compiled ``body_invweight0``), which
        the cut leaves to the steps after it."""
        if not self._resting(x, body, force_fx, v_scale_z=100.0):
            return k
        near = self._gaps(x, t_of, pusher, ee_yaw, k) <= 0
        first = np.where(near.any(1), np.argmax(near, 1), near.shape[1])
        return k + max(int(first.min()) - 1, 0)

    def _place_pusher(self, x, t_of, k, pusher, ee_yaw) -> None:
        """Put the pusher of state rows ``x`` where the drive has it at step ``k`` (position,
        yaw, and the velocities its dead-beat servo reaches there)."""
        x[:, self.pq : self.pq + 3] = pusher[t_of, k]
        x[:, self.pq + 3] = ee_yaw[t_of, k]
        x[:, self.pv : self.pv + 3] = (pusher[t_of, k] - pusher[t_of, k - 1]) / self.eng.dt
        x[:, self.pv + 3] = (ee_yaw[t_of, k] - ee_yaw[t_of, k - 1]) / self.eng.dt

    def _grasp_rel(self, x, p_ee, yaw_ee, t_of, on_t, rel_p, rel_q):
        """Freeze the object pose in the EE yaw frame for rollouts whose grasp starts now."""
        on = on_t[t_of]
        if not on.any():
            return rel_p, rel_q
        rel_p, rel_q = rel_p.copy(), rel_q.copy()
        ey = yaw_ee[t_of][on]
        d = x[on, self.qa : self.qa + 3] - p_ee[t_of][on]
        c, s = np.cos(-ey), np.sin(-ey)
        rel_p[on] = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], -1)
        rel_q[on] = _qmul(_yaw_quat(-ey), self.lay.quat(x[on]))
        return rel_p, rel_q

    def _carried(
        self,
        tt: np.ndarray,
        ks: np.ndarray,
        arrays: tuple[np.ndarray, ...],
        rel_p: np.ndarray,
        rel_q: np.ndarray,
    ) -> np.ndarray:
        """The object held on the EE, rigidly in the EE's yaw frame: its state columns
        (:meth:`~robogs.physics.engines.mujoco_engine.JointLayout.columns`) [n, K, C] for
        rollouts on trajectories ``tt`` [n] at steps ``ks`` [K]. Position ``ee + R(yaw) rel_p``
        (never below the resting height), orientation ``q(yaw) rel_q``, velocity ``v_ee + rate
        z x R(yaw) rel_p`` (world), angular velocity ``rate z``; ``arrays`` as
        :func:`_drive_arrays` gives them, ``rel_p`` [n, 3] m and ``rel_q`` [n, 4] (w, x, y, z)
        each grasp's pose in the EE frame (:meth:`_grasp_rel`)."""
        pusher, ee_yaw, cvel, rate = arrays
        at = (tt[:, None], ks[None])
        ey = ee_yaw[at]
        c, s = np.cos(ey), np.sin(ey)
        rp = rel_p[:, None]
        rx, ry = c * rp[..., 0] - s * rp[..., 1], s * rp[..., 0] + c * rp[..., 1]
        pos = pusher[at] + np.stack([rx, ry, np.broadcast_to(rp[..., 2], rx.shape)], -1)
        pos[..., 2] = np.maximum(pos[..., 2], self.rest_z)
        lay = self.lay.compact()
        out = np.zeros(ey.shape + (len(self.lay.columns()),))
        lay.set_pose(out, pos, _qmul(_yaw_quat(ey), rel_q[:, None]))
        r = rate[at]
        z = np.zeros_like(r)
        lay.set_vel(out, cvel[at] + np.stack([-r * ry, r * rx, z], -1), np.stack([z, z, r], -1))
        return out

    # ------------------------------------------------------------------ impacts
    def _bounce_rows(self, body) -> np.ndarray | None:
        """[R] restitution of the rollouts' object (``body`` rows) for the impact events of
        :meth:`_bounce`, clipped to 0-0.98; None where the engine has none (not a flat box on
        the planar joint set, :attr:`bounce_events`: the support pairs' solref bounces it)."""
        if not self.bounce_events:
            return None
        return np.clip(body.restitution.detach().numpy()[:, 0].astype(float), 0.0, 0.98)

    def _airborne(self, x) -> np.ndarray:
        """[R] bool: state rows whose object is off its resting height by more than 0.1 mm or
        moves vertically faster than 1 cm/s (held ones too: a release may come at the next
        step): an impact may come within the next steps, so they are stepped one at a time (a
        box resting or sliding on the table stays on it on the planar joint set)."""
        return (x[:, self.qa + 2] - self.rest_z > 1e-4) | (np.abs(x[:, self.va + 2]) > 1e-2)

    def _bounce(self, x, e, body, held) -> np.ndarray:
        """Newton impacts of the object with the table in the step about to be taken from
        state rows ``x`` [R, nstate] (changed in place), as the planar model's table contact
        (:mod:`robogs.physics.model`) and the generator take them: where the step's velocity
        before contact, ``v_z - g dt``, approaches faster than the scene's
        ``bounce_min_speed`` and would close the gap within the step, the box leaves the table
        at ``e`` times the approach speed, the rebound starting at the time of impact in the
        step, and the normal impulse ``(1 + e)`` times the approach speed (per unit mass)
        takes the Coulomb friction impulse ``mu_d`` times it off the CoM's planar twist
        ``(v_x, v_y, c_r w)`` (ellipsoidal limit surface, sticking when that stops it; MuJoCo
        has no static coefficient). The support pair is plastic (:func:`~robogs.format.mjcf.
        write_body` with ``bounce_solref=False``) and pushes nothing at these steps: the box
        starts them at most ``e`` times the gap (under 1 mm) deep, leaving at ``e`` times the
        approach speed, where the soft contact's reference acceleration pulls.
        ``e`` [R]: restitution per row (0: a plastic impact, the same event: the landing's
        friction impulse is the rigid one, and the objective is continuous at ``e = 0``);
        ``held`` [R]: rows held by a grasp (no events). Returns [R] bool, the rows hit."""
        dt, g = self.eng.dt, self.gravity
        qz, vz = self.qa + 2, self.va + 2
        v1 = x[:, vz] - g * dt
        gap = x[:, qz] - self.rest_z
        # not yet in contact: a box the plastic support already holds (more than 10 um deep,
        # its rest is 8 um) is left to it, else the event would depend on where the contact's
        # solver left the speed, at the threshold (the two runners parted by 0.1 mm)
        hit = ~held & (gap > -1e-5) & (-v1 > self.bounce_min) & (gap + dt * v1 <= 0.0)
        if not hit.any():
            return hit
        h = np.flatnonzero(hit)
        ap = -v1[h]
        lam = (1.0 + e[h]) * ap  # normal impulse per unit mass [m/s]
        # friction on the CoM twist (the velocity columns are the body origin's), by the
        # planar model's own table-friction step
        com = body.com.detach().numpy()[h, 0]
        yaw = x[h, self.qa + 3]
        c, s = np.cos(yaw), np.sin(yaw)
        rx, ry = c * com[:, 0] - s * com[:, 1], s * com[:, 0] + c * com[:, 1]  # R com, world
        w = x[h, self.va + 3]
        vcx, vcy = x[h, self.va] - w * ry, x[h, self.va + 1] + w * rx
        kr = body.mass.detach().numpy()[h] * self.c_r**2 / body.inertia_z.detach().numpy()[h]
        mu = body.mu_d.detach().numpy()[h]  # [H, 1]; static = dynamic on MuJoCo
        col = (vcx[:, None], vcy[:, None], w[:, None])  # [H, 1]: the planar step's layout
        vcx, vcy, w = (
            a[:, 0]
            for a in _steps(np.dtype(np.float64)).friction(
                *col,
                col[0] ** 2 + col[1] ** 2,
                lam[:, None],
                np.ones((len(h), 1), bool),
                mu,
                mu,
                kr,
                self.c_r,
            )
        )
        x[h, self.va + 3] = w
        x[h, self.va] = vcx + w * ry
        x[h, self.va + 1] = vcy - w * rx
        # the rebound from the time of impact tau = gap / ap in the step: after MuJoCo's step
        # (gravity, then position) the box is e ap (dt - tau) above the contact height, moving
        # up at e ap
        x[h, vz] = e[h] * ap + g * dt
        x[h, qz] = self.rest_z - e[h] * np.maximum(gap[h], 0.0)
        return hit

    # ------------------------------------------------------------------ strikes
    def _strike_begin(self, drive: Drive, scene: Any, n_rows: int, want_force: bool) -> None:
        """Set up :meth:`_strike` for one :meth:`simulate`: the drive's end-sphere centres and
        velocities [T, S, J, 3] (the planar model's, :func:`~robogs.physics.model.
        _pusher_points`) and, where the pusher force is wanted, the events' impulses [R, S, 2]."""
        if not self.strike_events:
            self._strike_ctx = None
            return
        f64 = torch.float64
        pts, pv = _pusher_points(
            scene,
            drive.pusher.to(f64),
            drive.pusher_vel.to(f64),
            drive.ee_yaw.to(f64),
            drive.ee_yaw_rate.to(f64),
        )
        imp = np.zeros((n_rows, drive.n_steps, 2)) if want_force else None
        self._strike_ctx = (scene, pts, pv, imp)

    def _contacts(self, x, k: int, t_of, body, grasping):
        """:func:`~robogs.physics.model.pusher_contacts` of state rows ``x`` [R, nstate] at
        step ``k`` (rows as the model's T axis), with the CoM (world), yaw and CoM velocity."""
        scene, pts_all, pv_all, _ = self._strike_ctx
        com = body.com.detach().numpy()[:, 0]  # [R, 2] body frame (x, y)
        yaw = x[:, self.qa + 3]
        c, s = np.cos(yaw), np.sin(yaw)
        rx, ry = c * com[:, 0] - s * com[:, 1], s * com[:, 0] + c * com[:, 1]
        p = x[:, self.qa : self.qa + 3] + np.stack([rx, ry, 0.0 * rx], -1)
        w = x[:, self.va + 3]
        vcx, vcy = x[:, self.va] - w * ry, x[:, self.va + 1] + w * rx
        args = (p[None], c[None], s[None], vcx[None], vcy[None], w[None])
        coms = (com[None, :, 0], com[None, :, 1])
        pts, pv = pts_all[t_of, k], pv_all[t_of, k]
        geo = pusher_contacts(scene, *args, *coms, pts, pv, grasping)
        return geo, args, coms, (pts, pv), (rx, ry)

    def _strike_horizon(self, x, k: int, t_of, body, grasping) -> int:
        """The first step after ``k`` (at most :data:`_STRIKE_WINDOW` on) at which a strike
        (:meth:`_strike`) could fire in state rows ``x``: the runners check for strikes only
        from there (and again after an impact event or a grasp change). A sphere's closing
        speed ``i`` steps on is at most its speed now, plus the change ``dv_i`` of the drive's
        sphere velocity since, plus the box point's speed now (friction can stop it, not
        reverse it), plus :data:`_BOX_ACCEL` ``i dt`` (what else may push the box: a tilted
        table, force effects); a sphere off the box (gap over 0.1 mm) cannot strike before
        that bound, summed over the steps, has covered its gap. A sphere that touches the box
        and closes slower than half :data:`STRIKE_MIN_SPEED` is the soft pair's: it strikes
        again only after the pusher has braked away and come back, so not before ``dv_i``
        exceeds half :data:`STRIKE_MIN_SPEED`. A strike the bound misses is taken by the soft
        pair, as without events."""
        dt = self.eng.dt
        geo = self._contacts(x, k, t_of, body, grasping)[0]
        close = np.maximum(-geo.rate_n[0], 0.0)  # [R, J]
        act = geo.active[0]
        touch = act & (geo.gap[0] <= 1e-4) & (close < 0.5 * STRIKE_MIN_SPEED)
        win = self._strike_ctx[2][t_of, k : k + _STRIKE_WINDOW + 1, :, :2]  # [R, W, J, 2]
        dv = np.linalg.norm(win - win[:, :1], axis=-1)  # [R, W, J]
        i = np.arange(dv.shape[1])[None, :, None]
        v_pt = np.hypot(x[:, self.va], x[:, self.va + 1]) + np.abs(x[:, self.va + 3]) * self._lever
        bound = (close + v_pt[:, None])[:, None] + dv + _BOX_ACCEL * i * dt  # at step k + i
        reach = np.cumsum(bound, axis=1) * dt  # distance closed by the end of step k + i
        gap = np.maximum(geo.gap[0], 0.0)[:, None]
        soft = dv >= 0.5 * STRIKE_MIN_SPEED
        could = np.where(touch[:, None], soft, (bound > STRIKE_MIN_SPEED) & (reach >= gap))
        could = (could & act[:, None]).any(axis=(0, 2))
        could[0] = False  # step k: checked already
        return k + (int(np.argmax(could)) if could.any() else len(could))

    def _strike(self, x, k: int, t_of, body, grasping, rows=None) -> np.ndarray:
        """Pusher strikes in the step about to be taken from state rows ``x`` [R, nstate]
        (changed in place) as the planar model and the generator take them: where an end
        sphere of the drive's pusher (at step ``k``) closes on the box faster than
        :data:`STRIKE_MIN_SPEED` and would reach it within the step, the box takes the planar
        model's frictionless inelastic contact impulse (:func:`~robogs.physics.model.
        _pusher_impulse`: both end spheres at once, speculative, so it touches at the end of
        the step), on its CoM twist. Slower approaches, and the steady push that follows, are
        the soft pusher pair's. ``grasping`` [R]: rows held by a grasp or whose pusher is parked
        after one (:data:`PUSHER_PARK_M`; no strikes); ``rows``
        [R]: the rows' indices into the impulse record (pusher force). Returns [R] bool."""
        hit = np.zeros(len(x), bool)
        if self._strike_ctx is None:
            return hit
        dt = self.eng.dt
        geo, args, coms, (pts, pv), (rx, ry) = self._contacts(x, k, t_of, body, grasping)
        close = -geo.rate_n[0]
        fire = geo.active[0] & (close > STRIKE_MIN_SPEED) & (geo.gap[0] - close * dt <= 0.0)
        hit = fire.any(-1)
        if not hit.any():
            return hit
        h = np.flatnonzero(hit)
        mass = body.mass.detach().numpy()[h, 0][None]
        inertia = body.inertia_z.detach().numpy()[h, 0][None]
        sub = [a[:, h] for a in args]
        vcx, vcy, w, jx, jy = (
            a[0]
            for a in _pusher_impulse(
                self._strike_ctx[0],
                *sub,
                coms[0][:, h],
                coms[1][:, h],
                mass,
                inertia,
                pts[h],
                pv[h],
                grasping[h],
                dt,
            )
        )
        x[h, self.va + 3] = w
        x[h, self.va] = vcx + w * ry[h]
        x[h, self.va + 1] = vcy - w * rx[h]
        imp = self._strike_ctx[3]
        if imp is not None:
            r = h if rows is None else np.asarray(rows)[h]
            imp[r, k] += np.stack([jx, jy], -1)
        return hit

    def _forces(self, x, body, force_fx, vz_prev=None) -> np.ndarray:
        """Per-step applied wrench [R, 6] of the force effects from the rollouts' current
        states ``x`` [R, nstate] (``body`` and the effects' parameters one row per rollout);
        ``vz_prev`` [R]: the object's vertical velocity a step before [m/s], which gives the
        table's normal force (:func:`step_forces` ``az``); None: the object's weight."""
        n_r = x.shape[0]
        v = x[:, self.va : self.va + 3]
        com = body.com.numpy()[:, 0]  # body frame [m]
        # velocity of the CoM = origin velocity + omega x (R ipos)
        if self.lay.planar:  # yaw and yaw rate are state columns: the same in 2-D
            c, s = np.cos(x[:, self.qa + 3]), np.sin(x[:, self.qa + 3])
            w = x[:, self.va + 3]
            vc = v.copy()
            vc[:, 0] -= w * (s * com[:, 0] + c * com[:, 1])
            vc[:, 1] += w * (c * com[:, 0] - s * com[:, 1])
            yaw = np.arctan2(s, c)  # in (-pi, pi], as quat_yaw gives it
        else:
            q = self.lay.quat(x)
            w_world = self.lay.omega(x)
            w = w_world[:, 2]
            vc = v + _cross(w_world, _rot(q, com))
            yaw = quat_yaw(q)
        gap = x[:, self.qa + 2] - (self.table_z + self.half_z)
        f = step_forces(
            force_fx,
            body,
            vc.reshape(n_r, 1, 3),
            w.reshape(n_r, 1),
            yaw.reshape(n_r, 1),
            (gap < self.z_rest_gap).reshape(n_r, 1),
            self.gravity,
            self.eng.dt,
            self.c_r,
            None if vz_prev is None else ((v[:, 2] - vz_prev) / self.eng.dt).reshape(n_r, 1),
        )
        return f.reshape(n_r, 6)


class _Carry:
    """Held objects of a runner's rollouts: at each grasp's onset its pose on the EE is frozen
    (:meth:`MujocoFit._grasp_rel`); the held states of every grasping rollout are then made
    for ``_CARRY_BLOCK`` steps at once (:meth:`MujocoFit._carried`) and each held step writes
    its rows (the same values as computing them step by step, without a dozen small array
    operations a step; memory bounded by the block, not the trajectory's length)."""

    def __init__(self, sim: MujocoFit, drive: Drive, t_of: np.ndarray, grasp: np.ndarray):
        self.sim, self.t_of, self.n_s = sim, t_of, drive.n_steps
        self.arrays = _drive_arrays(drive)
        self.rel_p = np.zeros((len(t_of), 3))
        self.rel_q = np.tile([1.0, 0, 0, 0], (len(t_of), 1))
        self.cols = sim.lay.columns()
        # the rollouts whose trajectory grasps, and each one's row of the block (-1: none)
        grasps = grasp.any(1)[t_of]
        self.grasping = np.flatnonzero(grasps)
        self.row = np.cumsum(grasps) - 1
        self.row[~grasps] = -1
        self.k0 = -1  # first step of the block; -1: none made since the last onset
        self.block = np.zeros((0, 0, len(self.cols)))

    def start(self, x: np.ndarray, k_ee: int, on_t: np.ndarray, k: int) -> None:
        """Grasps that start at step ``k`` (``on_t`` [T] per trajectory): the objects' poses in
        state rows ``x`` relative to the EE at step ``k_ee``."""
        if k >= self.n_s or not on_t[self.t_of].any():
            return
        pusher, ee_yaw = self.arrays[:2]
        self.rel_p, self.rel_q = self.sim._grasp_rel(
            x, pusher[:, k_ee], ee_yaw[:, k_ee], self.t_of, on_t, self.rel_p, self.rel_q
        )
        self.k0 = -1  # the block was made with the old grasp poses

    def attach(self, x: np.ndarray, hold: np.ndarray, k: int) -> None:
        """Set the held objects of state rows ``x`` (``hold`` [R] bool) where step ``k`` has
        them."""
        if self.k0 < 0 or not 0 <= k - self.k0 < self.block.shape[1]:
            g = self.grasping
            ks = np.arange(k, min(k + _CARRY_BLOCK, self.n_s))
            self.block = self.sim._carried(
                self.t_of[g], ks, self.arrays, self.rel_p[g], self.rel_q[g]
            )
            self.k0 = k
        rows = np.flatnonzero(hold)
        x[rows[:, None], self.cols] = self.block[self.row[rows], k - self.k0]


def _below(m: mujoco.MjModel, gid: int) -> float:
    """How far [m] a mesh geom reaches below its body frame's origin along the body's z (its
    lowest compiled vertex: the resting height above a horizontal support of a body turned
    about z only, as every start is); -inf for other geom types (unknown)."""
    if m.geom_type[gid] != mujoco.mjtGeom.mjGEOM_MESH:
        return -np.inf
    k = int(m.geom_dataid[gid])
    v0, nv = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, m.geom_quat[gid])
    z = m.geom_pos[gid][2] + m.mesh_vert[v0 : v0 + nv] @ rot.reshape(3, 3)[2]
    return float(-np.min(z))


def _schedule(
    grasp: np.ndarray, park: np.ndarray, force: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(steps k whose transition k -> k+1 is taken alone [S], grasp onsets [T, S], a grasp at
    each step [S]): alone where a grasp holds or starts at k+1, the pusher is parked at k+1, or
    a force effect needs every step's state."""
    g_any = grasp.any(0)
    onset = np.zeros_like(grasp)
    onset[:, 1:] = grasp[:, 1:] & ~grasp[:, :-1]
    onset[:, 0] = grasp[:, 0]
    single = np.zeros(grasp.shape[1], bool)
    single[:-1] = g_any[1:] | (np.diff(park, axis=1) != 0).any(0)
    if force:
        single[:] = True
    return single, onset, g_any


def _active_rows(force_fx: list, n_r: int) -> np.ndarray:
    """[R] bool: the row's set moves some force effect off its switched-off values."""
    out = np.zeros(n_r, bool)
    for e, th in force_fx:
        if not e.params:
            out[:] = True
        zero = {p.name: p.zero for p in e.params}
        for k, v in th.items():
            out |= (v != zero[k]).reshape(n_r, -1).any(1).numpy()
    return out


def _reach(half: np.ndarray, yaw: np.ndarray, u: np.ndarray) -> np.ndarray:
    """[R] half extent [m] along the horizontal unit axes ``u`` [R, 2] of boxes of half sizes
    ``half`` (x, y first) turned by ``yaw`` [R] rad about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return half[0] * np.abs(c * u[:, 0] + s * u[:, 1]) + half[1] * np.abs(
        -s * u[:, 0] + c * u[:, 1]
    )


def _take(body: Any, ids: np.ndarray) -> Any:
    """Rows ``ids`` of a :class:`~robogs.physics.model.Body` ([M, 1] tensors)."""
    idx = torch.as_tensor(ids)
    return type(body)(**{f.name: getattr(body, f.name)[idx] for f in fields(body)})


def _span(single: np.ndarray, k: int, n_s: int) -> int:
    """Steps to take in one call from step ``k``: 1 where that step is taken alone, else up to
    the next such step, at most ``_MAX_CHUNK``."""
    if single[k]:
        return 1
    nxt = np.flatnonzero(single[k:])
    n = int(nxt[0]) if nxt.size else n_s - 1 - k
    return max(1, min(n, _MAX_CHUNK, n_s - 1 - k))


def _drive_arrays(drive: Drive) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(EE position [T, S, 3] m, EE yaw [T, S] rad, carried velocity [T, S, 3] m/s, EE yaw rate
    [T, S] rad/s)."""
    cvel = drive.pusher_vel if drive.carry_vel is None else drive.carry_vel
    return drive.pusher.numpy(), drive.ee_yaw.numpy(), cvel.numpy(), drive.ee_yaw_rate.numpy()


def _has_batch() -> bool:
    """Whether this MuJoCo has ``mujoco.batch`` (3.17 on)."""
    try:
        from mujoco import batch  # noqa: F401
    except ImportError:
        return False
    return True


def _state_map(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(columns of the full physics state, the same quantities' columns in the integration
    state a ``mujoco.batch`` row holds), found by writing distinct values with ``mj_setState``."""
    full, integ = mujoco.mjtState.mjSTATE_FULLPHYSICS, mujoco.mjtState.mjSTATE_INTEGRATION
    probe = np.arange(1.0, mujoco.mj_stateSize(model, full) + 1.0)
    d = mujoco.MjData(model)
    mujoco.mj_setState(model, d, probe, full)
    out = np.zeros(mujoco.mj_stateSize(model, integ))
    mujoco.mj_getState(model, d, out, integ)
    dst = np.flatnonzero(out)
    src = out[dst].astype(int) - 1
    if sorted(src.tolist()) != list(range(len(probe))):
        raise RuntimeError("the full physics state is not part of the integration state")
    return src, dst


def _active(e: Any, th: dict[str, torch.Tensor]) -> bool:
    """Whether any set moves the effect off its switched-off values."""
    zero = {p.name: p.zero for p in e.params}
    return not e.params or any(bool((v != zero[k]).any()) for k, v in th.items())


def _observe(dpos, dyaw, obs_t: torch.Tensor, sensor_fx, dt: float) -> SimResult:
    """Sample the dense poses [M, T, S, 3] m, [M, T, S] rad at the (effect-mapped) stamps
    ``obs_t`` [T, K] s and map them into the sensor frame (the same observation as the planar
    model's)."""
    m_sets, n_t, n_s = dpos.shape[:3]
    t_q = torch.as_tensor(obs_t).to(torch.float64).unsqueeze(0).expand(m_sets, n_t, -1)
    for e, th in sensor_fx:
        t_q = e.sample_times(_lift(th), t_q)
    fidx = (t_q / dt).clamp(0.0, n_s - 1 - 1e-9)
    i0 = fidx.floor().long()
    frac = fidx - i0
    i1 = (i0 + 1).clamp(max=n_s - 1)
    g0 = torch.gather(dpos, 2, i0.unsqueeze(-1).expand(-1, -1, -1, 3))
    g1 = torch.gather(dpos, 2, i1.unsqueeze(-1).expand(-1, -1, -1, 3))
    pos = g0 * (1 - frac).unsqueeze(-1) + g1 * frac.unsqueeze(-1)
    yaw = torch.gather(dyaw, 2, i0) * (1 - frac) + torch.gather(dyaw, 2, i1) * frac
    for e, th in sensor_fx:
        pos, yaw = e.to_sensor(_lift(th), pos, yaw)
    return SimResult(pos=pos, yaw=yaw, dense_pos=dpos, dense_yaw=dyaw, force=None)


def _yaw_quat(yaw: np.ndarray) -> np.ndarray:
    yaw = np.asarray(yaw, float)
    z = np.zeros_like(yaw)
    return np.stack([np.cos(yaw / 2), z, z, np.sin(yaw / 2)], -1)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (w, x, y, z) quaternions [..., 4]."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def _rot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors [..., 3] (or planar [..., 2], z = 0) by unit quaternions [..., 4]."""
    if v.shape[-1] == 2:
        v = np.concatenate([v, np.zeros(v.shape[:-1] + (1,))], -1)
    u, w = q[..., 1:], q[..., :1]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of [..., 3] vectors (``np.cross``'s values, without its per-call cost:
    the force effects call it every step)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], -1)


def _rot_t(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors by the inverse of unit quaternions."""
    qc = q.copy()
    qc[..., 1:] *= -1
    return _rot(qc, v)

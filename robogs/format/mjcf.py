"""MJCF (MuJoCo's XML) of a robogs scene: physics.json + object meshes -> one XML document.

This is a serialisation of the format's physics model into another format, so it lives in
``robogs.format``: the MuJoCo engine (``robogs.physics.engines``) compiles it in memory, the
``mjcf`` exporter (``robogs.convert.export.mjcf``) writes it to disk. It needs no MuJoCo itself
(the XML is built with :mod:`xml.etree.ElementTree`; meshes are hulled with trimesh).

What the document holds (world frame = the dataset world, z up, metres):

* ``table`` - a plane through ``objects.table.point_m`` (default ``(0, 0, plane_z_m)``) with
  normal ``objects.table.normal`` (default +z), so a fitted tilted plane stays tilted;
* one body per ``rigid`` object (``mass_kg``, ``com_m``, ``inertia_kgm2`` as an explicit
  ``<inertial>``; the geometry is never used for mass): a box of ``size_m`` resting on an
  n x n grid of small spheres on its bottom face (:func:`footprint_points`: the friction
  torque of a uniformly loaded face, not of four corners), or the convex hull
  of the object's mesh when one is given (:func:`collision_hull`; MuJoCo collides a mesh
  through its convex hull anyway, so a non-convex, open or too-detailed mesh is replaced by its
  hull, decimated to :data:`MAX_HULL_VERTICES`, and the substitution is reported);
* ``static`` objects other than the table with a box size or mesh: fixed geometry;
* ``pusher`` - the pusher shape (``shape`` sphere | capsule | box, ``radius_m``, ``length_m``
  along the pusher frame's y axis, ``size_m`` for a box) on a body with four joints (slide x,
  y, z and a hinge about z: the planar pusher's degrees of freedom) driven by servos (see
  :data:`PUSHER_ACTUATORS`). It is not a mocap body: MuJoCo gives a mocap body zero velocity
  in the contact solver, so pusher friction would oppose the object's motion instead of the
  relative sliding, and the normal contact would only see the penetration, never the rate;
* contacts as explicit ``<pair>`` elements (every geom has ``contype = conaffinity = 0``), so
  each pair carries its own friction: object-table ``objects.<obj>.friction_dynamic``,
  object-pusher ``objects.pusher.friction_dynamic`` (default 0: the planar model's
  frictionless pusher), object-object the larger of the two objects' coefficients (MuJoCo's own
  rule for geoms without a pair);
* ``gravity_mps2`` as the gravity vector;
* the objects' joint set (``joints``, :data:`JOINTS`): a free joint each, or, for boxes on a
  horizontal support (:func:`planar_joints_fit`, the ``auto`` default there), the planar joint
  set - slide x, y, z and a hinge about z, one footprint contact with torsional friction under
  the CoM (``com_m`` x, y: the friction centre, as in the planar model and the generator; a
  fitted ``com_offset`` moves it with the CoM, :func:`write_body`) and a 10 ms friction
  reference (:data:`PLANAR_SETTINGS`). The ``mujoco`` engine and
  ``robogs export mjcf`` both take this choice from here, so an exported scene is the model
  that was fitted (the reasons are in ``robogs.physics.engines.mujoco_engine``, "Planar joint
  set"). Planar bodies sit at the world origin (qpos is the pose ``T_world_object``: x, y, z m,
  yaw rad) and start from the ``<keyframe>`` ``start`` (``mj_resetDataKeyframe``); free bodies
  start at their ``pos``/``quat`` (qpos0), which the same keyframe repeats.

MuJoCo has one Coulomb coefficient per contact: ``friction_dynamic`` is used, also for
sticking (the planar model's ``friction_static`` has no counterpart). Restitution, damping and
effects are not mapped by :func:`scene_mjcf`; :attr:`MjcfScene.unmapped` lists the keys that
were present. Fitted effects with an MJCF-native form are applied to the *compiled* model by
:data:`NATIVE_EFFECTS` (``table_tilt`` -> gravity, ``viscous_damping`` -> DOF damping), the one
map both the ``mujoco`` engine and ``robogs export mjcf`` use (the exporter writes the changed
fields, :data:`NATIVE_FIELDS`, back into the document); these functions take an ``MjModel`` but
need no MuJoCo import here.
"""

from __future__ import annotations

import io
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from robogs.format.errors import FormatError, RobogsError
from robogs.format.frames import matrix_to_quat_np, quat_to_matrix_np

__all__ = [
    "BODY_EFFECTS",
    "BODY_FIELDS",
    "BOUNCE_SOLIMP",
    "BOUNCE_TIMECONST",
    "BodyValues",
    "JOINTS",
    "MAX_HULL_VERTICES",
    "OBJECT_PAIR_DAMPRATIO",
    "PLANAR_SETTINGS",
    "PUSHER_ACTUATORS",
    "PUSHER_ONSET_D0",
    "PUSHER_SOLREFFRICTION_STEPS",
    "ContactSettings",
    "EffectSlots",
    "NATIVE_EFFECTS",
    "NATIVE_FIELDS",
    "ballast_contact",
    "body_values",
    "inertia_tensor",
    "MjcfScene",
    "collision_hull",
    "com_feet",
    "footprint_points",
    "planar_joints_fit",
    "principal",
    "pusher_onset_solimp",
    "restitution_damping_ratio",
    "use_planar_joints",
    "scene_mjcf",
    "torsion_radius",
    "write_body",
]

MAX_HULL_VERTICES = 256
"""A collision hull with more vertices is decimated to this many (MuJoCo's convex collision
cost grows with the vertex count; a scanned mesh has 10^4-10^6)."""

PUSHER_ACTUATORS = ("x", "y", "z", "yaw")
"""Pusher joints, in qpos order; each has a position servo ``pusher_<j>`` (ctrl: target
position, m or rad) followed, after all four, by a velocity servo ``pusher_v<j>`` (ctrl: target
velocity, m/s or rad/s)."""

JOINTS = ("auto", "free", "planar")
"""Joint sets of the objects: ``free`` (6 DOF), ``planar`` (slide x, y, z and a hinge about
z: no roll or pitch), ``auto`` (planar where :func:`planar_joints_fit` says the scene allows)."""

PLANAR_JOINTS = (
    ("", "slide", "1 0 0"),
    ("_y", "slide", "0 1 0"),
    ("_z", "slide", "0 0 1"),
    ("_yaw", "hinge", "0 0 1"),
)
"""(name suffix, type, axis) of an object's planar joints, in qpos order (the first is named
as the object, like its free joint)."""

PUSHER_SOLREFFRICTION_STEPS = 2.0
"""Friction time constant of the object-pusher pairs in timesteps (damping ratio 1). A soft
friction reference lets a slowly sliding contact creep below the Coulomb limit: against the
quasi-static pusher-friction generator (:mod:`robogs.synth.scenarios.pusher_friction`, mu_p
0.3, 4 pushes turning 28-43 deg) the box turned 2.2-3.2 deg RMS short with the pairs' 20 ms
(planar joint set), 1.1-1.7 deg at 4 ms and 1.0-1.5 deg at 2 ms (positions 1-2.7 mm ->
0.1-0.4 mm); the table pairs keep theirs (2-4 ms there made it worse, 1.6-2.7 deg)."""

OBJECT_PAIR_DAMPRATIO = 2.0
"""Damping ratio of object-object contact pairs (time constant as ``solref``). A critically
damped soft contact gives back part of its compression: box A driven into box B at 0.45 m/s
launched B at 0.51 m/s, 13 % above A, and B slid 3.6 mm past the plastic-impact generator
(:mod:`robogs.synth.scenarios.two_objects`, restitution 0); at ratio 2 B leaves at 0.485 m/s
and both boxes end within 0.8 mm at 0.25-0.45 m/s (ratio 4: A 2.8 mm short; 1 with a 2 ms
time constant: B 2 mm long)."""

_NAME = re.compile(r"[^A-Za-z0-9_.-]+")


@dataclass(frozen=True)
class ContactSettings:
    """Solver and contact settings of the scene; the reasons are in the module docstring of
    ``robogs.physics.engines.mujoco_engine``.

    Attributes:
        timestep: s.
        cone: ``"elliptic"`` or ``"pyramidal"``.
        impratio: frictional-to-normal impedance ratio (elliptic cones).
        solref: (time constant s, damping ratio) of every contact pair.
        solreffriction: (time constant s, damping ratio) of the pairs' friction dimensions
            (elliptic cones; ``(0, 0)``: as ``solref``).
        solimp: (d0, dwidth, width m, midpoint, power) of every contact pair.
        noslip_iterations: post-solve iterations removing residual slip (0: off).
        iterations, tolerance: main solver (Newton) limits.
        integrator: MuJoCo integrator (``"Euler"``: semi-implicit, actuator forces explicit).
        pusher_mass: kg of the pusher body (and kg m^2 x 0.01 of its yaw inertia).
        footprint_grid: a box rests on the support through an n x n grid of small spheres
            on its bottom face (0: through the box geom itself); see :func:`footprint_points`.
        footprint_spread: factor on the footprint points' distances from the face centre.
        capsule_ends: a capsule pusher collides through its two end spheres (``pusher`` at
            -y, ``pusher_end`` at +y), as the planar model and the scenario generator model it;
            a full capsule makes one or two contacts with a parallel face depending on
            micrometres, which turned centred pushes by a degree at random.
        footprint_torsion: footprint contacts get torsional friction (``condim 4``) of radius
            :func:`torsion_radius`, so that a turning box meets the friction torque of the
            uniformly loaded face with the footprint drawn in (see that function).
        servo_velocity_gain, servo_position_gain: the pusher servos' gains in units of the
            pusher's mass and the timestep: ``kv = gain_v * m / dt``, ``kp = gain_p * m / dt^2``
            (``gain_v = 1`` is dead-beat velocity tracking with explicit forces).
        z_ballast: planar joint set only: the z slide of an object of mass m carries ``k m`` of
            added inertia (``armature``) and a constant force ``k m g_z`` (a bias-only actuator
            ``<obj>_ballast``), so it falls at g with a (1 + k)-fold weight on the support, whose
            friction coefficients are divided by (1 + k): the friction forces are Coulomb's, the
            soft cone's slip-normal coupling lifts the box (1 + k) times less (see
            :func:`ballast_contact` for the impedances). 0: off.
        pusher_dampratio: damping ratio of the object-pusher pairs' ``solref`` (time constant
            as ``solref``): above 1 the pusher's strike is plastic, as in the planar model.
        pusher_timeconst_steps: time constant of the object-pusher pairs' ``solref`` in
            timesteps (0: ``solref``'s); sets how fast the strike's compression relaxes.
        pusher_onset_steps: ``c`` of the object-pusher pairs' impedance ramp (0: off, the pairs
            take ``solimp``): their ``solimp`` becomes :func:`pusher_onset_solimp`, rising
            linearly from MuJoCo's least impedance at contact to ``solimp``'s dmax over
            ``c * pusher_speed * timestep`` of penetration, so the strike's force grows with
            penetration instead of starting at 0.95 of its full value on whichever step the
            onset falls (see ``robogs.physics.engines.mujoco_engine``, "Pusher onset ramp").
        pusher_speed: m/s, the drive's fastest pusher speed, which sizes the ramp (set by the
            engine from the drive it rolls out; 0 with ``pusher_onset_steps > 0`` is an error).
    """

    timestep: float = 1e-3
    cone: str = "elliptic"
    impratio: float = 10.0
    solref: tuple[float, float] = (0.004, 1.0)
    solreffriction: tuple[float, float] = (0.0, 0.0)
    solimp: tuple[float, float, float, float, float] = (0.95, 0.99, 0.001, 0.5, 2.0)
    noslip_iterations: int = 0
    iterations: int = 50
    tolerance: float = 1e-10
    integrator: str = "Euler"
    pusher_mass: float = 1000.0
    footprint_grid: int = 5
    footprint_spread: float = 1.0
    capsule_ends: bool = True
    footprint_torsion: bool = False
    servo_velocity_gain: float = 1.0
    servo_position_gain: float = 0.3
    z_ballast: float = 0.0
    pusher_dampratio: float = 1.0
    pusher_timeconst_steps: float = 0.0
    pusher_onset_steps: float = 0.0
    pusher_speed: float = 0.0


PLANAR_SETTINGS = ContactSettings(
    footprint_grid=1,
    footprint_torsion=True,
    solreffriction=(0.01, 1.0),
    z_ballast=9.0,
    pusher_dampratio=1.2,
    pusher_timeconst_steps=5.0,
)
"""Contact settings of the planar joint set (see ``robogs.physics.engines.mujoco_engine``,
"Planar joint set", "Strike events", "Strike launch", "Friction bias of centred pushes" and
"Flush strikes"). On the fitting path strikes faster than 5 cm/s are events since stop 55, so the
pusher pair below sets the slower approaches and the steady push there, and every contact of a
plain MuJoCo model (``robogs export mjcf``).
The pusher pair is 5 steps x damping ratio 1.2 (``pusher_timeconst_steps``,
``pusher_dampratio``; slow mode ``dmax tc zeta (zeta + sqrt(zeta^2 - 1))`` = 11 ms): a struck
box rides the pusher within 0.16 % of its speed at 0.55 m/s, and a fast flush strike of the
capsule's two ends ends flush whatever a sub-degree start tilt (stop 53). The pair before, 2.5
steps x 1.7 (13 ms, stops 49-52), struck within 0.11 % but let a 0.1 deg tilt decide whether a
box with an off-centre CoM ended flush or spun 2-12 deg away at 0.425-0.55 m/s, which made the
CoM offset's fits on design A jump between the two (``tests/physics/test_mujoco_flush_strike.py``).
The trade: the softer pair's strike is less plastic (a struck box peaks at 1.07-1.09x the
pusher's speed at 0.3-0.55 m/s, against 1.02-1.04x; it stops within 0.06 mm of the rigid closed
form, against 0.15 mm). Stiffer still (2 steps x 1.5, MuJoCo's shortest) the capsule ends'
onsets fall on whole steps and the CoM offset's objective is rough; the slower 4 ms x 2 of
before stop 49 (slow mode 30 ms) let a struck box ride 0.86 % fast, which the fit read as
more friction. Measured in ``bench/RESULTS.md``, "issue 16 (h42)", "(lead, stop 49)" and
"(lead, stop 53)"."""


PUSHER_ONSET_D0 = 1e-4
"""Impedance of the object-pusher pairs at zero penetration with the onset ramp on
(``ContactSettings.pusher_onset_steps``): MuJoCo's least (``mjMINIMP``)."""


def pusher_onset_solimp(settings: ContactSettings) -> tuple[float, float, float, float, float]:
    """``solimp`` of the object-pusher pairs (before :func:`ballast_contact`): ``settings.solimp``
    with the ramp off, else a linear ramp (power 1) from :data:`PUSHER_ONSET_D0` at contact to
    ``solimp``'s dmax at ``width = pusher_onset_steps * pusher_speed * timestep`` [m].

    Raises:
        FormatError: the ramp is on but ``pusher_speed`` is not a positive number.
    """
    lo, hi, width, mid, power = (float(v) for v in settings.solimp)
    c = float(settings.pusher_onset_steps)
    if c <= 0:
        return lo, hi, width, mid, power
    v = float(settings.pusher_speed)
    if not (math.isfinite(v) and v > 0):
        raise FormatError(
            f"the pusher onset ramp needs the drive's fastest pusher speed, got {v!r} m/s",
            where="ContactSettings.pusher_speed",
            hint="set pusher_speed (m/s) from the drive, or pusher_onset_steps=0",
        )
    return PUSHER_ONSET_D0, hi, c * v * float(settings.timestep), mid, 1.0


def ballast_contact(
    solref: Sequence[float],
    solimp: Sequence[float],
    k: float,
    vertical: bool,
    solreffriction: Sequence[float] = (0.0, 0.0),
) -> tuple[tuple[float, float], tuple[float, ...], tuple[float, float]]:
    """``(solref, solimp, solreffriction)`` of a contact pair of a ballasted body
    (``ContactSettings.z_ballast`` ``k``) that give the contact the dynamics of the same pair on
    the unballasted body (positive ``solref`` only; ``k <= 0`` returns them unchanged).

    MuJoCo regularises a contact row with ``R = (1 - d) / d * A0``, ``A0`` the bodies'
    ``body_invweight0``: the mean of the translational diagonal of ``J M^-1 J^T`` over x, y, z
    (MuJoCo's ``engine_setconst.c``), so with the ballast ``A0 = (2 + 1/(1+k)) / (3 m)``, while
    the true inverse mass is ``1 / ((1+k) m)`` along z (a support contact, ``vertical``) and
    ``1/m`` horizontally (pusher and object-object contacts). The row's acceleration is
    ``a = d_eff a_ref + (1 - d_eff) a_0`` with ``d_eff = A / (A + R)`` (MuJoCo documentation,
    "Computation", soft constraints). So ``(1 - d) / d`` of dmin and dmax is scaled by
    ``A / A0`` (``d_eff`` as before: rest penetration unchanged), and the time constant and
    damping ratio by ``q = dmax / dmax'`` and ``1 / sqrt(q)``: ``a_ref``'s damping
    ``2 / (dmax timeconst)`` and stiffness ``imp / (dmax timeconst dampratio)^2`` then give
    ``d_eff a_ref`` of the unballasted pair (exactly for a constant impedance, to first order
    in the impedance ramp otherwise). The friction time constant is scaled by ``q`` too."""
    lo, hi, *rest = (float(v) for v in solimp)
    tc, zeta = (float(v) for v in solref)
    tf, zf = (float(v) for v in solreffriction)
    if k <= 0:
        return (tc, zeta), (lo, hi, *rest), (tf, zf)
    a0 = (2.0 + 1.0 / (1.0 + k)) / 3.0
    f = (1.0 / (1.0 + k) if vertical else 1.0) / a0

    def d(x: float) -> float:
        return 1.0 / (1.0 + f * (1.0 - x) / x)

    q = hi / d(hi)
    return (tc * q, zeta / math.sqrt(q)), (d(lo), d(hi), *rest), (tf * q, zf)


@dataclass(frozen=True)
class EffectSlots:
    """Where an effect's object lives in a compiled ``MjModel``: ``body`` its body id, ``dof``
    the first DOF address of its joints (free joint or planar joint set: x, y, z first) and
    ``ballast`` its z ballast factor k (:attr:`ContactSettings.z_ballast`; 0: none); for
    :func:`write_body` also ``table_pairs`` (compiled rows of its support pairs),
    ``table_torsion`` (their torsional friction radii [m], 0: none), ``nominal_mass`` [kg],
    ``nominal_inertia`` [3] kg m^2 and ``nominal_iquat`` (w, x, y, z) (the compiled body's
    principal moments and their rotation), ``tilt_inertia_scale`` (factor on the roll and pitch
    inertia), ``ballast_actuator`` (id of its ``<obj>_ballast`` actuator, -1: none) and
    ``com_feet`` (footprint geoms that follow the CoM: ``(geom id, x, y)`` with x, y [m] the
    geom's place relative to the CoM; the planar joint set's footprint, see
    :func:`com_feet`). ``robogs.physics.engines.mujoco_effects.ObjectSlots`` has the same
    attributes."""

    body: int
    dof: int
    ballast: float = 0.0
    table_pairs: tuple[int, ...] = ()
    table_torsion: tuple[float, ...] = ()
    nominal_mass: float = 0.0
    nominal_inertia: tuple[float, float, float] = (0.0, 0.0, 0.0)
    nominal_iquat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    tilt_inertia_scale: float = 1.0
    ballast_actuator: int = -1
    com_feet: tuple[tuple[int, float, float], ...] = ()


def _native_tilt(model: Any, th: Mapping[str, float], slots: Any) -> None:
    """``table_tilt``: gravity ``(g_x, g_y, -g)`` (the pusher is gravity compensated)."""
    model.opt.gravity[0] += float(th["g_x"])
    model.opt.gravity[1] += float(th["g_y"])


def _native_viscous(model: Any, th: Mapping[str, float], slots: Any) -> None:
    """``viscous_damping``: DOF damping ``c m`` of the x, y, z DOFs (``c m (1 + k)`` on a
    ballasted z, whose inertia is ``(1 + k) m``: the same decay rate ``c``)."""
    c = float(th["c"]) * float(model.body_mass[slots.body])
    z = np.array([1.0, 1.0, 1.0 + float(slots.ballast)])
    model.dof_damping[slots.dof : slots.dof + 3] += c * z


NATIVE_EFFECTS: dict[str, Any] = {
    "table_tilt": _native_tilt,
    "viscous_damping": _native_viscous,
}
"""Catalogue effects with an MJCF-native form -> ``f(model, params, slots)``, which writes the
fitted ``params`` (name -> value) into a compiled ``MjModel`` (``slots``: :class:`EffectSlots`).
The ``mujoco`` engine applies them to each parameter set's model
(``robogs.physics.engines.mujoco_effects.NATIVE`` is this table) and ``robogs export mjcf``
to the exported scene's, writing back the fields of :data:`NATIVE_FIELDS`: one mapping."""

NATIVE_FIELDS = ("opt.gravity", "dof_damping")
"""The ``MjModel`` fields that :data:`NATIVE_EFFECTS` change (the exporter writes these back as
``<option gravity>`` and per-joint ``damping``; it refuses to export a change of any other)."""


@dataclass(frozen=True)
class BodyValues:
    """One object's body as the rigid-object model has it (plain floats, SI): ``mass`` [kg],
    ``inertia_z`` [kg m^2] (the body-z moment about the CoM), ``com`` (x, y) [m] in the object
    frame, ``mu_d`` (object-table Coulomb coefficient), ``restitution`` (object-table, 0-1) and
    ``damping`` [1/s] (linear damping ``a = -c v``). ``robogs.physics.model.Body`` holds the
    same quantities as [M, 1] tensors, one row per parameter set."""

    mass: float
    inertia_z: float
    com: tuple[float, float]
    mu_d: float
    restitution: float
    damping: float


def body_values(entry: Mapping[str, Any], where: str = "objects") -> BodyValues:
    """The nominal :class:`BodyValues` of a rigid object's physics.json entry (``mass_kg``,
    ``inertia_kgm2``'s zz or the ``size_m`` box formula, ``com_m``, ``friction_dynamic``
    (default 0.4), ``restitution``, ``damping_linear``), as ``robogs.physics.scene`` reads them.

    Raises:
        FormatError: a value is missing or malformed (the key is named).
    """
    mass = _number(entry, "mass_kg", 0.0, where)
    com = _floats(entry, "com_m", 3, where) if "com_m" in entry else [0.0, 0.0, 0.0]
    return BodyValues(
        mass=mass,
        inertia_z=float(_inertia_tensor(entry, mass, where)[2, 2]),
        com=(com[0], com[1]),
        mu_d=_number(entry, "friction_dynamic", 0.4, where),
        restitution=_number(entry, "restitution", 0.0, where),
        damping=_number(entry, "damping_linear", 0.0, where),
    )


def _body_mass(body: BodyValues, th: Mapping[str, float]) -> BodyValues:
    """``mass``: ``m (1 + dm)``, the yaw moment scaled with it (uniform density)."""
    s = 1.0 + float(th.get("dm", 0.0))
    return replace(body, mass=body.mass * s, inertia_z=body.inertia_z * s)


def _body_com(body: BodyValues, th: Mapping[str, float]) -> BodyValues:
    """``com_offset``: the CoM moved by ``(dx, dy)`` in the object frame."""
    return replace(
        body, com=(body.com[0] + float(th.get("dx", 0.0)), body.com[1] + float(th.get("dy", 0.0)))
    )


def _body_restitution(body: BodyValues, th: Mapping[str, float]) -> BodyValues:
    """``restitution``: ``e + e_delta``, clamped to 0-0.98."""
    return replace(
        body, restitution=min(max(body.restitution + float(th.get("e_delta", 0.0)), 0.0), 0.98)
    )


BODY_EFFECTS: dict[str, Any] = {
    "mass": _body_mass,
    "com_offset": _body_com,
    "restitution": _body_restitution,
}
"""Catalogue effects that change an object's body -> ``f(body, params) -> body``
(:class:`BodyValues`; a missing parameter is the effect's zero, as the engine starts it; the
catalogue's ``body`` hooks in ``robogs.physics.catalogue`` do the same
on [M, 1] tensors, and ``tests/converters/test_mjcf_export_body_effects.py`` checks that the
exported model equals the engine's). :func:`write_body` writes the body into a compiled model:
the ``mujoco`` engine for every parameter set, ``robogs export mjcf`` for the exported scene."""

BODY_FIELDS = (
    "body_mass",
    "body_inertia",
    "body_iquat",
    "body_ipos",
    "geom_pos",
    "pair_friction",
    "pair_solref",
    "pair_solimp",
    "dof_damping",
    "dof_armature",
    "actuator_biasprm",
)
"""The ``MjModel`` fields that :func:`write_body` changes (the exporter writes them back as the
body's ``<inertial>``, the footprint geoms' ``pos``, the support pairs'
``friction``/``solref``/``solimp``, the slides'
``damping``/``armature`` and the ballast actuator's ``biasprm``)."""

BOUNCE_TIMECONST = 0.02
"""Contact time constant [s] of an underdamped (bouncing) object-table pair (the export and free
joints; the fitting engine bounces a flat box by impact events instead): with the 4 ms of
the plastic contacts, damping ratios below about 0.2 (e > 0.5) made the semi-implicit Euler
contact unstable (a 5 cm drop at e = 0.7 rose 11 cm); at 20 ms the bounce follows the
closed-form ratio within 0.03 (drops of 2 and 5 cm, e = 0.3-0.7)."""

BOUNCE_SOLIMP = (0.9, 0.9, 0.001, 0.5, 2.0)
"""solimp of a bouncing pair: a constant impedance, so the contact is the linear spring-damper
whose damping ratio the closed form assumes (the plastic pairs' impedance rises from 0.95 to
0.99 within 1 mm, which made the bounce depend on the drop height)."""


def restitution_damping_ratio(e: float) -> float:
    """Damping ratio of a linear spring-damper whose impact restitution is ``e`` (0 -> 1):
    ``zeta = -ln e / sqrt(pi^2 + ln^2 e)`` (e clamped to 0-0.98; 1 for e = 0)."""
    e = min(max(float(e), 0.0), 0.98)
    if e <= 1e-6:
        return 1.0
    le = math.log(e)
    return -le / math.sqrt(math.pi**2 + le * le)


def inertia_tensor(moments: Sequence[float], iquat: Sequence[float] | None) -> np.ndarray:
    """[3, 3] inertia tensor in the body frame [kg m^2] of MuJoCo's principal ``moments`` [3]
    rotated by ``iquat`` (w, x, y, z; None: identity): ``R diag(moments) R^T``."""
    r = quat_to_matrix_np(np.array([1.0, 0, 0, 0]) if iquat is None else np.asarray(iquat, float))
    return r @ np.diag(np.asarray(moments, float)) @ r.T


def principal(tensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(principal moments [3], ``iquat`` (w, x, y, z)) of a symmetric [3, 3] inertia tensor:
    the body_inertia / body_iquat pair MuJoCo stores (moments ascending, a proper rotation)."""
    vals, vecs = np.linalg.eigh(0.5 * (tensor + tensor.T))
    if np.linalg.det(vecs) < 0:
        vecs[:, 0] *= -1.0
    return vals, matrix_to_quat_np(vecs)


def write_body(
    model: Any, body: BodyValues, slots: Any, *, timeconst: float, bounce_solref: bool = True
) -> None:
    """Write ``body`` into a compiled ``MjModel`` in place (``slots``: :class:`EffectSlots`).

    * ``body_mass``; the inertia tensor of the nominal body (``slots.nominal_*``) scaled with
      the mass, its body-z moment set to ``inertia_z``, roll and pitch scaled by
      ``slots.tilt_inertia_scale`` (congruence ``diag(k, k, 1)^1/2``, positive definite) and
      re-diagonalised into ``body_inertia`` / ``body_iquat`` (:func:`principal`);
    * ``body_ipos`` (x, y) = ``com``, and the footprint geoms of ``slots.com_feet`` (the planar
      joint set's central footprint) at ``com`` plus their offset: the support's friction
      centre is the CoM, as in the planar model and the generator (a footprint left at the
      face centre does not feel the CoM: a box with its CoM 8 mm off the line of a central
      push turned 0.12 deg instead of 10.2, ``tests/physics/test_mujoco_com_offset.py``);
    * the support pairs' friction ``mu_d / (1 + k)`` (torsional ``* radius``), and for
      ``restitution > 0`` their ``solref`` ``(max(timeconst, BOUNCE_TIMECONST), zeta)`` with
      :func:`restitution_damping_ratio` and :data:`BOUNCE_SOLIMP` (corrected by
      :func:`ballast_contact`); ``timeconst`` [s] is the pairs' solref time constant. With
      ``bounce_solref=False`` the pairs stay plastic whatever the restitution: the fitting
      engine bounces a flat box by impact events instead (``robogs.physics.engines.
      mujoco_fit``, "Restitution"), because the soft bounce lasts 10-14 ms and delays the
      rebound; the export keeps the solref, the bounce plain MuJoCo can play;
    * ``dof_damping`` of the x, y, z DOFs ``damping m`` (``(1 + k)`` on z); with a z ballast
      ``k`` (``slots.ballast``) the z armature ``k m`` and the ballast force ``k m g_z``.
    """
    b = slots.body
    mass = float(body.mass)
    # the tensor in the body frame: scaled with the mass, the yaw moment set, roll and pitch
    # scaled (congruence diag(k, k, 1)^1/2 keeps it positive definite), re-diagonalised
    tensor = inertia_tensor(slots.nominal_inertia, slots.nominal_iquat)
    tensor = tensor * (mass / slots.nominal_mass)
    tensor[2, 2] = float(body.inertia_z)
    k = np.sqrt([slots.tilt_inertia_scale, slots.tilt_inertia_scale, 1.0])
    tensor = tensor * np.outer(k, k)
    model.body_mass[b] = mass
    model.body_inertia[b], model.body_iquat[b] = principal(tensor)
    model.body_ipos[b, :2] = body.com
    for g, ox, oy in slots.com_feet or ():
        model.geom_pos[g, 0] = body.com[0] + ox
        model.geom_pos[g, 1] = body.com[1] + oy
    kb = float(slots.ballast)
    mu = max(float(body.mu_d), 1e-5) / (1.0 + kb)
    zeta = restitution_damping_ratio(body.restitution)
    rho = slots.table_torsion or [0.0] * len(slots.table_pairs)
    for row, r in zip(slots.table_pairs, rho, strict=True):
        model.pair_friction[row, :2] = mu
        if r > 0:
            model.pair_friction[row, 2] = mu * r
        if zeta < 1.0 and bounce_solref:
            sr, si, _ = ballast_contact(
                (max(timeconst, BOUNCE_TIMECONST), zeta), BOUNCE_SOLIMP, kb, vertical=True
            )
            model.pair_solref[row], model.pair_solimp[row] = sr, si
    z = np.array([1.0, 1.0, 1.0 + kb])  # the z DOF's inertia is (1 + k) m
    model.dof_damping[slots.dof : slots.dof + 3] = float(body.damping) * mass * z
    if kb > 0:
        model.dof_armature[slots.dof + 2] = kb * mass
        model.actuator_biasprm[slots.ballast_actuator, 0] = kb * mass * model.opt.gravity[2]


def com_feet(model: Any, scene: MjcfScene, name: str) -> tuple[tuple[int, float, float], ...]:
    """``(geom id, x, y)`` of object ``name``'s footprint spheres in the compiled ``model``,
    x, y [m] relative to its compiled CoM (``body_ipos``), on the planar joint set
    (:attr:`EffectSlots.com_feet`: :func:`write_body` keeps them there when the CoM moves);
    empty on free joints, whose footprint's normal loads follow the CoM through roll and
    pitch. ``model`` is an ``MjModel`` (no MuJoCo import here)."""
    if not scene.planar:
        return ()
    c = model.body_ipos[model.body(name).id]
    out = []
    for foot in scene.feet.get(name, []):
        g = int(model.geom(foot).id)
        out.append((g, float(model.geom_pos[g, 0] - c[0]), float(model.geom_pos[g, 1] - c[1])))
    return tuple(out)


def planar_joints_fit(
    physics: Mapping[str, Any], meshes: Mapping[str, Any] | None = None
) -> tuple[bool, str]:
    """Whether the objects can move on the planar joint set: every rigid object is a box
    (``size_m``, no mesh) on a horizontal support, as in the planar model. Meshes (their hull
    rests on whichever vertices touch) and tilted support planes keep the free joint.

    Returns:
        ``(fits, why)``: the verdict and one line of reason.
    """
    objects = physics.get("objects") or {}
    meshes = meshes or {}
    normal = np.asarray((objects.get("table") or {}).get("normal", [0.0, 0.0, 1.0]), float)
    if normal.shape != (3,) or np.linalg.norm(normal[:2]) > 1e-9 * np.linalg.norm(normal):
        return False, "the support plane is not horizontal"
    if normal[2] <= 0:
        return False, "the support plane faces down"
    for name, entry in objects.items():
        if name in ("table", "pusher") or not isinstance(entry, Mapping):
            continue
        if entry.get("equation") == "rigid" and (name in meshes or "size_m" not in entry):
            return False, f"object {name!r} is a mesh (its hull may rest on any vertices)"
    return True, "boxes on a horizontal plane"


def use_planar_joints(
    physics: Mapping[str, Any],
    meshes: Mapping[str, Any],
    joints: str,
    error: type[RobogsError] = FormatError,
) -> bool:
    """Resolve ``joints`` (one of :data:`JOINTS`) for this scene: True for the planar joint set.

    Raises:
        error: an unknown joint set, or ``planar`` for a scene it cannot represent.
    """
    if joints not in JOINTS:
        raise error(f"joints {joints!r} is not one of {', '.join(JOINTS)}", where="joints")
    fits, why = planar_joints_fit(physics, meshes)
    if joints == "planar" and not fits:
        raise error(
            f"the planar joint set cannot represent this scene: {why}",
            path="physics.json",
            where="joints",
            hint="use joints='free' (or 'auto')",
        )
    return joints == "planar" or (joints == "auto" and fits)


@dataclass
class MjcfScene:
    """An MJCF document and what a caller needs to drive it.

    Attributes:
        xml: the document (UTF-8 text).
        assets: mesh file name (as referenced in ``xml``) -> binary STL bytes.
        objects: free bodies (= their free joints and geoms), in qpos order.
        pusher: the pusher body name, None without a pusher.
        pairs: ``(geom1, geom2)`` of every contact pair, in ``<contact>`` order.
        notes: substitutions made (hulled or decimated meshes), one line each.
        unmapped: physics.json keys present but not represented in MuJoCo.
        table_pairs: object name -> rows of its contact pairs with the support (footprint
            spheres and the box geom itself).
        feet: object name -> its footprint sphere geoms.
        pair_torsion: per contact pair (``pairs`` order), the torsional friction radius [m]
            (the pair's third friction coefficient is ``mu * radius``; 0: condim 3).
        torsion: object name -> torsional friction radius [m] of its footprint (0: none).
        planar: the objects are on the planar joint set (else free joints).
        settings: the contact settings the document was built with.
        ballast: the z ballast factor k of every object (``ContactSettings.z_ballast`` on the
            planar joint set, else 0): support-pair friction coefficients in the document are
            the physics.json ones divided by (1 + k).
    """

    xml: str
    assets: dict[str, bytes] = field(default_factory=dict)
    objects: list[str] = field(default_factory=list)
    pusher: str | None = None
    pairs: list[tuple[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    unmapped: list[str] = field(default_factory=list)
    table_pairs: dict[str, list[int]] = field(default_factory=dict)
    feet: dict[str, list[str]] = field(default_factory=dict)
    pair_torsion: list[float] = field(default_factory=list)
    torsion: dict[str, float] = field(default_factory=dict)
    planar: bool = False
    settings: ContactSettings = field(default_factory=ContactSettings)
    ballast: float = 0.0


def _f(v: float) -> str:
    return repr(float(v))


def _vec(vs: Sequence[float]) -> str:
    return " ".join(_f(v) for v in vs)


def _floats(entry: Mapping[str, Any], key: str, n: int, where: str) -> list[float]:
    val = entry.get(key)
    try:
        out = [float(v) for v in val]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        out = []
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise FormatError(
            f"{key} must be {n} finite numbers, got {val!r}",
            path="physics.json",
            where=f"{where}/{key}",
        )
    return out


def _number(entry: Mapping[str, Any], key: str, default: float, where: str) -> float:
    val = entry.get(key, default)
    try:
        out = float(val)
    except (TypeError, ValueError):
        out = math.nan
    if not math.isfinite(out) or out < 0:
        raise FormatError(
            f"{key} must be a finite number >= 0, got {val!r}",
            path="physics.json",
            where=f"{where}/{key}",
        )
    return out


def collision_hull(mesh: Any, name: str) -> tuple[Any, str | None]:
    """The convex collision hull MuJoCo gets for an object mesh, and a note if it differs.

    The hull (qhull, via trimesh) is what MuJoCo collides anyway. A hull with more than
    :data:`MAX_HULL_VERTICES` vertices is decimated by farthest-point sampling of its vertices
    (greedy k-centre, Gonzalez 1985) and hulled again.

    Args:
        mesh: a ``trimesh.Trimesh`` (object frame, metres).
        name: the object, for messages.

    Returns:
        ``(hull, note)``: the hull mesh and one line saying what was substituted (None when the
        mesh was already a closed convex mesh within the vertex budget).

    Raises:
        FormatError: the mesh has no volume (fewer than 4 non-coplanar vertices).
    """
    import trimesh

    verts = np.asarray(mesh.vertices, dtype=np.float64)
    try:
        hull = trimesh.convex.convex_hull(verts)
    except Exception as exc:  # qhull raises its own types on flat or tiny inputs
        raise FormatError(
            f"mesh of {name!r} has no convex hull ({type(exc).__name__})",
            where=f"assets/{name}/mesh",
            hint="give the object a box size (size_m) or a closed mesh",
        ) from None
    if hull.volume <= 0 or len(hull.vertices) < 4:
        raise FormatError(
            f"mesh of {name!r} is flat (hull volume {hull.volume:.3g} m^3)",
            where=f"assets/{name}/mesh",
            hint="give the object a box size (size_m) or a closed mesh",
        )
    reasons = []
    try:  # STL and process=False loads keep one vertex per corner: weld them to judge closure
        welded = mesh.copy()
        welded.merge_vertices()
    except Exception:  # not a trimesh: judge it as given
        welded = mesh
    watertight = bool(getattr(welded, "is_watertight", False))
    if not watertight:
        reasons.append("not watertight")
    elif abs(float(welded.volume)) < 0.99 * hull.volume:
        reasons.append(f"non-convex ({abs(float(welded.volume)) / hull.volume:.0%} of its hull)")
    n_hull = len(hull.vertices)
    if n_hull > MAX_HULL_VERTICES:
        hv = np.asarray(hull.vertices)
        pick = [int(np.argmax(np.linalg.norm(hv - hv.mean(0), axis=1)))]
        dist = np.linalg.norm(hv - hv[pick[0]], axis=1)
        while len(pick) < MAX_HULL_VERTICES:
            i = int(np.argmax(dist))
            pick.append(i)
            dist = np.minimum(dist, np.linalg.norm(hv - hv[i], axis=1))
        hull = trimesh.convex.convex_hull(hv[pick])
        reasons.append(f"hull of {n_hull} vertices decimated to {len(hull.vertices)}")
    if not reasons and len(verts) <= MAX_HULL_VERTICES:
        return hull, None
    note = (
        f"mesh of {name!r} ({len(verts)} vertices, {', '.join(reasons) or 'detailed'}) replaced "
        f"by its convex hull ({len(hull.vertices)} vertices, {hull.volume * 1e6:.1f} cm^3) for "
        "collision; mass and inertia stay those of physics.json"
    )
    return hull, note


def _quat_from_z(normal: np.ndarray) -> np.ndarray:
    """A (w, x, y, z) rotation taking +z to the unit vector ``normal``."""
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, normal))
    if c < -1.0 + 1e-12:
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(z, normal)
    q = np.array([1.0 + c, *axis])
    return q / np.linalg.norm(q)


def _inertial(body: ET.Element, entry: Mapping[str, Any], where: str) -> float:
    mass = _number(entry, "mass_kg", 0.0, where)
    J = _inertia_tensor(entry, mass, where)
    com = _floats(entry, "com_m", 3, where) if "com_m" in entry else [0.0, 0.0, 0.0]
    full = [J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]]
    ET.SubElement(body, "inertial", pos=_vec(com), mass=_f(mass), fullinertia=_vec(full))
    return mass


def _inertia_tensor(entry: Mapping[str, Any], mass: float, where: str) -> np.ndarray:
    """[3, 3] inertia about the CoM [kg m^2]: ``inertia_kgm2``, else the ``size_m`` box's."""
    if mass <= 0:
        raise FormatError(
            "a rigid object needs mass_kg > 0", path="physics.json", where=f"{where}/mass_kg"
        )
    if "inertia_kgm2" in entry:
        rows = entry["inertia_kgm2"]
        J = np.array([_floats({"r": r}, "r", 3, f"{where}/inertia_kgm2") for r in rows])
        if J.shape != (3, 3) or not np.allclose(J, J.T, atol=1e-12, rtol=1e-9):
            raise FormatError(
                "inertia_kgm2 must be a symmetric 3x3 matrix",
                path="physics.json",
                where=f"{where}/inertia_kgm2",
            )
    elif "size_m" in entry:
        sx, sy, sz = _floats(entry, "size_m", 3, where)
        J = np.diag([sy**2 + sz**2, sx**2 + sz**2, sx**2 + sy**2]) * mass / 12.0
    else:
        raise FormatError(
            "a rigid object needs inertia_kgm2 (or size_m for the box formula)",
            path="physics.json",
            where=where,
        )
    return J


FOOTPRINT_RADIUS = 1e-3
"""Radius [m] of the footprint spheres (their lowest points lie on the box's bottom face)."""

FOOTPRINT_GAP = 2e-4
"""The bottom face of the collision box of a box with a footprint is raised by this much [m]: a
flat box rests on its footprint spheres alone, a tilted one (> ~0.4 deg) or one pressed in
deeper on the box geom. (A pair ``gap`` does not do this: MuJoCo 3.17 clamps a pair's
``margin - gap`` at 0, so the four box corners carried a fifth of the load and turned the box like
a corner-supported one.)"""


def footprint_points(size: Sequence[float], n: int, spread: float = 1.0) -> np.ndarray:
    """[n*n, 2] support points (object frame, m) of an ``sx x sy`` bottom face.

    Why: MuJoCo collides a box with a plane at its four corners, so a turning box meets
    friction at the corner distance ``hypot(sx, sy) / 2`` (0.050 m for 8 x 6 cm), while a
    uniformly loaded face (Coulomb friction with uniform pressure, the limit-surface model of
    Goyal, Ruina & Papadopoulos 1991, and the scenario generator) has the mean radius of the
    face (0.027 m): the corner box turned 5-7 deg less under off-centre pushes. Equal-load
    points on a midpoint grid, spread so their mean distance from the centre equals the
    face's, give the same maximum friction torque ``mu N r_mean``; the soft contacts share
    the load equally on a flat face. ``spread`` scales the points towards (< 1) the centre.
    """
    sx, sy = float(size[0]), float(size[1])
    u = (np.arange(n) + 0.5) / n - 0.5
    gx, gy = np.meshgrid(u * sx, u * sy, indexing="ij")
    m = 200
    v = (np.arange(m) + 0.5) / m - 0.5
    fx, fy = np.meshgrid(v * sx, v * sy, indexing="ij")
    r_face = float(np.hypot(fx, fy).mean())
    r_grid = float(np.hypot(gx, gy).mean())
    k = min(r_face / r_grid if r_grid > 0 else 1.0, 1.0 / (1.0 - 1.0 / n) if n > 1 else 1.0)
    return np.stack([gx.ravel(), gy.ravel()], -1) * k * float(spread)


def torsion_radius(size: Sequence[float], points: np.ndarray) -> float:
    """Torsional friction radius rho [m] of equal-load footprint ``points`` [P, 2] under an
    ``sx x sy`` face: the mean of ``sqrt(r_i^2 + rho^2)`` equals the face's mean radius.

    Why: MuJoCo's elliptic cone with ``condim 4`` bounds a contact's tangential force f and
    torsional torque tau by ``|f|^2/mu^2 + tau^2/(mu rho)^2 <= N^2``: the ellipsoidal limit
    surface of a patch of radius rho (Howe & Cutkosky 1996, "Practical force-motion models for
    sliding manipulation"). Points drawn towards the centre with this rho spin the box under the
    same maximum friction torque ``mu N r_mean`` as the uniformly loaded face, and the closer
    they are, the closer the summed limit surface is to one ellipsoid (the model of Lynch,
    Maekawa & Tanie 1992 and of the scenario generator); the outer points keep the box from
    tipping on them.
    """
    sx, sy = float(size[0]), float(size[1])
    m = 200
    v = (np.arange(m) + 0.5) / m - 0.5
    fx, fy = np.meshgrid(v * sx, v * sy, indexing="ij")
    r_face = float(np.hypot(fx, fy).mean())
    r = np.hypot(points[:, 0], points[:, 1])
    lo, hi = 0.0, r_face
    for _ in range(60):  # mean sqrt(r^2 + rho^2) is increasing in rho: bisection
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.sqrt(r * r + mid * mid).mean() < r_face else (lo, mid)
    return 0.5 * (lo + hi)


def _shape_geom(
    parent: ET.Element,
    name: str,
    entry: Mapping[str, Any],
    where: str,
    mesh: Any | None,
    scene: MjcfScene,
    asset: ET.Element,
    meshdir: str,
    footprint: int = 0,
    spread: float = 1.0,
    torsion: bool = False,
    centre: Sequence[float] = (0.0, 0.0),
) -> None:
    """A box of ``size_m`` (with ``footprint`` x ``footprint`` support spheres about
    ``centre`` (x, y) [m] of the bottom face) or the collision hull of ``mesh`` (object
    frame)."""
    attrs = {"name": name, "contype": "0", "conaffinity": "0", "group": "1"}
    if mesh is not None:
        hull, note = collision_hull(mesh, name)
        if note:
            scene.notes.append(note)
        fname = f"{_NAME.sub('_', name)}_hull.stl"
        buf = io.BytesIO()
        hull.export(buf, file_type="stl")
        scene.assets[fname] = buf.getvalue()
        ET.SubElement(
            asset, "mesh", name=f"{name}_hull", file=f"{meshdir}{fname}", inertia="convex"
        )
        ET.SubElement(parent, "geom", type="mesh", mesh=f"{name}_hull", **attrs)
    elif "size_m" in entry:
        half = [0.5 * s for s in _floats(entry, "size_m", 3, where)]
        if footprint > 0:  # the bottom face raised by FOOTPRINT_GAP (see there)
            hz = half[2] - 0.5 * FOOTPRINT_GAP
            lift = _vec([0.0, 0.0, 0.5 * FOOTPRINT_GAP])
            ET.SubElement(parent, "geom", type="box", size=_vec([*half[:2], hz]), pos=lift, **attrs)
        else:
            ET.SubElement(parent, "geom", type="box", size=_vec(half), **attrs)
        if footprint > 0:
            z = -half[2] + FOOTPRINT_RADIUS
            face = [2 * half[0], 2 * half[1]]
            pts = footprint_points(face, footprint, spread)
            scene.torsion[name] = torsion_radius(face, pts) if torsion else 0.0
            for i, (x, y) in enumerate(pts + np.asarray(centre, float)[:2]):
                ET.SubElement(
                    parent,
                    "geom",
                    type="sphere",
                    size=_f(FOOTPRINT_RADIUS),
                    pos=_vec([x, y, z]),
                    **{**attrs, "name": f"{name}_foot{i}", "group": "3"},
                )
                scene.feet.setdefault(name, []).append(f"{name}_foot{i}")
    else:
        raise FormatError(
            f"object {name!r} has neither size_m nor a mesh",
            path="physics.json",
            where=where,
            hint="give size_m (box edges, m) or an asset mesh",
        )


def _pusher(
    world: ET.Element, entry: Mapping[str, Any], settings: ContactSettings, actuator: ET.Element
) -> None:
    where = "objects/pusher"
    shape = str(entry.get("shape") or ("capsule" if entry.get("length_m") else "sphere"))
    r = _number(entry, "radius_m", 0.01, where)
    length = _number(entry, "length_m", 0.0, where)
    body = ET.SubElement(world, "body", name="pusher", gravcomp="1")
    m = settings.pusher_mass
    ET.SubElement(body, "inertial", pos="0 0 0", mass=_f(m), diaginertia=_vec([0.01 * m] * 3))
    axes = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
    for j in PUSHER_ACTUATORS:
        kind = "hinge" if j == "yaw" else "slide"
        ET.SubElement(body, "joint", name=f"pusher_{j}", type=kind, axis=axes.get(j, "0 0 1"))
    attrs = {"name": "pusher", "contype": "0", "conaffinity": "0", "group": "1"}
    if shape == "sphere" or (shape == "capsule" and length <= 0):
        ET.SubElement(body, "geom", type="sphere", size=_f(r), **attrs)
    elif shape == "capsule" and settings.capsule_ends:
        for name, y in (("pusher", -0.5 * length), ("pusher_end", 0.5 * length)):
            ET.SubElement(
                body,
                "geom",
                type="sphere",
                size=_f(r),
                pos=_vec([0, y, 0]),
                **{**attrs, "name": name},
            )
    elif shape == "capsule":
        h = 0.5 * length
        ET.SubElement(
            body, "geom", type="capsule", size=_f(r), fromto=_vec([0, -h, 0, 0, h, 0]), **attrs
        )
    elif shape == "box":
        half = [0.5 * s for s in _floats(entry, "size_m", 3, where)]
        ET.SubElement(body, "geom", type="box", size=_vec(half), **attrs)
    else:
        raise FormatError(
            f"pusher shape {shape!r} is not sphere, capsule or box",
            path="physics.json",
            where=f"{where}/shape",
        )
    dt = settings.timestep
    for j in PUSHER_ACTUATORS:
        mu = m if j != "yaw" else 0.01 * m
        ET.SubElement(
            actuator,
            "position",
            name=f"pusher_{j}",
            joint=f"pusher_{j}",
            kp=_f(settings.servo_position_gain * mu / dt**2),
            ctrllimited="false",
            forcelimited="false",
        )
    for j in PUSHER_ACTUATORS:
        mu = m if j != "yaw" else 0.01 * m
        ET.SubElement(
            actuator,
            "velocity",
            name=f"pusher_v{j}",
            joint=f"pusher_{j}",
            kv=_f(settings.servo_velocity_gain * mu / dt),
            ctrllimited="false",
            forcelimited="false",
        )


def _pose_attrs(pose: Sequence[float] | None) -> dict[str, str]:
    if pose is None:
        return {}
    p = [float(v) for v in pose]
    if len(p) != 7 or not all(math.isfinite(v) for v in p):
        raise FormatError(f"a pose is [x, y, z, qw, qx, qy, qz], got {pose!r}")
    return {"pos": _vec(p[:3]), "quat": _vec(p[3:])}


def scene_mjcf(
    physics: Mapping[str, Any],
    *,
    meshes: Mapping[str, Any] | None = None,
    poses: Mapping[str, Sequence[float]] | None = None,
    settings: ContactSettings | None = None,
    model_name: str = "robogs_scene",
    meshdir: str = "",
    joints: str = "auto",
) -> MjcfScene:
    """Build the MJCF of a physics.json document.

    Args:
        physics: the physics.json document.
        meshes: object name -> ``trimesh.Trimesh`` (object frame, m); an object with a mesh
            gets its collision hull instead of a ``size_m`` box.
        poses: object name -> ``T_world_object`` as ``[x, y, z, qw, qx, qy, qz]`` (free bodies'
            initial pose, static objects' pose; default identity).
        settings: solver and contact settings (default :data:`PLANAR_SETTINGS` on the planar
            joint set, else :class:`ContactSettings`).
        model_name: the ``<mujoco model>`` name.
        meshdir: prefix of mesh file names in the XML (e.g. ``"meshes/"``).
        joints: the objects' joint set, ``auto``, ``free`` or ``planar`` (:data:`JOINTS`).

    Returns:
        The document, its mesh assets, the free objects in qpos order and notes.

    Raises:
        FormatError: a value the scene needs is missing or malformed (the key is named), an
            unknown joint set, or ``planar`` for a scene it cannot represent.
    """
    meshes = dict(meshes or {})
    planar = use_planar_joints(physics, meshes, joints)
    settings = settings or (PLANAR_SETTINGS if planar else ContactSettings())
    poses = dict(poses or {})
    objects = physics.get("objects") or {}
    kb = float(settings.z_ballast) if planar else 0.0
    scene = MjcfScene(xml="", planar=planar, settings=settings, ballast=kb)
    root = ET.Element("mujoco", model=model_name)
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    grav = _floats(physics, "gravity_mps2", 3, "") if "gravity_mps2" in physics else [0, 0, -9.81]
    ET.SubElement(
        root,
        "option",
        timestep=_f(settings.timestep),
        gravity=_vec(grav),
        integrator=settings.integrator,
        cone=settings.cone,
        impratio=_f(settings.impratio),
        solver="Newton",
        iterations=str(settings.iterations),
        tolerance=_f(settings.tolerance),
        noslip_iterations=str(settings.noslip_iterations),
    )
    asset = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    contact = ET.Element("contact")
    actuator = ET.Element("actuator")
    table = objects.get("table") or {}
    normal = np.array(table.get("normal", [0.0, 0.0, 1.0]), dtype=float)
    if normal.shape != (3,) or not np.all(np.isfinite(normal)) or np.linalg.norm(normal) == 0:
        raise FormatError(
            "table normal must be 3 finite numbers", path="physics.json", where="objects/table"
        )
    normal = normal / np.linalg.norm(normal)
    z0 = _floats({"plane_z_m": [table.get("plane_z_m", 0.0)]}, "plane_z_m", 1, "objects/table")[0]
    point = table.get("point_m", [0.0, 0.0, z0])
    point = _floats({"p": point}, "p", 3, "objects/table/point_m")
    ET.SubElement(
        world,
        "geom",
        name="table",
        type="plane",
        size="0 0 0.05",
        pos=_vec(point),
        quat=_vec(_quat_from_z(normal)),
        contype="0",
        conaffinity="0",
    )
    free: dict[str, float] = {}
    masses: dict[str, float] = {}
    static: list[str] = []
    start: list[float] = []  # keyframe qpos of the objects, in body (= qpos) order
    for name in sorted(objects):
        entry = objects[name]
        if name in ("table", "pusher") or not isinstance(entry, Mapping):
            continue
        where = f"objects/{name}"
        eq = entry.get("equation")
        if eq == "rigid":
            pose = _pose_attrs(poses.get(name))
            p = [float(v) for v in poses.get(name, (0, 0, 0, 1, 0, 0, 0))]
            if planar:  # at the world origin: qpos is the pose (see the module docstring)
                body = ET.SubElement(world, "body", name=name)
                for suffix, kind, axis in PLANAR_JOINTS:
                    ET.SubElement(
                        body, "joint", name=f"{name}{suffix}", type=kind, axis=axis, limited="false"
                    )
                w, x, y, z = p[3:7]
                start += [*p[:3], math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))]
            else:
                body = ET.SubElement(world, "body", name=name, **pose)
                ET.SubElement(body, "freejoint", name=name)
                start += p
            masses[name] = _inertial(body, entry, where)
            if kb > 0:  # the z slide's ballast inertia (ContactSettings.z_ballast)
                zj = body.find(f"joint[@name='{name}_z']")
                zj.set("armature", _f(kb * masses[name]))
            _shape_geom(
                body,
                name,
                entry,
                where,
                meshes.get(name),
                scene,
                asset,
                meshdir,
                settings.footprint_grid,
                settings.footprint_spread,
                settings.footprint_torsion,
                # planar joint set: the footprint under the CoM (the friction centre; no roll
                # or pitch to shift its load; see write_body)
                _floats(entry, "com_m", 3, where)[:2] if planar and "com_m" in entry else (0, 0),
            )
            free[name] = _number(entry, "friction_dynamic", 0.4, where)
            for key in ("restitution", "damping_linear", "damping_angular"):
                if float(entry.get(key) or 0.0) != 0.0:
                    scene.unmapped.append(f"objects.{name}.{key}")
        elif eq == "static" and ("size_m" in entry or name in meshes):
            body = ET.SubElement(world, "body", name=name, **_pose_attrs(poses.get(name)))
            _shape_geom(body, name, entry, where, meshes.get(name), scene, asset, meshdir)
            static.append(name)
    scene.objects = list(free)
    pusher = objects.get("pusher")
    mu_p = 0.0
    if isinstance(pusher, Mapping):
        _pusher(world, pusher, settings, actuator)
        scene.pusher = "pusher"
        mu_p = _number(pusher, "friction_dynamic", 0.0, "objects/pusher")
    pusher_ends = False
    if isinstance(pusher, Mapping):
        length = _number(pusher, "length_m", 0.0, "objects/pusher")
        shape = str(pusher.get("shape") or "capsule")
        pusher_ends = settings.capsule_ends and length > 0 and shape == "capsule"
    if kb > 0:  # after the pusher's: its actuators keep their indices
        for name, mass in masses.items():
            ET.SubElement(
                actuator,
                "general",
                name=f"{name}_ballast",
                joint=f"{name}_z",
                gainprm="0",
                biastype="affine",
                biasprm=_vec([kb * mass * grav[2], 0.0, 0.0]),
                ctrllimited="false",
            )
        scene.notes.append(
            f"z ballast {kb:g}: each object's z slide has armature {kb:g} m and a constant "
            f"force {kb:g} m g_z (actuator <obj>_ballast, ctrl unused); support friction "
            f"coefficients are physics.json's / {1 + kb:g}"
        )
    # see PUSHER_SOLREFFRICTION_STEPS, ContactSettings.pusher_dampratio, OBJECT_PAIR_DAMPRATIO;
    # with a z ballast each pair's parameters are corrected by ballast_contact
    sr, si, srf = (_vec(v) for v in (settings.solref, settings.solimp, settings.solreffriction))
    sup = [
        _vec(v)
        for v in ballast_contact(
            settings.solref, settings.solimp, kb, True, settings.solreffriction
        )
    ]
    tc = settings.solref[0]
    tc_pusher = settings.pusher_timeconst_steps * settings.timestep or tc
    f_pusher = (PUSHER_SOLREFFRICTION_STEPS * settings.timestep, 1.0)
    # the onset ramp (ContactSettings.pusher_onset_steps) where the scene has a pusher
    imp_pusher = settings.solimp if scene.pusher is None else pusher_onset_solimp(settings)
    side = {
        key: [_vec(v) for v in ballast_contact((t, ratio), imp, kb, False, sf)]
        for key, t, ratio, sf, imp in (
            ("pusher", tc_pusher, settings.pusher_dampratio, f_pusher, imp_pusher),
            ("object", tc, OBJECT_PAIR_DAMPRATIO, settings.solreffriction, settings.solimp),
            ("static", tc, settings.solref[1], settings.solreffriction, settings.solimp),
        )
    }

    def pair(
        g1: str,
        g2: str,
        mu: float,
        rho: float = 0.0,
        solref: str = sr,
        solimp: str = si,
        solreffriction: str = srf,
    ) -> None:
        # condim 3 even without friction, so that a fitted friction can be set on the model;
        # condim 4 with torsional friction mu * rho on torsion footprints
        mu = max(mu, 1e-5)
        fr = _vec([mu, mu, mu * rho if rho > 0 else 0.005, 1e-4, 1e-4])
        ET.SubElement(
            contact,
            "pair",
            geom1=g1,
            geom2=g2,
            condim="4" if rho > 0 else "3",
            friction=fr,
            solref=solref,
            solreffriction=solreffriction,
            solimp=solimp,
        )
        scene.pairs.append((g1, g2))
        scene.pair_torsion.append(float(rho))

    names = list(free)
    for i, a in enumerate(names):
        feet = scene.feet.get(a, [])
        mu_t = free[a] / (1.0 + kb)  # the support carries (1 + k) m g (z_ballast)
        for g in feet:
            scene.table_pairs.setdefault(a, []).append(len(scene.pairs))
            pair(g, "table", mu_t, scene.torsion.get(a, 0.0), *sup)
        scene.table_pairs.setdefault(a, []).append(len(scene.pairs))
        pair(a, "table", mu_t, 0.0, *sup)
        if scene.pusher is not None:
            pair(a, "pusher", mu_p, 0.0, *side["pusher"])
            if pusher_ends:
                pair(a, "pusher_end", mu_p, 0.0, *side["pusher"])
        for b in names[i + 1 :]:
            pair(a, b, max(free[a], free[b]), 0.0, *side["object"])
        for s in static:
            pair(a, s, free[a], 0.0, *side["static"])
    if not len(asset):
        root.remove(asset)
    if len(contact):
        root.append(contact)
    if len(actuator):
        root.append(actuator)
    if start:  # the pusher (last body) starts at its qpos0, the world origin
        keyframe = ET.SubElement(root, "keyframe")
        ET.SubElement(
            keyframe, "key", name="start", qpos=_vec(start + [0.0] * 4 * (scene.pusher is not None))
        )
    if planar:
        scene.notes.append(
            "objects on the planar joint set (slide x, y, z, hinge z): no roll or pitch, "
            "as in the planar model"
        )
    for key in ("effects",):
        if physics.get(key):
            scene.unmapped += [f"effects.{e.get('name')}" for e in physics[key]]
    ET.indent(root)
    scene.xml = ET.tostring(root, encoding="unicode") + "\n"
    return scene

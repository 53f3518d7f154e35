"""``robogs export mjcf DATASET OUT``: the physics scene as MJCF (MuJoCo's XML), a folder::

    OUT/scene.xml                 plane, objects, pusher, contact pairs, solver options, robot
    OUT/meshes/*.stl              collision hulls of the objects that have a mesh asset
    OUT/meshes/robot/*.stl|obj    the robot's meshes (STL copied, DAE/PLY/GLB/OBJ as OBJ)
    OUT/robot_trajectory.npz      the recorded joint trajectory of every episode

The document is built by :func:`robogs.format.mjcf.scene_mjcf`, the same builder the
``mujoco`` physics engine compiles, from the dataset's current physics.json revision (its
fitted values: masses, CoM, inertia, friction of every pair, gravity) and the object meshes.
Objects start at their pose at the start of the first episode
(:func:`.urdf_scene.scene_state`). The pusher is a body on four joints (x, y, z, yaw) with a
position servo ``pusher_<j>`` and a velocity servo ``pusher_v<j>`` per joint: replaying the
recorded pusher path means setting, at each step ``k``, the position servos to ``p[k]`` and
the velocity servos to ``(p[k+1] - p[k]) / dt`` (see ``docs/exports.md``).

When the dataset has a robot, its URDF is in the document too (:mod:`robogs.format.mjcf_robot`:
MuJoCo's URDF compiler reads it, every link a body, written at full precision), after the scene's
bodies and actuators (the scene's qpos and ctrl indices are those of the engine's model). The
robot is kinematic: it collides with nothing (the pusher stays the end effector's contact
proxy), gravity is compensated, and each actuated joint has a position servo ``robot_<joint>``
and a velocity servo ``robot_v_<joint>`` on a heavy armature. The ``start`` keyframe puts it at
the first ``joint_states`` row of the first episode. The recorded trajectory goes to the
companion ``robot_trajectory.npz`` rather than to keyframes (an episode has thousands of
samples; a keyframe holds the whole scene's state): ``joint_names`` [J] (the servos' joints,
URDF order), ``episodes`` [E], and per episode ``k`` ``t_ns_<k>`` [N] int64 (dataset clock) and
``q_<k>`` [N, J] float64 (rad or m; NaN where ``joint_states`` has no column for a joint).

With ``objects.pusher.geometry = "robot"`` the pusher is the engine's robot pusher instead of
the primitive: the URDF collision geoms of the pusher link and the links below it, one pair per
geom and object, and the servo DOFs the recording moves (the end effector's pitch and roll,
moving joints below the pusher link), written by
:func:`robogs.format.mjcf_pusher.robot_pusher_scene`, the function the ``mujoco`` engine
compiles. What it places is measured from the recording by the physics side, which this module
may not import: the ``robot_pusher`` option
(:func:`robogs.physics.export_pusher.robot_pusher_paths`) carries it, and the export refuses
the dataset without it. Its meshes go to ``OUT/meshes/robot/`` (mesh names ``robot/<mesh>``;
the kinematic robot is then prefixed ``arm/`` when it needs a prefix), and
``robot_trajectory.npz`` gets the pusher's path and DOFs per episode (``pusher_*``, see
:func:`_pusher_arrays` and ``docs/exports.md``). A primitive-pusher export is unchanged.

Meshes replaced by their convex hulls and physics.json keys MuJoCo does not represent are listed
in the report notes and in a ``<custom>`` text element of the document.

Fitted effects (physics.json ``effects``): those with an MJCF-native form are in the model as
the ``mujoco`` engine compiles them, in the engine's order. First the body effects
(:data:`robogs.format.mjcf.BODY_EFFECTS`: ``mass``, ``com_offset``, ``restitution``) change the
target object's physics.json body, which :func:`robogs.format.mjcf.write_body` - the function
the engine writes each parameter set's body with - writes into the compiled scene (mass and
inertia, CoM, the support pairs' friction and restitution ``solref``/``solimp``, the linear
damping on the planar joint set, the z ballast); then the map
:data:`robogs.format.mjcf.NATIVE_EFFECTS` (the engine's ``mujoco_effects.NATIVE``: gravity for
``table_tilt``, the slide joints' damping for ``viscous_damping`` on the planar joint set). The
fields they changed (:data:`robogs.format.mjcf.NATIVE_FIELDS`,
:data:`~robogs.format.mjcf.BODY_FIELDS`) are written back at full precision (a body's
``<inertial>`` as ``diaginertia`` + ``quat``, the compiled principal form); any other change
refuses the export. Every other effect (per-step
forces on the engine: quadratic drag, Stribeck, anisotropic friction, user effects; sensor
effects; viscous damping on a free joint, whose MJCF damping would also damp rotation) is a
``<numeric name="robogs_effect/<effect>/<param>">`` per fitted parameter, and a note
(:data:`FORCE_NOTE` for the force effects) in the report and the ``<text>``: a plain MuJoCo load
does not simulate it. The notes list the effects in the model and those only as records;
``facts["effects"]``: name, target, params, ``written``.

Dependency note: this module imports only ``robogs.format`` (the builder is format-level), so
the rule that ``robogs.convert`` never imports ``robogs.physics`` holds without an exception.
"""

from __future__ import annotations

import io
from dataclasses import replace
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from robogs.format import Dataset
from robogs.format.errors import FormatError, InputError, PathEscapeError
from robogs.format.mjcf import (
    BODY_EFFECTS,
    BODY_FIELDS,
    NATIVE_EFFECTS,
    NATIVE_FIELDS,
    EffectSlots,
    MjcfScene,
    body_values,
    com_feet,
    scene_mjcf,
    write_body,
)
from robogs.format.mjcf_pusher import PusherPaths, pusher_geometry, robot_pusher_scene
from robogs.format.shapes import BOX_BUDGET, object_shapes

from . import ExportReport, register_exporter
from .urdf_scene import scene_state

__all__ = ["FORCE_NOTE", "TRAJECTORY_FILE", "export_mjcf"]

TRAJECTORY_FILE = "robot_trajectory.npz"
"""The companion file of the recorded joint trajectory (see the module docstring)."""


def _trajectory(
    ds: Dataset, joints: list[str], pusher: PusherPaths | None = None
) -> tuple[bytes, dict[str, Any], list[str]]:
    """``robot_trajectory.npz`` bytes, its facts, and notes (joints without a column); with a
    robot pusher also its paths (:func:`_pusher_arrays`)."""
    arrays: dict[str, np.ndarray] = {"joint_names": np.array(joints, dtype=str)}
    ids, counts, missing = [], [], set()
    for ep in ds.episodes:
        if not ep.has("joint_states"):
            continue
        tab = ep.table("joint_states").sort_by("t_ns")
        k = len(ids)
        arrays[f"t_ns_{k}"] = np.asarray(tab.column("t_ns").to_numpy(), dtype=np.int64)
        q = np.full((tab.num_rows, len(joints)), np.nan)
        for i, j in enumerate(joints):
            if f"position.{j}" in tab.column_names:
                q[:, i] = np.asarray(tab.column(f"position.{j}").to_numpy(), dtype=np.float64)
            else:
                missing.add(j)
        arrays[f"q_{k}"] = q
        ids.append(ep.id)
        counts.append(tab.num_rows)
    arrays["episodes"] = np.array(ids, dtype=str)
    if pusher is not None:
        arrays.update(_pusher_arrays(pusher))
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    notes = []
    if missing:
        notes.append(
            f"joint_states has no column for {', '.join(sorted(missing))}: NaN in "
            f"{TRAJECTORY_FILE}, 0 in the start keyframe"
        )
    if not ids:
        notes.append(f"no episode has joint_states: {TRAJECTORY_FILE} holds no episode")
    return buf.getvalue(), {"episodes": ids, "samples": counts}, notes


def _pusher_arrays(pusher: PusherPaths) -> dict[str, np.ndarray]:
    """The robot pusher's part of ``robot_trajectory.npz``: ``pusher_dof_names`` [J],
    ``pusher_servos`` [J, 3] (MuJoCo joint, position servo, velocity servo of each DOF),
    ``pusher_episodes`` [E] and per episode ``k`` ``pusher_t_ns_<k>`` [N] int64 (the end
    effector's stamps), ``pusher_p_<k>`` [N, 3] m (the pusher point), ``pusher_yaw_<k>`` [N]
    rad (unwrapped) and ``pusher_q_<k>`` [N, J] (rad or m), the recording the engine fits with."""
    rp = pusher.pusher
    out: dict[str, np.ndarray] = {
        "pusher_dof_names": np.array(list(rp.dofs), dtype=str),
        "pusher_servos": np.array(rp.servos, dtype=str).reshape(len(rp.dofs), 3),
        "pusher_episodes": np.array(pusher.episodes, dtype=str),
    }
    for k in range(len(pusher.episodes)):
        out[f"pusher_t_ns_{k}"] = np.asarray(pusher.t_ns[k], dtype=np.int64)
        out[f"pusher_p_{k}"] = np.asarray(pusher.point[k], dtype=np.float64)
        out[f"pusher_yaw_{k}"] = np.asarray(pusher.yaw[k], dtype=np.float64)
        out[f"pusher_q_{k}"] = np.asarray(pusher.dofs[k], dtype=np.float64)
    return out


def _robot_pusher(
    ds: Dataset, physics: dict[str, Any], scene: MjcfScene, given: PusherPaths | None
) -> tuple[MjcfScene, dict[str, bytes], dict[str, Any], list[str]]:
    """With ``objects.pusher.geometry = "robot"``: the scene with the engine's robot pusher
    (:func:`robogs.format.mjcf_pusher.robot_pusher_scene`, the function the ``mujoco`` engine
    compiles), its mesh files (``meshes/robot/...``, paths relative to the document), its facts
    and notes. With the primitive pusher the scene unchanged.

    Raises:
        InputError: geometry ``robot`` without ``given`` (the measurement is the physics
            side's), or ``given`` with the primitive pusher.
    """
    where = ds.resolve("physics.json")
    if pusher_geometry(physics) != "robot":
        if given is not None:
            raise InputError(
                "a robot pusher was given but physics.json's pusher is the primitive",
                path=where,
                where="objects/pusher/geometry",
                hint="leave robot_pusher out, or set objects.pusher.geometry=robot",
            )
        return scene, {}, {}, []
    if given is None:
        raise InputError(
            "physics.json's pusher is the robot (objects.pusher.geometry robot), measured from "
            "the recording by robogs.physics, and the export was not given it",
            path=where,
            where="objects/pusher/geometry",
            hint="pass robot_pusher=robogs.physics.export_pusher.robot_pusher_paths(dataset) "
            "to the mjcf export",
        )
    before = set(scene.assets)
    scene, geoms = robot_pusher_scene(scene, given.pusher)
    files = {k: v for k, v in scene.assets.items() if k not in before}
    rp = given.pusher
    facts = {
        "link": rp.link,
        "links": list(rp.frames),
        "bodies": {n: rp.bodies.get(n, "") for n in rp.frames},
        "geoms": geoms,
        "dofs": list(rp.dofs),
        "servos": [list(s) for s in rp.servos],
        "tilt": bool(rp.tilt),
        "moved_mm": rp.moved_m * 1e3,
        "budget_mm": rp.budget_m * 1e3,
        "meshes": sorted(files),
        "trajectory": {"file": TRAJECTORY_FILE, "episodes": list(given.episodes)},
    }
    notes = [
        f"pusher: the robot's links {', '.join(rp.frames)} as the mujoco engine fits with "
        "(objects.pusher.geometry robot)"
        + (f", servo-driven DOFs {', '.join(rp.dofs)}" if rp.dofs else "")
        + f"; its path and DOFs per episode in {TRAJECTORY_FILE} (pusher_*)"
    ]
    return scene, files, facts, notes


FORCE_NOTE = "applied by robogs as per-step forces; not simulated by a plain MuJoCo load"
"""What the notes and the document say of a fitted effect without an MJCF-native form."""

_NOT_NATIVE = {
    "force": FORCE_NOTE,
    "free": "viscous damping on a free joint: MJCF joint damping is one value for all six "
    "DOFs, the engine damps x, y, z only; not simulated by a plain MuJoCo load",
    "sensor": "a sensor effect (applied by robogs to the sampled poses, not to the dynamics)",
}
_SENSOR = ("time_offset", "camera_extrinsics")
_WRITTEN = ("native", "body")


def _kind(name: str) -> str:
    """How a plain MuJoCo load sees a fitted effect: ``native`` (:data:`NATIVE_EFFECTS`) or
    ``body`` (:data:`BODY_EFFECTS`), both in the model; ``sensor``; or ``force`` (every other,
    built-in or a user's, runs as per-step forces)."""
    if name in NATIVE_EFFECTS:
        return "native"
    if name in BODY_EFFECTS:
        return "body"
    return "sensor" if name in _SENSOR else "force"


def _effects(
    xml: str, scene: MjcfScene, physics: dict[str, Any], where: Path
) -> tuple[str, list[dict[str, Any]], list[str]]:
    """The document with every fitted effect of ``physics["effects"]`` that has an MJCF-native
    form, one record per effect (name, target, params, how it is written), and the
    ``scene.unmapped`` keys the written bodies now represent.

    The maps the ``mujoco`` engine applies are applied to the compiled scene in the engine's
    order: first each body effect's target body (its physics.json values with
    :data:`BODY_EFFECTS` applied in order, written by :func:`robogs.format.mjcf.write_body`: mass,
    inertia, CoM, the support pairs' restitution; the nominal ``restitution`` and, on the planar
    joint set, ``damping_linear`` with them), then :data:`NATIVE_EFFECTS`. The fields they changed
    (:data:`NATIVE_FIELDS`, :data:`BODY_FIELDS`) are written back at full precision; a change of
    any other field refuses the export."""
    import xml.etree.ElementTree as ET

    import mujoco

    entries = [e for e in physics.get("effects") or [] if isinstance(e, dict)]
    if not entries:
        return xml, [], []
    model = mujoco.MjModel.from_xml_string(xml, assets=scene.assets)
    rows = _pair_rows(model, scene)
    before = {f: np.array(_field(model, f)).copy() for f in _WATCHED}
    objects = physics.get("objects") or {}
    records, bodies, native = [], {}, []
    for i, entry in enumerate(entries):
        name = str(entry.get("name"))
        target = str(entry.get("target") or (scene.objects[0] if scene.objects else ""))
        params = entry.get("params") or {}
        if not isinstance(params, dict) or not all(
            isinstance(v, (int, float)) and np.isfinite(v) for v in params.values()
        ):
            raise FormatError(
                f"effect {name!r} has parameters that are not finite numbers",
                path=where,
                where=f"effects[{i}].params",
                hint="refit the effect (robogs fit --add) or revert the revision",
            )
        params = {k: float(v) for k, v in params.items()}
        kind = _kind(name)
        if kind in _WRITTEN and target not in scene.objects:
            raise FormatError(
                f"effect {name!r} targets {target!r}, not a rigid object of the scene",
                path=where,
                where=f"effects[{i}].target",
                hint=f"rigid objects: {', '.join(scene.objects)}",
            )
        free = kind in _WRITTEN and _free(model, target)
        if kind == "native" and name == "viscous_damping" and free:
            kind = "free"
        elif kind == "native":
            native.append((name, params, target))
        elif kind == "body":
            if target not in bodies:  # free joint: MJCF cannot damp x, y, z alone
                nominal = body_values(objects[target], f"objects/{target}")
                bodies[target] = replace(nominal, damping=0.0) if free else nominal
            bodies[target] = BODY_EFFECTS[name](bodies[target], params)
        records.append(
            {
                "name": name,
                "target": target,
                "params": params,
                "written": kind in _WRITTEN,
                **({"why": _NOT_NATIVE[kind]} if kind not in _WRITTEN else {}),
            }
        )
    covered = []
    for target, values in bodies.items():  # the engine's order: the body, then the maps
        slots = _slots(model, scene, target, rows)
        write_body(model, values, slots, timeconst=float(scene.settings.solref[0]))
        covered.append(f"objects.{target}.restitution")
        if not _free(model, target):
            covered.append(f"objects.{target}.damping_linear")
    for name, params, target in native:
        NATIVE_EFFECTS[name](model, params, _slots(model, scene, target, rows))
    changed = {
        f: np.flatnonzero(np.any(np.array(_field(model, f)) != b, axis=1))
        for f, b in before.items()
    }
    for f, idx in changed.items():  # the maps may change NATIVE_FIELDS and BODY_FIELDS only
        if len(idx) and f not in NATIVE_FIELDS + BODY_FIELDS:
            raise FormatError(
                f"an effect map changed MjModel.{f}, which the export cannot write",
                path=where,
                where="effects",
                hint=f"robogs.format.mjcf.NATIVE_EFFECTS may change {', '.join(NATIVE_FIELDS)}, "
                f"write_body {', '.join(BODY_FIELDS)}",
            )
    root = ET.fromstring(xml)
    _write_back(root, model, changed, rows, where)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n", records, covered


_WATCHED = (
    "opt.gravity",
    *BODY_FIELDS,
    "body_pos",
    "body_quat",
    "geom_friction",
    "geom_solref",
    "geom_solimp",
    "pair_margin",
    "actuator_gainprm",
)
"""Model fields compared before and after the maps: those of :data:`NATIVE_FIELDS` and
:data:`BODY_FIELDS` are written back, a change of another refuses the export."""


def _free(model: Any, name: str) -> bool:
    """Whether the object ``name`` moves on a free joint (else on the planar joint set)."""
    import mujoco

    return int(model.jnt_type[model.joint(name).id]) == mujoco.mjtJoint.mjJNT_FREE


def _field(model: Any, name: str) -> np.ndarray:
    """``MjModel`` field ``name`` (``opt.gravity`` reaches into ``opt``) as [rows, columns]."""
    obj = model
    for part in name.split("."):
        obj = getattr(obj, part)
    return np.atleast_2d(np.asarray(obj).T).T if np.ndim(obj) == 1 else np.asarray(obj)


def _pair_rows(model: Any, scene: MjcfScene) -> list[int]:
    """Compiled row of each ``scene.pairs`` entry (XML order): MuJoCo sorts the pairs when it
    compiles, so the two orders differ with several objects."""
    import mujoco

    def name(g: int) -> str:
        return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, int(g)) or ""

    compiled = [
        frozenset((name(model.pair_geom1[j]), name(model.pair_geom2[j])))
        for j in range(model.npair)
    ]
    return [compiled.index(frozenset(p)) for p in scene.pairs]


def _slots(model: Any, scene: MjcfScene, target: str, rows: list[int]) -> EffectSlots:
    """Where ``target`` lives in the compiled scene (:class:`robogs.format.mjcf.EffectSlots`)."""
    import mujoco

    b = model.body(target).id
    table = scene.table_pairs.get(target, [])
    return EffectSlots(
        body=b,
        dof=int(model.jnt_dofadr[model.joint(target).id]),
        ballast=float(scene.ballast),
        table_pairs=tuple(rows[k] for k in table),
        table_torsion=tuple(float(scene.pair_torsion[k]) for k in table),
        nominal_mass=float(model.body_mass[b]),
        nominal_inertia=tuple(float(v) for v in model.body_inertia[b]),
        nominal_iquat=tuple(float(v) for v in model.body_iquat[b]),
        ballast_actuator=mujoco.mj_name2id(
            model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{target}_ballast"
        ),
        com_feet=com_feet(model, scene, target),
    )


def _reals(values: Any) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _write_back(
    root: Any, model: Any, changed: dict[str, np.ndarray], rows: list[int], where: Path
) -> None:
    """Write the changed rows of :data:`NATIVE_FIELDS` and :data:`BODY_FIELDS` into the
    document ``root`` at full precision: ``<option gravity>``, a body's ``<inertial>`` (mass,
    pos, diaginertia, quat: the compiled principal form), a geom's ``pos``, a joint's ``damping`` / ``armature``,
    a pair's ``friction`` / ``solref`` / ``solimp``, an actuator's ``biasprm``."""
    if len(changed["opt.gravity"]):
        root.find("option").set("gravity", _reals(model.opt.gravity))
    inertial_fields = ("body_mass", "body_inertia", "body_iquat", "body_ipos")
    body_rows = {int(b) for f in inertial_fields for b in changed[f]}
    for b in sorted(body_rows):
        inertial = root.find(f".//body[@name='{model.body(b).name}']/inertial")
        inertial.attrib.pop("fullinertia", None)
        inertial.set("pos", _reals(model.body_ipos[b]))
        inertial.set("mass", _reals(model.body_mass[b]))
        inertial.set("diaginertia", _reals(model.body_inertia[b]))
        inertial.set("quat", _reals(model.body_iquat[b]))
    for g in changed["geom_pos"]:  # footprint geoms that follow the CoM (write_body)
        geom = root.find(f".//geom[@name='{model.geom(int(g)).name}']")
        geom.set("pos", _reals(model.geom_pos[g]))
    for f, attr in (("dof_damping", "damping"), ("dof_armature", "armature")):
        for d in changed[f]:
            jname = model.joint(int(model.dof_jntid[d])).name
            joint = root.find(f".//joint[@name='{jname}']")
            if joint is None:  # a free joint: one value for its six DOFs
                raise FormatError(
                    f"an effect map changed {f} of the free joint {jname!r}, which MJCF cannot "
                    "write per DOF",
                    path=where,
                    where="effects",
                )
            joint.set(attr, _reals(getattr(model, f)[d]))
    pairs = root.find("contact").findall("pair") if model.npair else []
    xml_of = {j: i for i, j in enumerate(rows)}
    pair_fields = ("pair_friction", "pair_solref", "pair_solimp")
    for j in sorted({int(j) for f in pair_fields for j in changed[f]}):
        pair = pairs[xml_of[j]]
        pair.set("friction", _reals(model.pair_friction[j]))
        pair.set("solref", _reals(model.pair_solref[j]))
        pair.set("solimp", _reals(model.pair_solimp[j]))
    for a in changed["actuator_biasprm"]:
        act = root.find(f"actuator/*[@name='{model.actuator(int(a)).name}']")
        act.set("biasprm", _reals(model.actuator_biasprm[a]))


def _custom(records: list[dict[str, Any]]) -> tuple[str, list[str]]:
    """``<numeric>`` elements of the effects not in the model (``robogs_effect/<name>/<param>``,
    full precision) and one note per effect."""
    lines, notes = [], []
    for r in records:
        if r["written"]:
            continue
        for k, v in r["params"].items():
            name = quoteattr(f"robogs_effect/{r['name']}/{k}")  # names come from physics.json
            lines.append(f'    <numeric name={name} data="{float(v)!r}" />')
        vals = ", ".join(f"{k}={v:.6g}" for k, v in r["params"].items())
        notes.append(f"fitted effect {r['name']} on {r['target']} ({vals}): {r['why']}")
    return "\n".join(lines), notes


def _write_inside(out: Path, rel: str, data: bytes) -> None:
    """Write ``out/rel``, refusing a path that leaves ``out``."""
    target = (out / rel).resolve()
    if not target.is_relative_to(out.resolve()):
        raise PathEscapeError("output file escapes the export folder", path=out, where=rel)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(data)


def export_mjcf(ds: Dataset, out: Path, *, robot_pusher: PusherPaths | None = None) -> ExportReport:
    """Write ``OUT/scene.xml`` and ``OUT/meshes/`` from the dataset's physics.json.

    Args:
        robot_pusher: with ``objects.pusher.geometry = "robot"``, the robot pusher measured
            from the recording (:func:`robogs.physics.export_pusher.robot_pusher_paths`;
            required then, refused otherwise).

    Raises:
        InputError: the dataset has no physics.json or no rigid object in it; the robot
            pusher missing or not the dataset's.
        FormatError: a physics.json value the scene needs is missing or malformed.
    """
    if not ds.manifest.get("physics"):
        raise InputError(
            "dataset has no physics.json",
            path=ds.manifest_path,
            hint="run `robogs physics init` first",
        )
    physics = ds.physics()
    objects = physics.get("objects") or {}
    rigid = [n for n, e in objects.items() if isinstance(e, dict) and e.get("equation") == "rigid"]
    if not rigid:
        raise InputError(
            "physics.json has no rigid object to simulate",
            path=ds.resolve("physics.json"),
            where="objects",
        )
    meshes = {}
    for name, entry in objects.items():
        if name in ("table", "pusher") or not isinstance(entry, dict):
            continue
        if "mesh" in (ds.assets.get(name) or {}):
            meshes[name] = ds.mesh(name)
    # a rigid object's mesh that is its size_m box stays the box, as the fitting engine has it
    shapes = object_shapes(physics, meshes, float(ds.budgets[BOX_BUDGET]))
    kept_as_box = [
        f"object {n!r}: its mesh is its size_m box within {d * 1e3:.2g} mm "
        f"({BOX_BUDGET} {float(ds.budgets[BOX_BUDGET]):g} mm): written as the box"
        for n, d in sorted(shapes.boxes.items())
    ]
    meshes = {n: m for n, m in meshes.items() if n not in shapes.boxes}
    state = scene_state(ds, [n for n in objects if n not in ("table", "pusher")])
    poses = {n: p.pose for n, p in state.objects.items()}
    scene = scene_mjcf(
        physics, meshes=meshes, poses=poses, model_name=f"{ds.name}_scene", meshdir="meshes/"
    )
    scene, pusher_files, pusher_facts, pusher_notes = _robot_pusher(
        ds, physics, scene, robot_pusher
    )
    xml, effects, covered = _effects(scene.xml, scene, physics, ds.resolve("physics.json"))
    numeric, effect_notes = _custom(effects)
    written = [f"{r['name']} on {r['target']}" for r in effects if r["written"]]
    as_custom = [f"{r['name']} on {r['target']}" for r in effects if not r["written"]]
    if as_custom:
        effect_notes.insert(0, f"fitted effects as <custom> records only: {', '.join(as_custom)}")
    if written:
        effect_notes.insert(
            0,
            f"fitted effects in the model as the mujoco engine compiles them: {', '.join(written)}",
        )
    unmapped = [k for k in scene.unmapped if not k.startswith("effects.") and k not in covered]
    robot_notes: list[str] = []
    robot_facts: dict[str, Any] = {}
    robot_files: dict[str, bytes] = {}
    if (ds.manifest.get("robot") or {}).get("urdf"):
        from robogs.format.mjcf_robot import add_robot, document_names, robot_mjcf

        tree = ds.urdf(load_meshes=False).robot
        urdf_names = {lk.name for lk in tree.links} | {j.name for j in tree.joints}
        clash = sorted(urdf_names & document_names(xml))
        # the robot pusher's meshes are robot/<mesh>: the kinematic robot then takes arm/
        prefix = ("arm/" if pusher_files else "robot/") if clash else ""
        rob = robot_mjcf(ds.urdf_path, root=ds.root, meshdir="meshes/robot/", prefix=prefix)
        if clash:
            robot_notes.append(
                f"robot names prefixed {prefix!r} (the scene already has {', '.join(clash[:5])})"
            )
        q_first = state.joint_positions
        q0 = [float(q_first.get(j, 0.0)) for j in rob.actuated]
        xml, servos = add_robot(xml, rob, q0)
        traj, traj_facts, traj_notes = _trajectory(ds, rob.actuated, robot_pusher)
        for rel, data in pusher_files.items():  # the same URDF mesh converted the same way
            if rob.files.get(rel, data) != data:
                raise FormatError(
                    f"the robot pusher's mesh {rel} differs from the robot's file of that name",
                    path=ds.urdf_path,
                    where=rel,
                )
        robot_files = {**pusher_files, **rob.files, TRAJECTORY_FILE: traj}
        robot_notes += [
            f"robot {rob.name!r}: {len(rob.links)} links, {len(rob.joints)} joints, kinematic "
            "(no contact, gravity compensated, servos robot_JOINT / robot_v_JOINT)",
            *rob.notes,
            *traj_notes,
        ]
        robot_facts = {
            "robot": {
                "name": rob.name,
                "prefix": rob.prefix,
                "links": dict(rob.links),
                "joints": list(rob.joints),
                "actuated": list(rob.actuated),
                "servos": servos,
                "start_q": dict(zip(rob.actuated, q0, strict=True)),
                "start_q_t_ns": state.joint_positions_t_ns,
                "meshes": [
                    {
                        "source": c.source.name,
                        "file": c.file,
                        "action": c.action,
                        "vertices_in": c.vertices_in,
                        "vertices_out": c.vertices_out,
                        **({"why": c.why} if c.why else {}),
                    }
                    for c in rob.conversions
                ],
                "trajectory": {"file": TRAJECTORY_FILE, **traj_facts},
            }
        }
    remarks = [
        *kept_as_box,
        *scene.notes,
        *pusher_notes,
        *robot_notes,
        *effect_notes,
        *(f"not represented: {k}" for k in unmapped),
    ]
    remarks.append(f"physics revision {physics.get('revision')} of dataset {ds.name!r}")
    text = "; ".join(remarks).replace('"', "'").replace("&", "and").replace("<", "(")
    custom = f'    <text name="robogs" data="{text}" />' + (f"\n{numeric}" if numeric else "")
    xml = xml.replace("</mujoco>", f"  <custom>\n{custom}\n  </custom>\n</mujoco>")
    (out / "scene.xml").write_text(xml, encoding="utf-8")
    files = ["scene.xml"]
    hulls = {f: d for f, d in scene.assets.items() if f not in pusher_files}
    if hulls:
        (out / "meshes").mkdir()
        for fname, data in sorted(hulls.items()):
            (out / "meshes" / fname).write_bytes(data)
            files.append(f"meshes/{fname}")
    for rel, data in sorted(robot_files.items()):
        _write_inside(out, rel, data)
        files.append(rel)
    if not robot_facts:
        robot_notes = ["dataset has no robot: none in the document"]
    notes = [*kept_as_box, *scene.notes, *pusher_notes, *robot_notes, *effect_notes]
    if unmapped:
        notes.append(f"not represented in MuJoCo: {', '.join(unmapped)}")
    return ExportReport(
        out=out,
        files=files,
        notes=notes,
        facts={
            "objects": scene.objects,
            "pusher": scene.pusher,
            "pairs": [list(p) for p in scene.pairs],
            "hulled_meshes": sorted(meshes),
            "unmapped": unmapped,
            "effects": effects,
            "physics_revision": physics.get("revision"),
            **robot_facts,
            **({"robot_pusher": pusher_facts} if pusher_facts else {}),
        },
    )


register_exporter(
    "mjcf",
    export_mjcf,
    output="folder",
    help="MuJoCo MJCF scene: plane, objects, servo-driven pusher, fitted contact parameters, "
    "the kinematic robot and its recorded joint trajectory",
)

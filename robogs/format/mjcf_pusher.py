"""The robot pusher's scene document: the URDF's collision geometry as the MuJoCo pusher.

``objects.pusher.geometry = "robot"`` makes the robot's own links the pusher
(:mod:`robogs.physics.engines.mujoco_robot` says what is modelled and why: the links' constant
poses in the pusher frame, the end effector's pitch and roll and the moving joints below the
pusher link as servo DOFs, measured from the recording). This module is the MJCF-writing part of
it, pure document editing on a :class:`robogs.format.mjcf.MjcfScene`: the ``mujoco`` physics
engine compiles what :func:`robot_pusher_scene` returns, and ``robogs export mjcf`` writes the
same document (:mod:`robogs.convert.export.mjcf`), so the exported pusher is the fitted one by
construction (one writer, no copy). It lives in ``robogs.format`` beside the scene builder
(:func:`robogs.format.mjcf.scene_mjcf`) because the exporter may import only ``robogs.format``.

What the writer takes is a :class:`RobotPusher` record (the URDF, the pusher link, each link's
``T_body_link`` and the body that carries it, the tilt and the modelled joints): the physics
side measures it (:func:`robogs.physics.engines.mujoco_robot.pusher_model`), the writer only
places it. The document it writes:

* the pusher body's primitive geoms are replaced by the links' URDF collision geoms
  (``pusher/<link>/<k>``, read by :func:`robogs.format.mjcf_robot.robot_mjcf` with the name
  prefix :data:`PREFIX`, meshes as that module converts them), ``contype = conaffinity = 0``;
* each object-pusher ``<pair>`` becomes one pair per robot geom with the same attributes;
* with the tilt, hinges ``pusher_pitch`` and ``pusher_roll`` after the pusher's yaw hinge;
  each modelled joint its body ``pusher/<joint>`` (slide or hinge about the URDF axis,
  :data:`CHILD_MASS`); each such DOF a position servo and a velocity servo
  (:attr:`RobotPusher.servos`) after the scene's other actuators;
* each ``<key>``'s ``qpos`` extended by the DOFs' joints at :attr:`RobotPusher.start` (0 when
  unset, as the engine compiles it) and, with a start, a ``ctrl`` that holds them there (their
  position servos at the start, velocity servos and the rest 0): ``robogs export mjcf`` starts
  them at the first recorded values (:func:`robogs.physics.export_pusher.robot_pusher_paths`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import FormatError, InputError

__all__ = [
    "CHILD_MASS",
    "PREFIX",
    "PUSHER_GEOMETRIES",
    "TILT_DOFS",
    "PusherJoint",
    "PusherPaths",
    "RobotPusher",
    "pusher_geometry",
    "robot_pusher_scene",
]

PUSHER_GEOMETRIES = ("primitive", "robot")
"""Values of ``objects.pusher.geometry`` (default ``primitive``)."""

PREFIX = "robot/"
"""Name prefix of the robot's meshes, and of the moving joints' bodies, joints and servos, in
the scene document."""

TILT_DOFS = ("pitch", "roll")
"""The end effector's tilt DOFs (ZYX angles: ``R_ee = Rz(yaw) Ry(pitch) Rx(roll)``)."""

CHILD_MASS = 1e-6
"""Mass of a moving joint's body in units of the pusher's mass (its inertia the pusher body's
times the same factor): MuJoCo needs a moving body to have mass, and so little of it keeps the
pusher's servos dead-beat (its composite mass grows by 1e-6 per body). The joint's inertia is
its ``armature``: the pusher's mass (slide) or yaw inertia (hinge), so a finger yields to a
contact as little as the pusher does."""


@dataclass
class PusherJoint:
    """A URDF joint below the pusher link, with the chain's semantics
    (:class:`robogs.format.kinematics.Chain`: ``T_parent_child = origin @ motion(value)``).

    Attributes:
        name: the joint; kind: ``fixed``, ``slide`` (prismatic) or ``hinge`` (revolute,
        continuous); parent, child: its links; origin: ``T_parent_jointframe`` [4, 4] (m);
        axis: [3] unit axis in the joint frame.
    """

    name: str
    kind: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray


@dataclass
class RobotPusher:
    """The robot's pusher geometry for the MuJoCo engine.

    Attributes:
        urdf: the URDF file; root: allowed root of its meshes (the dataset root);
        package_roots: ``{package: folder}`` for ``package://`` URIs (None: the default search).
        link: the pusher link.
        frames: link name -> ``T_pusher_link`` [4, 4] (m), the pusher link and the links below
            it, in the pusher frame (origin the pusher point, axes the end effector's yaw).
        spread_m, spread_rad: the largest spread of those frames over the recording.
        moved_m, budget_m: the worst link's displacement and its budget
            (:class:`robogs.physics.engines.mujoco_robot.Rigidity`).
        notes: what was said about the geometry (hulled meshes, which links).
        tilt: the end effector's pitch and roll are servo DOFs of the pusher body (hinges
            ``pusher_pitch``, ``pusher_roll`` after the yaw hinge); the pusher frame is then
            the end effector's full orientation at the pusher point.
        joints: the URDF joints below the pusher link that the recording moves, each the joint
            of its own servo-driven body (``robot/<joint>``), in the chain's order.
        bodies: link -> the body that carries it: ``""`` the pusher body, else the name of
            the nearest modelled joint above it; ``frames`` is then ``T_body_link`` (the joint
            body's frame is its child link's frame). Absent links: the pusher body.
        start: [J] the values of :attr:`dofs` (rad or m) the document's keyframes start them
            at (the recording's first values, set for the export by
            :func:`robogs.physics.export_pusher.robot_pusher_paths`); None: 0, their qpos0
            (the engine sets the state itself and never reads a keyframe).
    """

    urdf: Path
    link: str
    frames: dict[str, np.ndarray]
    root: Path | None = None
    package_roots: Mapping[str, Any] | None = None
    spread_m: float = 0.0
    spread_rad: float = 0.0
    notes: list[str] = field(default_factory=list)
    moved_m: float = 0.0
    budget_m: float = 0.0
    tilt: bool = False
    joints: list[PusherJoint] = field(default_factory=list)
    bodies: dict[str, str] = field(default_factory=dict)
    start: list[float] | None = None

    @property
    def dofs(self) -> list[str]:
        """Names of the servo DOFs beyond the pusher's x, y, z and yaw, in the order of
        ``Drive.pusher_dofs``' last axis: ``pitch``, ``roll`` (with :attr:`tilt`), then the
        modelled joints (rad or m)."""
        return [*(TILT_DOFS if self.tilt else ()), *(j.name for j in self.joints)]

    @property
    def servos(self) -> list[tuple[str, str, str]]:
        """(MuJoCo joint, position servo, velocity servo) of each of :attr:`dofs`."""
        tilt = [(f"pusher_{d}", f"pusher_{d}", f"pusher_v{d}") for d in TILT_DOFS]
        out = tilt if self.tilt else []
        return out + [(f"pusher/{j.name}",) * 2 + (f"pusher/v/{j.name}",) for j in self.joints]


@dataclass
class PusherPaths:
    """What a replay of an exported robot pusher drives, per episode, at the end effector's
    stamps (the recording the engine fits with, ``robogs.physics.recording.load_recording``
    with ``split="none"``): the pusher point, its yaw and the servo DOFs.

    Attributes:
        pusher: the robot pusher measured over the recording.
        episodes: [E] episode ids.
        t_ns: per episode [N] int64 end-effector stamps (dataset clock).
        point: per episode [N, 3] m, the pusher point (``objects.pusher.offset_m`` applied).
        yaw: per episode [N] rad, the end effector's yaw, unwrapped.
        dofs: per episode [N, J] rad or m, :attr:`RobotPusher.dofs` (J may be 0).
    """

    pusher: RobotPusher
    episodes: list[str]
    t_ns: list[np.ndarray]
    point: list[np.ndarray]
    yaw: list[np.ndarray]
    dofs: list[np.ndarray]


def pusher_geometry(physics: Mapping[str, Any]) -> str:
    """``objects.pusher.geometry`` of a physics.json document (``primitive`` when absent).

    Raises:
        FormatError: another value.
    """
    pusher = (physics.get("objects") or {}).get("pusher") or {}
    value = pusher.get("geometry", "primitive") if isinstance(pusher, Mapping) else "primitive"
    if value not in PUSHER_GEOMETRIES:
        raise FormatError(
            f"objects.pusher.geometry is {value!r}",
            path="physics.json",
            where="objects/pusher/geometry",
            hint=f"one of {', '.join(PUSHER_GEOMETRIES)} (robot: the URDF's links push)",
        )
    return str(value)


def _quat(rot: np.ndarray) -> np.ndarray:
    """(w, x, y, z) unit quaternions of rotation matrices [..., 3, 3]."""
    from robogs.format.frames import matrix_to_quat_np

    return np.asarray(matrix_to_quat_np(rot), dtype=float)


def _find_body(bodies: Sequence[ET.Element], name: str) -> ET.Element | None:
    for b in bodies:
        for el in b.iter("body"):
            if el.get("name") == name:
                return el
    return None


def _pose_matrix(el: ET.Element) -> np.ndarray:
    """``T_body_geom`` of a geom element with ``pos`` and ``quat`` (w x y z)."""
    from robogs.format.frames import quat_to_matrix_np

    pos = [float(v) for v in (el.get("pos") or "0 0 0").split()]
    q = np.array([float(v) for v in (el.get("quat") or "1 0 0 0").split()])
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = quat_to_matrix_np(q), pos
    return out


def _vec(vs: Sequence[float]) -> str:
    return " ".join(repr(float(v)) for v in vs)


def robot_pusher_scene(scene: Any, rp: RobotPusher) -> tuple[Any, list[str]]:
    """Replace the primitive pusher of a scene document by the robot's collision geometry.

    Args:
        scene: a :class:`robogs.format.mjcf.MjcfScene` with a pusher.
        rp: the robot pusher.

    Returns:
        (a new scene: pusher body geoms, mesh assets, contact pairs, ``pairs``,
        ``pair_torsion``, ``table_pairs`` and notes rewritten, each ``<key>``'s qpos extended by the
        servo DOFs at :attr:`RobotPusher.start` (0 without one) and, with a start, its ctrl
        holding them there (:func:`_keys`); the names of the robot's pusher geoms,
        ``pusher/<link>/<k>``).

    Raises:
        InputError: the scene has no pusher, the links carry no collision geometry, or
            :attr:`RobotPusher.start` is not one finite value per DOF.
        FormatError: from :func:`robogs.format.mjcf_robot.robot_mjcf` (URDF or mesh refused).
    """
    import mujoco

    from robogs.format.mjcf_robot import robot_mjcf

    if scene.pusher is None:
        raise InputError(
            "objects.pusher.geometry is 'robot' but the scene has no pusher",
            where="objects/pusher",
            hint="declare objects.pusher (link, friction_dynamic)",
        )
    robot = robot_mjcf(rp.urdf, root=rp.root, package_roots=rp.package_roots, prefix=PREFIX)
    root = ET.fromstring(scene.xml)
    world = root.find("worldbody")
    body = next(b for b in world.iter("body") if b.get("name") == scene.pusher)
    old = [g for g in body.findall("geom") if (g.get("name") or "").startswith("pusher")]
    for g in old:
        body.remove(g)
    names: list[str] = []
    meshes: set[str] = set()
    carriers = _servo_bodies(root, body, rp)
    for link, t_pl in rp.frames.items():
        lb = _find_body(robot.bodies, robot.links.get(link, ""))
        if lb is None:
            continue
        carrier = carriers[rp.bodies.get(link, "")]
        for k, g in enumerate(el for el in lb.findall("geom") if el.get("group") == "3"):
            t = t_pl @ _pose_matrix(g)
            q = np.zeros(4)
            mujoco.mju_mat2Quat(q, t[:3, :3].reshape(-1).copy())
            attrs = {a: v for a, v in g.attrib.items() if a not in ("pos", "quat", "rgba")}
            name = f"pusher/{link}/{k}"
            attrs.update(name=name, pos=_vec(t[:3, 3]), quat=_vec(q), contype="0")
            attrs.update(conaffinity="0", group="1")
            ET.SubElement(carrier, "geom", **attrs)
            names.append(name)
            if g.get("mesh"):
                meshes.add(g.get("mesh"))
    if not names:
        raise InputError(
            "objects.pusher.geometry is 'robot' but the pusher "
            + (
                f"link {next(iter(rp.frames))!r} has"
                if len(rp.frames) == 1
                else f"links {', '.join(map(repr, rp.frames))} have"
            )
            + " no collision geometry in the URDF",
            path=rp.urdf,
            where="objects/pusher/geometry",
            hint="give the pusher link a <collision>, or use the primitive pusher "
            "(objects.pusher.geometry=primitive)",
        )
    assets = dict(scene.assets)
    if meshes:
        asset = root.find("asset")
        if asset is None:
            asset = ET.Element("asset")
            root.insert(list(root).index(world), asset)
        for m in robot.meshes:
            if m.get("name") in meshes:
                asset.append(m)
                assets[m.get("file")] = robot.files[m.get("file")]
    for j in rp.joints:  # after the geoms: each body's children stay in MJCF's usual order
        carriers[rp.bodies.get(j.parent, "")].append(carriers[j.name])
    pairs, torsion, moved = _pusher_pairs(root, scene, names)
    table = {o: [moved[i] for i in rows] for o, rows in scene.table_pairs.items()}
    used = [c for c in robot.conversions if c.file is None or c.file in assets]
    notes = [n for n in robot.notes if any(c.source.name in n for c in used)]
    notes.append(
        f"pusher: the robot's collision geometry of {', '.join(rp.frames)} ({len(names)} "
        f"geoms), carried by the pusher body (spread over the recording "
        f"{rp.spread_m * 1e3:.3g} mm, {np.degrees(rp.spread_rad):.3g} deg)"
    )
    if rp.dofs:
        notes.append(
            "pusher: servo-driven from the recording as well: "
            + ", ".join(
                [
                    *(["the end effector's pitch and roll (hinges on the pusher body)"] * rp.tilt),
                    *(f"joint {j.name} ({j.kind}, body pusher/{j.name})" for j in rp.joints),
                ]
            )
        )
    _keys(root, body, rp)
    ET.indent(root)
    out = replace(
        scene,
        xml=ET.tostring(root, encoding="unicode") + "\n",
        assets=assets,
        pairs=pairs,
        pair_torsion=torsion,
        table_pairs=table,
        notes=[*scene.notes, *rp.notes, *notes],
    )
    return out, names


def _keys(root: ET.Element, body: ET.Element, rp: RobotPusher) -> None:
    """Extend each ``<key>`` by the servo DOFs of ``rp``: ``qpos`` by their joints at
    :attr:`RobotPusher.start` (0 without one), and with a start a ``ctrl`` (the key's own, else
    zeros for the scene's actuators) whose DOF position servos hold that start (velocity servos
    0), so a scene reset to the key stays there. The DOFs' joints are the last of the document
    (the pusher body is the last body, its joint bodies below it), in MuJoCo's qpos order: the
    document order of the pusher body's subtree (bodies depth first, each body's joints in
    order), which need not be :attr:`RobotPusher.dofs`' order when joint bodies nest."""
    if not rp.dofs:
        return
    start = _start(rp)
    value = {j: float(v) for (j, _, _), v in zip(rp.servos, start, strict=True)}
    order = [el.get("name") for el in body.iter("joint") if el.get("name") in value]
    held = {pos: value[j] for j, pos, _ in rp.servos}
    for key in root.iter("key"):
        if key.get("qpos"):
            key.set("qpos", key.get("qpos") + "".join(f" {value[j]!r}" for j in order))
        if rp.start is not None:
            act = root.find("actuator")
            names = [a.get("name") for a in act] if act is not None else []
            ctrl = [float(v) for v in (key.get("ctrl") or "").split()]
            ctrl += [held.get(n, 0.0) for n in names[len(ctrl) :]]
            key.set("ctrl", _vec(ctrl))


def _start(rp: RobotPusher) -> list[float]:
    """:attr:`RobotPusher.start` checked (zeros without one)."""
    if rp.start is None:
        return [0.0] * len(rp.dofs)
    start = np.asarray(rp.start, dtype=float).reshape(-1)
    if len(start) != len(rp.dofs) or not np.isfinite(start).all():
        raise InputError(
            f"the robot pusher's start {list(start)} is not one finite value per servo DOF "
            f"({', '.join(rp.dofs)})",
            path=rp.urdf,
            where="objects/pusher/geometry",
            hint="give RobotPusher.start the recording's first value of each DOF in the order "
            "of RobotPusher.dofs, or leave it None (0)",
        )
    return [float(v) for v in start]


def _servo_bodies(root: ET.Element, body: ET.Element, rp: RobotPusher) -> dict[str, ET.Element]:
    """The moving DOFs of ``rp`` in the scene document: the tilt hinges ``pusher_pitch`` and
    ``pusher_roll`` inserted after the pusher body's yaw hinge (MuJoCo composes a body's joints
    in document order, each about its axis in the frame the previous ones left: ``Rz(yaw)
    Ry(pitch) Rx(roll)``, the order of :func:`ee_tilt`), and one body ``pusher/<joint>`` per
    modelled joint, placed at ``T_body_parentlink origin`` in its parent's body, with the
    joint (slide or hinge about the URDF axis, anchored at the body origin, value 0 at the
    URDF origin as in the chain), :data:`CHILD_MASS` and the joint's armature (the pusher's
    mass or yaw inertia). Each DOF gets the pusher's two servos (position ``<joint>``,
    velocity ``<joint>`` with ``v`` after the prefix: ``pusher_vpitch``, ``pusher/v/<joint>``)
    with the pusher's gains scaled to the DOF's inertia, appended after the other actuators.
    The joint bodies are returned unattached (the caller appends them once their geoms are
    in); ``""`` is the pusher body.

    With the tilt, the pusher body's rotational inertia becomes the three hinges' armature
    (its own inertia :data:`CHILD_MASS` times it): the joint-space inertia of ZYX hinges on a
    body of inertia ``I`` is ``J^T I J`` (``J`` the hinge axes in the world), which couples yaw
    and roll by ``I sin(pitch)``, so diagonal dead-beat servos would not track; armature is
    diagonal in joint space and has no Coriolis terms."""
    carriers = {"": body}
    if not rp.dofs:
        return carriers
    act = root.find("actuator")
    servo = {a.get("name"): a for a in act}
    mass = float(body.find("inertial").get("mass"))
    if rp.tilt:  # the rotational inertia moves into the hinges' armature (see the docstring)
        inertial = body.find("inertial")
        rot = [float(v) for v in inertial.get("diaginertia").split()]
        inertial.set("diaginertia", _vec([CHILD_MASS * v for v in rot]))
        yaw = next(j for j in body.findall("joint") if j.get("name") == "pusher_yaw")
        yaw.set("armature", repr(rot[2]))
        at = list(body).index(yaw)
        for k, (dof, axis) in enumerate(zip(TILT_DOFS, ("0 1 0", "1 0 0"), strict=True)):
            el = ET.Element("joint", name=f"pusher_{dof}", type="hinge", axis=axis)
            el.set("armature", repr(rot[1 - k]))
            body.insert(at + 1 + k, el)
    for j in rp.joints:
        t = rp.frames[j.parent] @ j.origin
        el = ET.Element(
            "body",
            name=f"pusher/{j.name}",
            pos=_vec(t[:3, 3]),
            quat=_vec(_quat(t[:3, :3])),
            gravcomp="1",
        )
        m = CHILD_MASS * mass
        ET.SubElement(el, "inertial", pos="0 0 0", mass=repr(m), diaginertia=_vec([0.01 * m] * 3))
        arm = mass if j.kind == "slide" else 0.01 * mass
        ET.SubElement(
            el, "joint", name=f"pusher/{j.name}", type=j.kind, axis=_vec(j.axis), armature=repr(arm)
        )
        carriers[j.name] = el
    slides = {f"pusher/{j.name}" for j in rp.joints if j.kind == "slide"}
    for joint, _, vel in rp.servos:
        slide = joint in slides
        ref = "x" if slide else "yaw"  # same inertia as the pusher's slide or yaw hinge
        scale = 1.0 + CHILD_MASS if joint.startswith("pusher/") else 1.0  # + the body's own
        for name, src, gain in ((joint, f"pusher_{ref}", "kp"), (vel, f"pusher_v{ref}", "kv")):
            attrs = dict(servo[src].attrib)
            attrs.update(name=name, joint=joint)
            attrs[gain] = repr(float(attrs[gain]) * scale)
            ET.SubElement(act, servo[src].tag, attrs)
    return carriers


def _pusher_pairs(
    root: ET.Element, scene: Any, names: list[str]
) -> tuple[list[tuple[str, str]], list[float], dict[int, int]]:
    """Each object-pusher ``<pair>`` becomes one pair per robot geom (same attributes, appended
    after the other pairs); a capsule's second end (``pusher_end``) goes. Returns the new
    ``pairs`` and ``pair_torsion`` (document order) and old row -> new row of the pairs kept."""
    contact = root.find("contact")
    kept: list[tuple[tuple[str, str], float]] = []
    added: list[tuple[tuple[str, str], float]] = []
    moved: dict[int, int] = {}
    for i, el in enumerate(list(contact) if contact is not None else []):
        ends = [a for a in ("geom1", "geom2") if el.get(a) in ("pusher", "pusher_end")]
        if not ends:
            moved[i] = len(kept)
            kept.append((scene.pairs[i], scene.pair_torsion[i]))
            continue
        contact.remove(el)
        if el.get(ends[0]) == "pusher_end":
            continue
        for n in names:
            new = ET.SubElement(contact, "pair", dict(el.attrib))
            new.set(ends[0], n)
            added.append(((new.get("geom1"), new.get("geom2")), scene.pair_torsion[i]))
    rows = kept + added
    return [p for p, _ in rows], [t for _, t in rows], moved

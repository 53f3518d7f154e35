"""The robot's own links as the MuJoCo pusher (``objects.pusher.geometry = "robot"``).

By default the MuJoCo engine pushes with a primitive (a sphere, capsule or box of
``objects.pusher``'s sizes at the end-effector pose). With ``objects.pusher.geometry = "robot"``
the pusher is the URDF's collision geometry of the pusher link (``objects.pusher.link``, else
the manifest's ``robot.ee_link``) and of every link below it in the chain (fingers, flange tool).

What does what:

* **The geometry** comes from :func:`robogs.format.mjcf_robot.robot_mjcf`: MuJoCo's URDF compiler
  reads the URDF, every mesh goes through its rule (an STL copied, other formats converted to
  OBJ; a mesh MuJoCo refuses kept with ``inertia="shell"``, else hulled, else dropped, each said
  in the notes). Only the collision geoms (URDF ``<collision>``) are used.
* **The pose**: the geoms are carried by the engine's pusher body, the heavy servo-driven body
  on slide x, y, z and a yaw hinge that follows the drive (the measured end effector resampled
  on the step grid as for the primitive: :func:`robogs.physics.prepare.build_drive`). Each link
  sits in the pusher frame (origin at the pusher point ``p = x_ee + R_ee offset_m``, axes the
  end effector's yaw) at ``T_pusher_link``, measured by forward kinematics of the recorded
  joints (:func:`robogs.physics.recording.load_recording`; with ``ee_poses`` only, the links
  below the pusher link must hang from it by fixed joints). So a link's pose at each step is
  the primitive's pose at that step composed with a constant transform, which is the forward
  kinematics pose exactly when that transform is constant over the recording: the end effector
  only yaws (its roll and pitch keep the value they had) and the joints below the pusher link do
  not move. The recording is checked (:func:`pusher_frames`): each link's largest displacement
  from its constant pose must stay within a budget derived from the dataset, its
  ``geometry.box3d_mm`` (the shape error it already accepts when a mesh is modelled as its box)
  plus three times the recording's own pose noise at that link. Within it, that is the whole
  model (one body, bit for bit as before moving links were modelled).
* **What moves is modelled** (:func:`pusher_model`; h78): a recording that moves the links more
  gets servo DOFs for the cause, the larger first, until every link stays within its budget in
  the body that carries it:

  - the end effector's roll and pitch: hinges ``pusher_pitch`` and ``pusher_roll`` on the
    pusher body after its yaw hinge. MuJoCo composes a body's joints in document order, each
    about its axis as the previous ones left it, so the body's orientation is ``Rz(yaw)
    Ry(pitch) Rx(roll)``: the ZYX angles of the end effector (:func:`ee_tilt`; the yaw is the
    drive's, :func:`robogs.physics.recording.yaw_of`), and the pusher frame becomes the end
    effector's full orientation at the pusher point (each pusher-body link at ``[I | -offset]
    T_ee_link``). Past :data:`GIMBAL_DEG` of pitch it is refused (gimbal lock);
  - a joint below the pusher link whose value varies (:func:`joint_value`, from the links'
    forward-kinematics poses, so a ``<mimic>`` is its own joint): its own body ``pusher/<joint>``,
    a child of the body that carries its parent link, placed at that link's pose times the
    joint origin, on a slide or hinge joint about the URDF axis (value 0 at the origin, as in
    :class:`robogs.format.kinematics.Chain`): the links below it that no other modelled joint
    moves ride on it. The simplest sound construction: MuJoCo's own joint tree reproduces the
    URDF's forward kinematics exactly (``robogs.format.mjcf_robot`` drives the exported robot
    the same way), the joint's velocity is real in the contact solver (a finger sliding along
    an object is friction on the relative motion), and no weld constraint is solved (a free
    body welded to a mocap target would lag by the weld's softness). Its mass is
    :data:`CHILD_MASS` of the pusher's and its inertia the joint's ``armature``;
  - every DOF has the pusher's two servos, gains scaled to its inertia, following the recorded
    values on the step grid (``Drive.pusher_dofs``, names :attr:`RobotPusher.dofs`, columns of
    :func:`dof_values`) through the pusher's knot smoothing
    (:func:`robogs.physics.engines.mujoco_engine.servo_dof_targets`).

  What is still not modelled: force-controlled closing and joint compliance (a finger is where
  the recording says, however hard the object pushes back), the force the fingers take along
  their own joints in the predicted pusher force, moving fingers in ``ee_poses``-only
  recordings (they need ``joint_states``). A link that strays with nothing left to model is
  refused naming the link, the amount and the budget (the primitive pusher is the fallback).
* **Why not mocap bodies**: MuJoCo gives a mocap body zero velocity in the contact solver, so
  the contact damping and the pusher friction would act against the object's motion instead of
  the relative sliding, and the pusher's strike and pushes would differ from the primitive's
  (the engine's docstring, :mod:`robogs.physics.engines.mujoco_engine`). Carried by the pusher
  body, a URDF sphere of the primitive's radius at the pusher point is the primitive:
  ``tests/physics/test_mujoco_robot_pusher.py`` checks the box trajectories agree within 1e-6 m.
* **Contacts**: robot geoms have ``contype = conaffinity = 0``; they touch only the objects,
  through one ``<pair>`` per (object, robot geom) with the primitive's settings (the primitive's
  pair copied: friction ``objects.pusher.friction_dynamic``, ``solref``, ``solimp``, onset
  ramp). No contact with the table, the other links or itself.

The engine receives the geometry as ``meshes["pusher"]`` (a :class:`RobotPusher`:
:meth:`robogs.physics.recording.Recording.shapes` puts it there, so every caller that passes
the shapes to the engine passes the robot too).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.budgets import DEFAULT_BUDGETS
from robogs.format.errors import FormatError, InputError
from robogs.format.shapes import BOX_BUDGET

__all__ = [
    "CHILD_MASS",
    "GIMBAL_DEG",
    "NOISE_FACTOR",
    "PUSHER_GEOMETRIES",
    "TILT_DOFS",
    "PusherJoint",
    "Rigidity",
    "RobotPusher",
    "distal_joints",
    "distal_links",
    "dof_values",
    "ee_tilt",
    "joint_value",
    "pose_noise",
    "pusher_frames",
    "pusher_geometry",
    "pusher_model",
    "pusher_reach",
    "robot_pusher_scene",
]

PUSHER_GEOMETRIES = ("primitive", "robot")
"""Values of ``objects.pusher.geometry`` (default ``primitive``)."""

NOISE_FACTOR = 3.0
"""The rigidity budget's noise allowance, in units of the recording's pose noise (the RMS norm
of the per-component noise: with two or three noisy components 4.2 or 5.2 standard deviations
of one, about the largest distance noise alone reaches over thousands of samples)."""

PREFIX = "robot/"
"""Name prefix of the robot's meshes, and of the moving joints' bodies, joints and servos, in
the scene document."""

TILT_DOFS = ("pitch", "roll")
"""The end effector's tilt DOFs (ZYX angles: ``R_ee = Rz(yaw) Ry(pitch) Rx(roll)``)."""

GIMBAL_DEG = 80.0
"""The largest |pitch| [deg] a modelled tilt may reach: at 90 deg yaw and roll turn about the
same axis (gimbal lock) and the recorded yaw (the heading of the end effector's x axis) is
undefined; at 80 deg a rotation rate shows up as yaw and roll rates 5.8x larger."""

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
class Rigidity:
    """How far the worst link strays from its constant pose in the pusher frame.

    Attributes:
        link: the link with the least margin (displacement minus budget).
        moved_m: its largest displacement [m]: position spread plus angle spread times the lever.
        budget_m: its budget [m]: ``geometry.box3d_mm`` plus :data:`NOISE_FACTOR` times the noise.
        spread_m, spread_rad: its largest position and angle distance from the constant pose.
        lever_m: the lever that turns the angle into a displacement [m].
        noise_m: the recording's pose noise at that link [m].
        cause: what moves it (the end effector's roll and pitch, or a joint below the link).
    """

    link: str
    moved_m: float
    budget_m: float
    spread_m: float
    spread_rad: float
    lever_m: float
    noise_m: float
    cause: str


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
        moved_m, budget_m: the worst link's displacement and its budget (:class:`Rigidity`).
        notes: what was said about the geometry (hulled meshes, which links).
        tilt: the end effector's pitch and roll are servo DOFs of the pusher body (hinges
            ``pusher_pitch``, ``pusher_roll`` after the yaw hinge); the pusher frame is then
            the end effector's full orientation at the pusher point.
        joints: the URDF joints below the pusher link that the recording moves, each the joint
            of its own servo-driven body (``robot/<joint>``), in the chain's order.
        bodies: link -> the body that carries it: ``""`` the pusher body, else the name of
            the nearest modelled joint above it; ``frames`` is then ``T_body_link`` (the joint
            body's frame is its child link's frame). Absent links: the pusher body.
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


def distal_links(chain: Any, link: str) -> list[str]:
    """``link`` and every link below it in ``chain`` (a
    :class:`robogs.format.kinematics.Chain`), in the chain's order."""
    k0 = chain.link_index(link)
    below = {k0}
    for k in range(k0 + 1, chain.num_links):
        if chain.parents[k] in below:
            below.add(k)
    return [chain.link_names[k] for k in sorted(below)]


def distal_joints(chain: Any, link: str) -> list[PusherJoint]:
    """The joints below ``link`` in ``chain`` (:func:`distal_links` without ``link``: the
    joint above each), in the chain's order."""
    out = []
    for name in distal_links(chain, link)[1:]:
        k = chain.link_index(name)
        kind = chain.joint_types[k - 1]
        out.append(
            PusherJoint(
                chain.tree_joint_names[k - 1],
                "fixed" if kind == "fixed" else "slide" if kind == "prismatic" else "hinge",
                chain.link_names[chain.parents[k]],
                name,
                np.array(chain.origins[k - 1], dtype=float),
                np.array(chain.axes[k - 1], dtype=float),
            )
        )
    return out


def joint_value(joint: PusherJoint, t_parent: np.ndarray, t_child: np.ndarray) -> np.ndarray:
    """The joint's value [K] (m, or rad unwrapped along the series) from its links' poses
    ``t_parent``, ``t_child`` [K, 4, 4] in any common frame: ``M = origin^-1 T_parent^-1
    T_child`` is the joint's motion, a translation ``v axis`` or a rotation of ``v`` about
    ``axis`` (``sin v = axis . vee(M - M^T) / 2``, ``cos v = (trace M - 1) / 2``)."""
    m = np.linalg.inv(joint.origin) @ np.linalg.inv(t_parent) @ t_child
    if joint.kind == "slide":
        return m[:, :3, 3] @ joint.axis
    r = m[:, :3, :3]
    vee = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], -1)
    return np.unwrap(np.arctan2(0.5 * vee @ joint.axis, 0.5 * (np.trace(r, axis1=1, axis2=2) - 1)))


def ee_tilt(ee_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pitch and roll [N] rad of end-effector orientations [N, 3, 3] (``R = Rz(yaw) Ry(pitch)
    Rx(roll)``, the yaw of :func:`robogs.physics.recording.yaw_of`): ``pitch = atan2(-R20,
    hypot(R21, R22))``, ``roll = atan2(R21, R22)`` unwrapped along the series (a tool pointing
    down has roll near pi)."""
    r = np.asarray(ee_rot, dtype=float)
    pitch = np.arctan2(-r[:, 2, 0], np.hypot(r[:, 2, 1], r[:, 2, 2]))
    return pitch, np.unwrap(np.arctan2(r[:, 2, 1], r[:, 2, 2]))


def dof_values(
    rp: RobotPusher, ee_rot: np.ndarray, links: Mapping[str, np.ndarray] | None = None
) -> np.ndarray:
    """The robot pusher's servo DOFs (:attr:`RobotPusher.dofs`) over a stretch of motion:
    [N, J] rad or m, from the end effector's orientations ``ee_rot`` [N, 3, 3] and, for the
    modelled joints, the links' poses ``links`` (name -> [N, 4, 4], any common frame, at the
    same N stamps)."""
    cols: list[np.ndarray] = []
    if rp.tilt:
        cols += list(ee_tilt(ee_rot))
    for j in rp.joints:
        if links is None or j.parent not in links or j.child not in links:
            raise InputError(
                f"the robot pusher's joint {j.name!r} moves but its links' poses were not given",
                where="objects/pusher/geometry",
                hint="record joint_states (forward kinematics gives the links' poses)",
            )
        cols.append(joint_value(j, np.asarray(links[j.parent]), np.asarray(links[j.child])))
    n = len(np.asarray(ee_rot))
    return np.stack(cols, -1) if cols else np.zeros((n, 0))


def pusher_model(
    ee_rot: np.ndarray,
    offset: Sequence[float] | None,
    links_in_ee: Mapping[str, np.ndarray],
    joints: Sequence[PusherJoint] = (),
    *,
    budget_mm: float = DEFAULT_BUDGETS[BOX_BUDGET].value,
    reach_m: float = 0.0,
    where: str = "recording",
) -> tuple[dict[str, np.ndarray], dict[str, str], bool, list[PusherJoint], Rigidity]:
    """What of the robot pusher must move: :func:`pusher_frames`' links, with the DOFs that
    make them stray over their budget modelled instead of refused.

    When every link stays within its budget in the pusher frame this is :func:`pusher_frames`
    (the one pusher body, bit for bit). Otherwise, while the worst link (largest displacement
    over budget) strays, the larger of its two causes is modelled:

    * the end effector's roll and pitch (its part ``d_ee + a_ee lever``): ``tilt``, two hinge
      servos on the pusher body, whose frame then is the end effector's orientation at the
      pusher point, so each pusher-body link sits at ``[I | -offset] T_ee_link``;
    * the joints below the pusher link (its own part ``d + a lever``, relative to the body
      that carries it): every joint on its path up to that body whose value varies over the
      recording (:func:`joint_value`) gets its own body, which carries the links below it
      that no other modelled joint moves (``T_body_link`` their mean pose in it).

    The same budget (``geometry.box3d_mm`` plus :data:`NOISE_FACTOR` times the pose noise)
    then holds for every link in its body.

    Args:
        ee_rot, offset, links_in_ee, budget_mm, reach_m, where: as :func:`pusher_frames`.
        joints: the joints below the pusher link (:func:`distal_joints`): without them only
            the tilt can be modelled.

    Returns:
        (link -> ``T_body_link`` [4, 4], link -> body (``""``: the pusher body, else a joint
        name), tilt, the modelled joints in the order of ``joints``, the worst link's
        :class:`Rigidity` in its body).

    Raises:
        InputError: a link strays over its budget with nothing left to model (the message as
            :func:`pusher_frames`'), or the modelled tilt comes within 90 - :data:`GIMBAL_DEG`
            deg of gimbal lock.
    """
    frames, worst = _rigid_frames(ee_rot, offset, links_in_ee, budget_mm, reach_m)
    if worst.moved_m <= worst.budget_m:
        return frames, {n: "" for n in frames}, False, [], worst
    rel = {n: np.asarray(v, dtype=float).reshape(-1, 4, 4) for n, v in links_in_ee.items()}
    above = {j.child: j for j in joints}
    moves = {
        j.name
        for j in joints
        if j.kind != "fixed"
        and j.parent in rel
        and j.child in rel
        and np.ptp(joint_value(j, rel[j.parent], rel[j.child])) > 1e-12
    }
    mean_pe, d_pe, a_pe, n_pos_pe, n_rot_pe = _ee_part(ee_rot, offset)
    off = np.zeros(3) if offset is None else np.asarray(offset, dtype=float)
    t_be = np.eye(4)
    t_be[:3, 3] = -off  # T_body_ee with the tilt modelled
    tilt, modelled = False, set()
    for _ in range(len(joints) + 2):
        bodies: dict[str, str] = {}
        paths: dict[str, list[str]] = {}
        for n in rel:
            path, link = [], n
            while link in above and above[link].name not in modelled:
                if above[link].name in moves:
                    path.append(above[link].name)
                link = above[link].parent
            bodies[n] = above[link].name if link in above else ""
            paths[n] = path
        worst, parts = None, (0.0, 0.0)
        for n, t in rel.items():
            b = bodies[n]
            on_pusher = b == ""
            if on_pusher:
                t_in = t
            else:
                t_in = np.linalg.inv(rel[_child_of(above, b)]) @ t
            mean, dp, dr = _spread(t_in)
            ee_part = on_pusher and not tilt
            frames[n] = (mean_pe if ee_part else t_be if on_pusher else np.eye(4)) @ mean
            d = float(np.linalg.norm(dp, axis=1).max())
            a = float(np.linalg.norm(dr, axis=1).max())
            lever = float(np.linalg.norm(frames[n][:3, 3])) + float(reach_m)
            dp_e, ap_e = (d_pe, a_pe) if ee_part else (0.0, 0.0)
            np_e, nr_e = (n_pos_pe, n_rot_pe) if ee_part else (0.0, 0.0)
            noise = float(np.hypot(np_e, pose_noise(dp)) + lever * np.hypot(nr_e, pose_noise(dr)))
            own, tilt_part = d + a * lever, dp_e + ap_e * lever
            rig = Rigidity(
                n,
                moved_m=own + tilt_part,
                budget_m=budget_mm * 1e-3 + NOISE_FACTOR * noise,
                spread_m=dp_e + d,
                spread_rad=ap_e + a,
                lever_m=lever,
                noise_m=noise,
                cause="a joint below the pusher link moves"
                if own > tilt_part
                else "the end effector rolls or pitches",
            )
            if worst is None or rig.moved_m - rig.budget_m > worst.moved_m - worst.budget_m:
                worst, parts = rig, (own, tilt_part)
        assert worst is not None
        if worst.moved_m <= worst.budget_m:
            break
        own, tilt_part = parts
        path = paths[worst.link]
        if path and (own >= tilt_part or tilt):
            modelled |= set(path)
        elif tilt_part > 0 and not tilt:
            tilt = True
        elif path:
            modelled |= set(path)
        else:
            raise _refusal(worst, budget_mm, where)
    else:  # pragma: no cover - each pass models at least one DOF more
        raise _refusal(worst, budget_mm, where)
    if tilt:
        pitch, _ = ee_tilt(np.asarray(ee_rot, dtype=float))
        top = float(np.degrees(np.abs(pitch).max()))
        if top > GIMBAL_DEG:
            raise InputError(
                f"objects.pusher.geometry 'robot': the end effector pitches to {top:.1f} deg "
                f"over the {where}, within {90 - GIMBAL_DEG:g} deg of gimbal lock (its x axis "
                "vertical: its yaw, the heading of that axis, is undefined)",
                where="objects/pusher/geometry",
                hint="keep the end effector's x axis out of the vertical (choose a pusher link "
                "whose x axis stays horizontal: objects.pusher.link), or use the primitive "
                "pusher (objects.pusher.geometry=primitive)",
            )
    kept = [j for j in joints if j.name in modelled]
    return frames, bodies, tilt, kept, worst


def _child_of(above: Mapping[str, PusherJoint], joint: str) -> str:
    """The child link of the joint named ``joint`` among ``above`` (child link -> joint)."""
    return next(c for c, j in above.items() if j.name == joint)


def _spread(T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean pose of poses ``T`` [N, 4, 4] (rotation: the mean projected onto SO(3)) and each
    pose's deviation from it: position [N, 3] m and rotation vector [N, 3] rad (axis times
    angle of ``R_mean^T R``)."""
    t = T[:, :3, 3].mean(0)
    u, _, vt = np.linalg.svd(T[:, :3, :3].mean(0))
    r = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    mean = np.eye(4)
    mean[:3, :3], mean[:3, 3] = r, t
    rel = r.T @ T[:, :3, :3]
    axis = np.stack(
        [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], -1
    )
    norm = np.linalg.norm(axis, axis=1, keepdims=True)  # 2 sin(angle)
    ang = np.arctan2(norm[:, 0] / 2.0, (np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0)
    rotvec = np.where(norm > 1e-300, axis / np.maximum(norm, 1e-300), 0.0) * ang[:, None]
    return mean, T[:, :3, 3] - t, rotvec


def pose_noise(x: np.ndarray) -> float:
    """The white noise in a sampled series ``x`` [N, 3] about a smooth path: RMS norm of the
    per-component standard deviation estimated from second differences (``x[i+1] - 2 x[i] +
    x[i-1]`` has variance 6 sigma^2 for white noise, while a smooth path's second difference is
    its curvature times the step squared; the median absolute value, scaled by 1.4826, keeps a
    few jumps, such as the seams between concatenated episodes, out). Zero for fewer than three
    samples (:func:`robogs.physics.noise.second_difference_sigma` per component)."""
    from robogs.physics.noise import second_difference_sigma

    x = np.asarray(x, dtype=float).reshape(len(x), -1)
    return float(np.sqrt(sum(second_difference_sigma(c) ** 2 for c in x.T)))


def pusher_reach(pusher: Mapping[str, Any]) -> float:
    """Half extent [m] of the primitive ``objects.pusher`` (physics init fits it to the pusher
    links' collision geometry): ``radius_m + length_m / 2`` for a sphere or capsule, the half
    diagonal for a box of half size ``radius_m`` (long side ``length_m``)."""
    r = float(pusher.get("radius_m") or 0.0)
    half = 0.5 * float(pusher.get("length_m") or 0.0)
    if pusher.get("shape") == "box":
        return float(np.sqrt(2.0 * r * r + max(half, r) ** 2))
    return r + half


def _yaw_rot(yaw: np.ndarray) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros((*np.shape(yaw), 3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def pusher_frames(
    ee_rot: np.ndarray,
    offset: Sequence[float] | None,
    links_in_ee: Mapping[str, np.ndarray],
    *,
    budget_mm: float = DEFAULT_BUDGETS[BOX_BUDGET].value,
    reach_m: float = 0.0,
    where: str = "recording",
) -> tuple[dict[str, np.ndarray], Rigidity]:
    """The links' constant poses in the pusher frame, checked against a recording (the rigid
    check alone; :func:`pusher_model` models what strays instead of refusing it).

    The engine carries each link at one pose in the pusher frame (the mean over the recording);
    the recorded forward-kinematics poses stray from it where the end effector rolls or pitches
    (``T_pusher_ee`` changes) or a joint below the pusher link moves (``T_ee_link`` changes).
    For each link the largest displacement of its geometry from the constant pose is bounded by

        moved = (d_ee + d_link) + (a_ee + a_link) * lever,

    with ``d`` the largest position distance and ``a`` the largest angle [rad] of a pose from
    its mean (of ``T_pusher_ee`` and of ``T_ee_link``), and ``lever`` the link origin's distance
    from the pusher point plus ``reach_m`` (the pusher geometry's half extent,
    :func:`pusher_reach`). The rule: ``moved <= budget`` where

        budget = geometry.box3d_mm + NOISE_FACTOR * noise,

    ``geometry.box3d_mm`` the dataset's budget for modelling a shape by a simpler one (the same
    that lets an object's mesh be its box, :mod:`robogs.format.shapes`), and ``noise`` the
    recording's own pose noise at the link (:func:`pose_noise` of both poses' position and, times
    the lever, rotation deviations), so that a rigid robot recorded with a noisy end-effector
    orientation is not refused for its noise.

    Args:
        ee_rot: [N, 3, 3] the end effector's orientations ``R_world_ee`` over the recording.
        offset: the pusher point in the end-effector frame [m] (``objects.pusher.offset_m``).
        links_in_ee: link name -> ``T_ee_link`` [K, 4, 4] (m) over the recording (K >= 1).
        budget_mm: the dataset's ``geometry.box3d_mm`` [mm].
        reach_m: the pusher geometry's half extent [m].
        where: what the recording is, for the error.

    Returns:
        (link -> mean ``T_pusher_link`` [4, 4], the worst link's :class:`Rigidity`).

    Raises:
        InputError: a link's displacement exceeds its budget (the message names the link, the
            displacement, its parts and the budget; the hint the fixes).
    """
    frames, worst = _rigid_frames(ee_rot, offset, links_in_ee, budget_mm, reach_m)
    if worst.moved_m > worst.budget_m:
        raise _refusal(worst, budget_mm, where)
    return frames, worst


def _ee_part(
    ee_rot: np.ndarray, offset: Sequence[float] | None
) -> tuple[np.ndarray, float, float, float, float]:
    """``T_pusher_ee`` = Rz(-yaw) [R_ee | -R_ee off] over the recording: its mean pose, largest
    position and angle distance from it [m, rad], and the noise of both (:func:`pose_noise`)."""
    from robogs.physics.recording import yaw_of

    rot = np.asarray(ee_rot, dtype=float)
    quat = _quat(rot)
    off = np.zeros(3) if offset is None else np.asarray(offset, dtype=float)
    r_yaw_t = np.swapaxes(_yaw_rot(yaw_of(quat)), -1, -2)
    t_pe = np.zeros((len(rot), 4, 4))  # T_pusher_ee = Rz(-yaw) [R_ee | -R_ee off]
    t_pe[:, :3, :3] = r_yaw_t @ rot
    t_pe[:, :3, 3] = -(t_pe[:, :3, :3] @ off)
    t_pe[:, 3, 3] = 1.0
    mean_pe, dp_pe, dr_pe = _spread(t_pe)
    d_pe = float(np.linalg.norm(dp_pe, axis=1).max())
    a_pe = float(np.linalg.norm(dr_pe, axis=1).max())
    return mean_pe, d_pe, a_pe, pose_noise(dp_pe), pose_noise(dr_pe)


def _rigid_frames(
    ee_rot: np.ndarray,
    offset: Sequence[float] | None,
    links_in_ee: Mapping[str, np.ndarray],
    budget_mm: float,
    reach_m: float,
) -> tuple[dict[str, np.ndarray], Rigidity]:
    """:func:`pusher_frames` without the refusal: the frames and the worst link."""
    mean_pe, d_pe, a_pe, n_pos_pe, n_rot_pe = _ee_part(ee_rot, offset)
    frames: dict[str, np.ndarray] = {}
    worst: Rigidity | None = None
    for name, rel in links_in_ee.items():
        mean_el, dp, dr = _spread(np.asarray(rel, dtype=float).reshape(-1, 4, 4))
        frames[name] = mean_pe @ mean_el
        d = float(np.linalg.norm(dp, axis=1).max())
        a = float(np.linalg.norm(dr, axis=1).max())
        lever = float(np.linalg.norm(frames[name][:3, 3])) + float(reach_m)
        noise = float(
            np.hypot(n_pos_pe, pose_noise(dp)) + lever * np.hypot(n_rot_pe, pose_noise(dr))
        )
        own = d + a * lever
        cause = (
            "a joint below the pusher link moves"
            if own > d_pe + a_pe * lever
            else "the end effector rolls or pitches"
        )
        rig = Rigidity(
            name,
            moved_m=d_pe + d + (a_pe + a) * lever,
            budget_m=budget_mm * 1e-3 + NOISE_FACTOR * noise,
            spread_m=d_pe + d,
            spread_rad=a_pe + a,
            lever_m=lever,
            noise_m=noise,
            cause=cause,
        )
        if worst is None or rig.moved_m - rig.budget_m > worst.moved_m - worst.budget_m:
            worst = rig
    if worst is None:
        raise InputError(
            "objects.pusher.geometry 'robot': no pusher link", where="objects/pusher/link"
        )
    return frames, worst


def _refusal(w: Rigidity, budget_mm: float, where: str) -> InputError:
    """The error for a link that strays over its budget (:func:`pusher_frames`)."""
    return InputError(
        f"objects.pusher.geometry 'robot': link {w.link!r} strays over the {where} by "
        f"{w.moved_m * 1e3:.2f} mm from its constant pose in the pusher frame "
        f"({w.spread_m * 1e3:.2f} mm and {np.degrees(w.spread_rad):.2f} deg at a "
        f"{w.lever_m * 1e3:.1f} mm lever; {w.cause}), over its budget "
        f"{w.budget_m * 1e3:.2f} mm ({BOX_BUDGET} {budget_mm:g} mm + {NOISE_FACTOR:g} x "
        f"the recording's pose noise {w.noise_m * 1e3:.2f} mm)",
        where="objects/pusher/geometry",
        hint="the robot pusher follows the end effector's position and yaw with the links "
        "below it fixed: hold those joints and the end effector's roll and pitch still, "
        f"accept a coarser pusher (a larger {BOX_BUDGET} in the manifest's budgets), or use "
        "the primitive pusher (robogs physics set DATASET objects.pusher.geometry=primitive)",
    )


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
        ``pair_torsion``, ``table_pairs`` and notes rewritten; the names of the robot's pusher
        geoms, ``pusher/<link>/<k>``).

    Raises:
        InputError: the scene has no pusher, or the links carry no collision geometry.
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

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
    forward-kinematics poses, so a ``<mimic>`` is its own joint whose recorded value is its
    leader's through the URDF, ``multiplier q + offset`` as
    :class:`robogs.format.kinematics.Chain` applies it; the Franka Panda's fingers,
    ``tests/physics/test_mujoco_robot_panda.py``): its own body ``pusher/<joint>``, a child of
    the body that carries its parent link, placed at that link's pose times the
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

The document is written by :func:`robogs.format.mjcf_pusher.robot_pusher_scene` (with the
records :class:`RobotPusher` and :class:`PusherJoint`, re-exported here): ``robogs export mjcf``
writes the same pusher with the same function (h80), so it lives in ``robogs.format``; this
module measures what that writer places.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robogs.format.budgets import DEFAULT_BUDGETS
from robogs.format.errors import InputError
from robogs.format.mjcf_pusher import (
    CHILD_MASS,
    PUSHER_GEOMETRIES,
    TILT_DOFS,
    PusherJoint,
    RobotPusher,
    _quat,
    pusher_geometry,
    robot_pusher_scene,
)
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

NOISE_FACTOR = 3.0
"""The rigidity budget's noise allowance, in units of the recording's pose noise (the RMS norm
of the per-component noise: with two or three noisy components 4.2 or 5.2 standard deviations
of one, about the largest distance noise alone reaches over thousands of samples)."""

GIMBAL_DEG = 80.0
"""The largest |pitch| [deg] a modelled tilt may reach: at 90 deg yaw and roll turn about the
same axis (gimbal lock) and the recorded yaw (the heading of the end effector's x axis) is
undefined; at 80 deg a rotation rate shows up as yaw and roll rates 5.8x larger."""


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

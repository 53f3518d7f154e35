"""Measured data of a rigid-object scene, in memory: one :class:`Recording` of trajectories.

A recording is what the physics engine compares the model with. It can come from a robogs
dataset (:func:`load_recording`: one trajectory per episode) or from any object with the same
attribute names (:func:`as_recording`), e.g. the hidden-effect scenario generator in
``robogs.synth.scenarios`` which builds its own, independent, dataclasses.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from robogs.format.budgets import DEFAULT_BUDGETS
from robogs.format.errors import FormatError, InputError

__all__ = [
    "ObjectTrack",
    "Trajectory",
    "Recording",
    "as_recording",
    "load_recording",
    "check_finite",
    "yaw_of",
    "link_frames",
    "with_robot_pusher",
    "commanded_robot_pusher",
]


class ObjectTrack(NamedTuple):
    """Measured poses of one more tracked object of a trajectory: stamps [K] int64 ns,
    T_world_object translation [K, 3] m and rotation [K, 4] (w, x, y, z)."""

    t_ns: np.ndarray
    pos: np.ndarray
    quat: np.ndarray


@dataclass
class Trajectory:
    """One trajectory (episode) of one object pushed or carried by the end effector.

    Attributes:
        name: episode id.
        t_ns: object-pose stamps [N] int64 ns (camera / tracker clock as recorded).
        object_pos: T_world_object translation [N, 3] m.
        object_quat: T_world_object rotation [N, 4] (w, x, y, z).
        ee_t_ns: end-effector stamps [E] int64 ns (encoder clock).
        ee_pos: T_world_ee translation [E, 3] m (centre of the pusher sphere).
        ee_quat: T_world_ee rotation [E, 4] (w, x, y, z).
        grasp: grasp flag at ``ee_t_ns`` [E] bool (object attached to the EE while True).
        kind: free text describing the motion (``push``, ``release_slide``, ``grasp_place``).
        wrench_t_ns: optional force-sensor stamps [W] int64 ns.
        wrench_force: optional measured force on the tool [W, 3] N, world axes (the force the
            environment exerts on the sensor, offset included: :mod:`robogs.physics.prepare`
            removes it using the samples out of contact).
        others: the poses of the other tracked objects of the scene, by physics.json name
            (e.g. a box the pushed one strikes); empty for a one-object scene.
        pusher_dofs: optional [E, J] at ``ee_t_ns`` (rad or m): the robot pusher's servo DOFs
            beyond position and yaw (``Recording.robot_pusher.dofs``: the end effector's pitch
            and roll, the joints below the pusher link that move); None: none move.
    """

    name: str
    t_ns: np.ndarray
    object_pos: np.ndarray
    object_quat: np.ndarray
    ee_t_ns: np.ndarray
    ee_pos: np.ndarray
    ee_quat: np.ndarray
    grasp: np.ndarray
    kind: str = ""
    wrench_t_ns: np.ndarray | None = None
    wrench_force: np.ndarray | None = None
    others: dict[str, ObjectTrack] = field(default_factory=dict)
    pusher_dofs: np.ndarray | None = None


@dataclass
class Recording:
    """Trajectories plus the nominal physics (a physics.json document) they were taken with.

    Attributes:
        trajectories: the measured trajectories.
        physics: physics.json content; ``objects[object_name]`` is the box, ``objects["table"]``
            has ``plane_z_m``, ``objects["pusher"]`` has ``radius_m`` and ``link``.
        object_name: the free object (the one the pusher drives; effects act on it).
        meta: free-form information (e.g. the scenario's hidden effect, for benches only).
        meshes: rigid object name -> ``trimesh.Trimesh`` (object frame, m) from the dataset's
            assets (:func:`robogs.format.shapes.load_object_meshes`); empty for recordings
            without assets. Which of them reach the engines: :meth:`shapes`.
        box_budget_mm: the dataset's ``geometry.box3d_mm``, within which a mesh is its box.
        robot_pusher: with ``objects.pusher.geometry = "robot"``, the robot's pusher links
            (:class:`robogs.physics.engines.mujoco_robot.RobotPusher`: the URDF and each link's
            pose in the pusher frame, measured over the recording); None otherwise.
    """

    trajectories: list[Trajectory]
    physics: dict[str, Any]
    object_name: str = "box"
    meta: dict[str, Any] = field(default_factory=dict)
    meshes: dict[str, Any] = field(default_factory=dict)
    box_budget_mm: float = DEFAULT_BUDGETS["geometry.box3d_mm"].value
    robot_pusher: Any = None

    def shapes(self) -> Any:
        """The object meshes that are not their ``size_m`` box, with the notes to print
        (:func:`robogs.format.shapes.object_shapes`); with a robot pusher also
        ``meshes["pusher"]``, the :attr:`robot_pusher` (the MuJoCo engine takes it from there)."""
        from robogs.format.shapes import object_shapes

        out = object_shapes(self.physics, self.meshes, self.box_budget_mm)
        return with_robot_pusher(out, self.robot_pusher)

    @property
    def tracked(self) -> list[str]:
        """Names of the other tracked objects (:attr:`Trajectory.others`), in first-seen order."""
        out: list[str] = []
        for tr in self.trajectories:
            out += [n for n in tr.others if n not in out]
        return out


_TRAJ_FIELDS = ("t_ns", "object_pos", "object_quat", "ee_t_ns", "ee_pos", "ee_quat", "grasp")


def yaw_of(quat: np.ndarray) -> np.ndarray:
    """Yaw [rad] of (w, x, y, z) quaternions [..., 4]: heading of the rotated x axis."""
    w, x, y, z = (quat[..., i] for i in range(4))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def check_finite(rec: Recording) -> None:
    """Raise :class:`InputError` naming the stream and the stamp of the first NaN or inf."""
    for tr in rec.trajectories:
        checks = [
            ("object_poses", tr.t_ns, (tr.object_pos, tr.object_quat)),
            ("ee_poses", tr.ee_t_ns, (tr.ee_pos, tr.ee_quat)),
        ]
        checks += [(f"object_poses[{n}]", o.t_ns, (o.pos, o.quat)) for n, o in tr.others.items()]
        for stream, stamps, arrays in checks:
            for arr in arrays:
                bad = ~np.isfinite(np.asarray(arr, dtype=float)).all(axis=-1)
                if bad.any():
                    i = int(np.argmax(bad))
                    t = int(stamps[i])
                    raise InputError(
                        f"non-finite value in {stream} at t_ns={t} "
                        f"(t={1e-9 * (t - int(stamps[0])):.3f} s into the episode)",
                        where=f"episodes/{tr.name}/{stream}",
                        hint="drop or repair the sample before comparing with the model",
                    )
        if tr.wrench_t_ns is not None:
            bad = ~np.isfinite(tr.wrench_force).all(axis=-1)
            if bad.any() or len(tr.wrench_t_ns) != len(tr.wrench_force):
                raise InputError(
                    "non-finite or misaligned wrench samples"
                    + (f" at t_ns={int(tr.wrench_t_ns[int(np.argmax(bad))])}" if bad.any() else ""),
                    where=f"episodes/{tr.name}/wrenches",
                    hint="drop or repair the samples before comparing with the model",
                )
        streams = [("object_poses", tr.t_ns), ("ee_poses", tr.ee_t_ns)]
        streams += [(f"object_poses[{n}]", o.t_ns) for n, o in tr.others.items()]
        if tr.wrench_t_ns is not None and len(tr.wrench_t_ns):
            streams.append(("wrenches", tr.wrench_t_ns))
        for stream, stamps in streams:
            if len(stamps) < 2 and stream != "wrenches":
                raise InputError(
                    f"{stream} has fewer than 2 samples", where=f"episodes/{tr.name}/{stream}"
                )
            if np.any(np.diff(stamps) <= 0):
                i = int(np.argmax(np.diff(stamps) <= 0))
                raise InputError(
                    f"{stream} stamps are not increasing at t_ns={int(stamps[i + 1])}",
                    where=f"episodes/{tr.name}/{stream}",
                    hint="sort the table by t_ns and drop duplicates",
                )


def as_recording(obj: Any) -> Recording:
    """Copy any recording-like object (same attribute names) into a :class:`Recording`."""
    if isinstance(obj, Recording):
        rec = obj
    else:
        trajs = []
        for t in obj.trajectories:
            trajs.append(
                Trajectory(
                    name=str(t.name),
                    **{f: np.asarray(getattr(t, f)) for f in _TRAJ_FIELDS},
                    kind=str(getattr(t, "kind", "")),
                    wrench_t_ns=getattr(t, "wrench_t_ns", None),
                    wrench_force=getattr(t, "wrench_force", None),
                    others=dict(getattr(t, "others", None) or {}),
                    pusher_dofs=getattr(t, "pusher_dofs", None),
                )
            )
        rec = Recording(
            trajectories=trajs,
            physics=dict(obj.physics),
            object_name=str(getattr(obj, "object_name", "box")),
            meta=dict(getattr(obj, "meta", {}) or {}),
            meshes=dict(getattr(obj, "meshes", None) or {}),
            box_budget_mm=float(
                getattr(obj, "box_budget_mm", DEFAULT_BUDGETS["geometry.box3d_mm"].value)
            ),
            robot_pusher=getattr(obj, "robot_pusher", None),
        )
    for t in rec.trajectories:
        t.t_ns = np.asarray(t.t_ns, dtype=np.int64)
        t.ee_t_ns = np.asarray(t.ee_t_ns, dtype=np.int64)
        t.grasp = np.asarray(t.grasp, dtype=bool)
        if (t.wrench_t_ns is None) != (t.wrench_force is None):
            raise InputError(
                "a trajectory has wrench stamps without forces or forces without stamps",
                where=f"episodes/{t.name}/wrenches",
            )
        if t.wrench_t_ns is not None:
            t.wrench_t_ns = np.asarray(t.wrench_t_ns, dtype=np.int64)
            t.wrench_force = np.asarray(t.wrench_force, dtype=float).reshape(-1, 3)
        t.others = {str(n): _track(o, t.name, str(n)) for n, o in (t.others or {}).items()}
    _check_tracked(rec)
    check_finite(rec)
    return rec


def _track(obj: Any, episode: str, name: str) -> ObjectTrack:
    """An :class:`ObjectTrack` from ``(t_ns, pos, quat)``; InputError on mismatched shapes."""
    t_ns, pos, quat = obj
    o = ObjectTrack(
        np.asarray(t_ns, dtype=np.int64),
        np.asarray(pos, dtype=float).reshape(-1, 3),
        np.asarray(quat, dtype=float).reshape(-1, 4),
    )
    if not len(o.t_ns) == len(o.pos) == len(o.quat):
        raise InputError(
            f"object {name!r}: {len(o.t_ns)} stamps, {len(o.pos)} positions, "
            f"{len(o.quat)} orientations",
            where=f"episodes/{episode}/object_poses",
            hint="one pose per stamp",
        )
    return o


def _check_tracked(rec: Recording) -> None:
    """Every other tracked object is a rigid object of physics.json (not the free object) and
    is tracked in every trajectory (its measured start pose places it in the model)."""
    objects = rec.physics.get("objects") or {}
    for name in rec.tracked:
        entry = objects.get(name)
        rigid = isinstance(entry, dict) and entry.get("equation") == "rigid"
        if name == rec.object_name or not rigid:
            raise InputError(
                f"tracked object {name!r} is not another rigid object of physics.json",
                where=f"objects/{name}",
                hint="declare it with equation 'rigid', size_m and mass_kg, or drop its poses",
            )
        for tr in rec.trajectories:
            if name not in tr.others or len(tr.others[name].t_ns) < 2:
                raise InputError(
                    f"object {name!r} is tracked in some trajectories but not in {tr.name!r}",
                    where=f"episodes/{tr.name}/object_poses",
                    hint=f"record {name!r} in every episode (at least 2 poses), or in none",
                )


def _pose_columns(table: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    pos = np.stack([table.column(c).to_numpy().astype(float) for c in ("x", "y", "z")], axis=-1)
    quat = np.stack(
        [table.column(c).to_numpy().astype(float) for c in ("qw", "qx", "qy", "qz")], axis=-1
    )
    return t, pos, quat


def _require_stream(ds: Any, ep: Any, stream: str, problem: str, hint: str) -> None:
    """FormatError ``episode <id> <problem>`` when episode ``ep`` lacks ``stream``."""
    if not ep.has(stream):
        raise FormatError(
            f"episode {ep.id!r} {problem}",
            path=ds.manifest_path,
            where=f"episodes/{ep.id}",
            hint=hint,
        )


def _robot_chain(ds: Any, physics: dict[str, Any], ee_link: Any, episode: str) -> Any:
    """The robot's forward kinematics with the fitted joint offsets, to drive the end effector
    from ``joint_states`` when an episode has no ``ee_poses``."""
    from robogs.format.kinematics import Chain, fitted_chain

    robot = ds.manifest.get("robot") or {}
    if not isinstance(robot.get("urdf"), str) or not isinstance(ee_link, str):
        raise FormatError(
            f"episode {episode!r} has no ee_poses stream, and no robot URDF with an end-effector "
            "link to compute it from joint_states",
            path=ds.manifest_path,
            where=f"episodes/{episode}",
            hint="record ee_poses, or declare robot.urdf and robot.ee_link (or objects.pusher.link)",
        )
    chain = Chain.from_urdf(ds.urdf(load_meshes=False), floating_as_fixed=True)
    if ee_link not in chain.link_names:
        raise FormatError(
            f"end-effector link {ee_link!r} is not a link of the robot URDF",
            path=ds.manifest_path,
            where="robot/ee_link",
            hint=f"links: {', '.join(chain.link_names[:12])}",
        )
    return fitted_chain(chain, physics, path=ds.manifest.get("physics"))[0]


def link_frames(
    ds: Any, ep: Any, chain: Any, t_query: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Every link's pose by forward kinematics of an episode's measured ``joint_states``, in
    the frame of ``robot.base_link`` (the world): stamps [N] int64 ns and T_base_link
    [N, L, 4, 4] (L = ``chain.link_names``), at the joint stamps or, with ``t_query``, with the
    joints linearly interpolated at those stamps.

    Raises:
        FormatError: the episode lacks ``joint_states`` or one of the chain's joints.
    """
    import torch

    _require_stream(
        ds,
        ep,
        "joint_states",
        "has neither ee_poses nor joint_states",
        "the rigid model is driven by the end effector: record one of them",
    )
    js = ep.table("joint_states")
    missing = [j for j in chain.joint_names if f"position.{j}" not in js.column_names]
    if missing:
        raise FormatError(
            f"joint_states lacks joints {', '.join(missing[:6])} of the robot URDF",
            path=ep.table_path("joint_states"),
            where="columns",
            hint="record every actuated joint of the URDF, or record ee_poses",
        )
    t = js.column("t_ns").to_numpy().astype(np.int64)
    q = np.stack(
        [js.column(f"position.{j}").to_numpy().astype(float) for j in chain.joint_names], 1
    )
    if t_query is not None:
        q = np.stack([np.interp(t_query, t, q[:, j]) for j in range(q.shape[1])], axis=1)
        t = np.asarray(t_query, dtype=np.int64)
    T = chain.forward(torch.as_tensor(q, dtype=torch.float64))  # [N, L, 4, 4] root frame
    base = (ds.manifest.get("robot") or {}).get("base_link")
    if isinstance(base, str) and base in chain.link_names and base != chain.link_names[0]:
        T = torch.linalg.inv(T[:, chain.link_index(base)]).unsqueeze(1) @ T
    return t, T.numpy()


def _ee_from_joints(ds: Any, ep: Any, chain: Any, link: str) -> tuple[np.ndarray, ...]:
    """End-effector poses (world = robot base frame) by forward kinematics of the measured
    joints, at the ``joint_states`` stamps: (t_ns [N], position [N, 3] m, quaternion [N, 4] wxyz).
    """
    from robogs.format.frames import matrix_to_quat_np

    t, T = link_frames(ds, ep, chain)
    Te = T[:, chain.link_index(link)]
    return t, Te[:, :3, 3].copy(), matrix_to_quat_np(Te[:, :3, :3])


def _frame_rotation(ds: Any, frame: str, ee_link: Any) -> tuple[str, np.ndarray] | None:
    """How a wrench frame is oriented: ``("world", I)`` for the world / base frame,
    ``("ee", R_link_frame)`` for the pusher link or a named frame fixed to it; None otherwise."""
    robot = ds.manifest.get("robot") or {}
    if frame in ("world", "map", robot.get("base_link")):
        return "world", np.eye(3)
    if frame == ee_link:
        return "ee", np.eye(3)
    named = (robot.get("frames") or {}).get(frame)
    if isinstance(named, dict) and named.get("parent") == ee_link:
        T = np.asarray(named.get("T_parent_frame"), dtype=float).reshape(4, 4)
        return "ee", T[:3, :3]
    return None


def _wrench_world(
    ds: Any,
    ep: Any,
    frame: Any,
    ee_link: Any,
    ee_t: np.ndarray,
    ee_quat: np.ndarray,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The measured force of the pusher's force-torque sensor: stamps [W] and force [W, 3] N in
    world axes (rotated by the pusher link's orientation at the nearest earlier EE sample), or
    None when the episode has no ``wrenches``. The frame is ``objects.pusher.wrench_frame``,
    else the only frame of the table."""
    import pyarrow.compute as pc

    from robogs.format.frames import quat_to_matrix_np

    if not ep.has("wrenches"):
        return None
    wt = ep.table("wrenches")
    frames = sorted(set(wt.column("frame").to_pylist()))
    if frame is None:
        if len(frames) != 1:
            raise FormatError(
                f"wrenches has frames {', '.join(frames)}: which one is the pusher's sensor?",
                path=ep.table_path("wrenches"),
                where="objects/pusher/wrench_frame",
                hint="robogs physics set objects.pusher.wrench_frame=<frame>",
            )
        frame = frames[0]
    wt = wt.filter(pc.equal(wt.column("frame"), frame))
    if wt.num_rows == 0:
        raise FormatError(
            f"wrenches has no rows in frame {frame!r}",
            path=ep.table_path("wrenches"),
            where="objects/pusher/wrench_frame",
            hint=f"frames: {', '.join(frames)}",
        )
    rot = _frame_rotation(ds, str(frame), ee_link)
    if rot is None:
        raise FormatError(
            f"wrench frame {frame!r} is neither the world, the pusher link {ee_link!r} nor a "
            "named frame fixed to it",
            path=ep.table_path("wrenches"),
            where="frame",
            hint="declare it in robot.frames (robogs convert keeps static TF frames)",
        )
    t = np.asarray(wt.column("t_ns").to_numpy(), dtype=np.int64)
    f = np.stack([wt.column(c).to_numpy().astype(float) for c in ("fx", "fy", "fz")], axis=-1)
    kind, r_fixed = rot
    if kind == "ee":
        idx = np.clip(np.searchsorted(ee_t, t, side="right") - 1, 0, len(ee_t) - 1)
        r = quat_to_matrix_np(ee_quat[idx]) @ r_fixed
        f = np.einsum("nij,nj->ni", r, f)
    return t, f


def with_robot_pusher(shapes: Any, rp: Any, where: str = "recording") -> Any:
    """``shapes`` (:class:`robogs.format.shapes.Shapes`) with the robot pusher ``rp`` (a
    :class:`robogs.physics.engines.mujoco_robot.RobotPusher`, or None: unchanged) as
    ``meshes["pusher"]`` and a note; the one place every engine caller gets it from."""
    if rp is not None:
        shapes.meshes["pusher"] = rp
        moving = getattr(rp, "dofs", [])
        shapes.notes.append(
            f"pusher: the robot's links {', '.join(rp.frames)} (objects.pusher.geometry robot; "
            + (f"servo-driven DOFs {', '.join(moving)}; " if moving else "")
            + f"they stray from their constant pose in {'their bodies' if moving else 'the pusher frame'} "
            f"by up to {rp.moved_m * 1e3:.2f} mm over the {where}, budget "
            f"{rp.budget_m * 1e3:.2f} mm)"
        )
    return shapes


def commanded_robot_pusher(
    ds: Any, chain: Any, T: np.ndarray, *, where: str = "commanded trajectory"
) -> Any:
    """The robot pusher (``objects.pusher.geometry = "robot"``) for a commanded joint
    trajectory, measured and checked over it as :func:`load_recording` does over a recording
    (``robogs render --simulate``; the same :class:`_RobotLinks` code).

    Args:
        ds: the dataset (its physics.json, URDF and budgets).
        chain: the robot chain the trajectory's forward kinematics used.
        T: [N, L, 4, 4] every link's pose in the world (robot base) frame over the trajectory.

    Returns:
        a :class:`robogs.physics.engines.mujoco_robot.RobotPusher`, or None with the primitive
        pusher. Its servo DOFs over the trajectory (``Drive.pusher_dofs`` before the grid):
        :func:`robogs.physics.engines.mujoco_robot.dof_values` of the same ``T``.
    """
    physics = ds.physics()
    pusher = (physics.get("objects") or {}).get("pusher") or {}
    ee_link = pusher.get("link") or (ds.manifest.get("robot") or {}).get("ee_link")
    links = _RobotLinks.of(ds, physics, ee_link, chain=chain)
    if links is None:
        return None
    T = np.asarray(T, dtype=float)
    links.add_frames(T[:, chain.link_index(links.link), :3, :3], T)
    return links.pusher(ds, pusher, where=where)


def load_recording(
    dataset: Any, *, object_name: str | None = None, split: str | None = None
) -> Recording:
    """Read a robogs dataset into a :class:`Recording`, each episode cut into trajectories.

    Args:
        dataset: a ``robogs.format.dataset.Dataset`` or a dataset folder.
        object_name: the free object; default the only ``rigid`` object in physics.json, or,
            with several, the one the pusher comes closest to in the first episode (horizontal
            distance of the EE to the tracked centre). The other rigid objects with rows in
            ``object_poses`` are tracked too (:attr:`Trajectory.others`), in every episode.
        split: ``auto`` (cut at stream gaps, object teleports and rest-motion-rest, see
            :mod:`robogs.physics.split`), ``none`` (one trajectory per episode) or
            ``at=T1,T2,...`` (s from each episode's start); default the mode of the enclosing
            :func:`~robogs.physics.split.split_option` block, else ``auto``. The pieces are
            listed in ``meta["split"]``.

    The end effector is ``objects.pusher.link`` of physics.json (default: the manifest's
    ``robot.ee_link``), read from ``ee_poses`` and moved by ``objects.pusher.offset_m`` (the
    pusher's centre in the link frame, default none); an episode without ``ee_poses`` is driven by
    forward kinematics of its ``joint_states`` (with the physics revision's fitted joint
    offsets). The ``wrenches`` of frame ``objects.pusher.wrench_frame`` (default: the only
    frame there), the force on the tool, are rotated into world axes. Grasp flags come from the
    joint named ``objects.pusher.grasp_joint``
    in ``joint_states`` (grasping while its position exceeds ``grasp_threshold``); without it
    the object is never attached. The rigid objects' mesh assets are loaded into
    :attr:`Recording.meshes` (with the dataset's ``geometry.box3d_mm`` budget).
    """
    import pyarrow.compute as pc

    from robogs.format.dataset import Dataset

    ds = dataset if isinstance(dataset, Dataset) else Dataset.open(Path(dataset))
    physics = ds.physics()
    objects = physics.get("objects", {})
    rigid = [k for k, v in objects.items() if isinstance(v, dict) and v.get("equation") == "rigid"]
    if not rigid or (object_name is not None and object_name not in rigid):
        raise FormatError(
            "physics.json has no rigid object"
            if not rigid
            else f"object {object_name!r} is not a rigid object of physics.json",
            path=ds.resolve("physics.json"),
            where="objects",
            hint=f"rigid objects: {', '.join(rigid)}" if rigid else "run robogs physics init",
        )
    pusher = objects.get("pusher", {})
    ee_link = pusher.get("link") or ds.manifest.get("robot", {}).get("ee_link")
    grasp_joint = pusher.get("grasp_joint")
    thr = float(pusher.get("grasp_threshold", 0.5))
    offset = pusher.get("offset_m")  # the pusher shape's centre in the link frame [m]
    wrench_frame = pusher.get("wrench_frame")
    from robogs.physics.split import current_split, parse_split, split_recording_trajectory

    log = current_split()
    mode, at_s = parse_split(split) if split is not None else ("auto", ())
    if split is None and log is not None:
        mode, at_s = log.mode, log.at_s
    trajs: list[Trajectory] = []
    pieces: list[Any] = []
    chain = None
    robot_links = _RobotLinks.of(ds, physics, ee_link)  # objects.pusher.geometry = "robot"
    robot_eps: list[tuple[Any, np.ndarray, np.ndarray, int]] = []  # its episodes' EE motion
    for ep in ds.episodes:
        _require_stream(
            ds,
            ep,
            "object_poses",
            "has no object_poses stream",
            "the rigid model needs tracked object poses",
        )
        ot_all = ep.table("object_poses")
        if ep.has("ee_poses"):
            et = ep.table("ee_poses")
            if ee_link is not None:
                et = et.filter(pc.equal(et.column("link"), ee_link))
            et_ns, epos, equat = _pose_columns(et)
        else:
            if chain is None:
                chain = _robot_chain(ds, physics, ee_link, ep.id)
            et_ns, epos, equat = _ee_from_joints(ds, ep, chain, str(ee_link))
        if robot_links is not None:
            robot_links.add(ds, ep, equat)
            robot_eps.append((ep, et_ns, equat, len(trajs)))
        if offset is not None:
            from robogs.format.frames import quat_to_matrix

            epos = epos + np.einsum("nij,j->ni", quat_to_matrix(equat), np.asarray(offset, float))
        tracks = {}
        for name in rigid:
            rows = ot_all.filter(pc.equal(ot_all.column("object"), name))
            if rows.num_rows:
                tracks[name] = ObjectTrack(*_pose_columns(rows))
        if object_name is None:
            object_name = rigid[0] if len(rigid) == 1 else _pushed_object(tracks, et_ns, epos)
        ot = ot_all.filter(pc.equal(ot_all.column("object"), object_name))
        if ot.num_rows < 2 or len(et_ns) < 2:
            raise FormatError(
                f"episode {ep.id!r}: too few rows for object {object_name!r} or link {ee_link!r}",
                path=ep.table_path("object_poses"),
            )
        t, pos, quat = _pose_columns(ot)
        grasp = np.zeros(len(et_ns), dtype=bool)
        if grasp_joint is not None and ep.has("joint_states"):
            js = ep.table("joint_states")
            col = f"position.{grasp_joint}"
            if col in js.column_names:
                jt = js.column("t_ns").to_numpy().astype(np.int64)
                jv = js.column(col).to_numpy().astype(float)
                idx = np.clip(np.searchsorted(jt, et_ns, side="right") - 1, 0, len(jt) - 1)
                grasp = jv[idx] > thr
        others = {n: o for n, o in tracks.items() if n != object_name}
        whole = Trajectory(
            ep.id, t, pos, quat, et_ns, epos, equat, grasp, kind=ep.segment, others=others
        )
        wr = _wrench_world(ds, ep, wrench_frame, ee_link, et_ns, equat)
        if wr is not None:
            whole.wrench_t_ns, whole.wrench_force = wr
        start = getattr(ep, "start_ns", None)
        parts, rows = split_recording_trajectory(
            whole, mode, at_s, int(start) if isinstance(start, (int, np.integer)) else None
        )
        trajs += [_clip_others(p) for p in parts]
        pieces += rows
    from robogs.format.shapes import BOX_BUDGET, load_object_meshes

    rp = None if robot_links is None else robot_links.pusher(ds, pusher)
    if rp is not None and rp.dofs:  # what moves in the robot pusher, on each trajectory
        ends = [i for *_, i in robot_eps[1:]] + [len(trajs)]
        for (ep, et_ns, equat, first), end in zip(robot_eps, ends, strict=True):
            vals = robot_links.dof_values(ds, ep, rp, et_ns, equat)
            for tr in trajs[first:end]:
                tr.pusher_dofs = vals[np.searchsorted(et_ns, tr.ee_t_ns)]
    rec = Recording(
        trajectories=trajs,
        physics=physics,
        object_name=object_name,
        meta={"split": pieces},
        meshes=load_object_meshes(ds),
        box_budget_mm=float(ds.budgets[BOX_BUDGET]),
        robot_pusher=rp,
    )
    rec = as_recording(rec)
    if log is not None:
        log.pieces += pieces
        log.recordings.append(rec)
    return rec


class _RobotLinks:
    """What ``objects.pusher.geometry = "robot"`` needs from a dataset: the robot chain, the
    pusher link and the links below it, and, per episode (or commanded trajectory), the end
    effector's orientations and the links' poses relative to it (forward kinematics of
    ``joint_states``; without them the links below the pusher link must hang from it by fixed
    joints)."""

    def __init__(self, chain: Any, link: str, urdf: Path) -> None:
        from robogs.physics.engines.mujoco_robot import distal_joints, distal_links

        self.chain, self.link, self.urdf = chain, link, urdf
        self.links = distal_links(chain, link)
        self.joints = distal_joints(chain, link)
        self.ee_rot: list[np.ndarray] = []
        self.rel: dict[str, list[np.ndarray]] = {n: [] for n in self.links}

    @classmethod
    def of(
        cls, ds: Any, physics: dict[str, Any], ee_link: Any, chain: Any = None
    ) -> _RobotLinks | None:
        """None with the primitive pusher; ``chain``: the robot chain (default: the dataset's
        with the fitted joint offsets, as the end effector is driven)."""
        from robogs.physics.engines.mujoco_robot import pusher_geometry

        if pusher_geometry(physics) != "robot":
            return None
        robot = ds.manifest.get("robot") or {}
        if not isinstance(robot.get("urdf"), str):
            raise FormatError(
                "objects.pusher.geometry is 'robot' but the dataset has no robot URDF",
                path=ds.manifest_path,
                where="robot/urdf",
                hint="declare robot.urdf, or use the primitive pusher "
                "(robogs physics set DATASET objects.pusher.geometry=primitive)",
            )
        if chain is None:
            chain = _robot_chain(ds, physics, ee_link, "(objects.pusher.geometry robot)")
        elif not isinstance(ee_link, str) or ee_link not in chain.link_names:
            raise FormatError(
                f"objects.pusher.geometry is 'robot' but the pusher link {ee_link!r} is not a "
                "link of the robot URDF",
                path=ds.manifest_path,
                where="objects/pusher/link",
                hint=f"links: {', '.join(chain.link_names[:12])}",
            )
        return cls(chain, str(ee_link), Path(ds.urdf_path))

    def add(self, ds: Any, ep: Any, ee_quat: np.ndarray) -> None:
        """One episode: its end-effector orientations and its links (``joint_states``)."""
        import torch

        from robogs.format.frames import quat_to_matrix

        ee_rot = np.asarray(quat_to_matrix(ee_quat), dtype=float)
        if ep.has("joint_states"):
            _, T = link_frames(ds, ep, self.chain)
        else:
            idx = [self.chain.link_index(n) for n in self.links]
            moving = [
                self.chain.link_names[k]
                for k in idx[1:]
                if self.chain.joint_types[k - 1] != "fixed"
            ]
            if moving:
                raise FormatError(
                    f"episode {ep.id!r} has no joint_states, and links {', '.join(moving)} "
                    f"below the pusher link {self.link!r} hang from moving joints",
                    path=ds.manifest_path,
                    where=f"episodes/{ep.id}",
                    hint="record joint_states, or use the primitive pusher "
                    "(objects.pusher.geometry=primitive)",
                )
            q = torch.zeros((1, self.chain.num_joints), dtype=torch.float64)
            T = self.chain.forward(q).numpy()
        self.add_frames(ee_rot, T)

    def add_frames(self, ee_rot: np.ndarray, T: np.ndarray) -> None:
        """End-effector orientations ``ee_rot`` [N, 3, 3] and every link's pose ``T``
        [K, L, 4, 4] (any common frame) over one stretch of motion."""
        self.ee_rot.append(np.asarray(ee_rot, dtype=float))
        inv = np.linalg.inv(T[:, self.chain.link_index(self.link)])
        for n in self.links:
            self.rel[n].append(inv @ T[:, self.chain.link_index(n)])

    def pusher(self, ds: Any, pusher: Any, where: str | None = None) -> Any:
        """The :class:`RobotPusher` over everything added, checked against the dataset's
        ``geometry.box3d_mm`` and the motion's own noise; what strays over it (the end
        effector's roll and pitch, joints below the pusher link) becomes servo DOFs
        (:func:`robogs.physics.engines.mujoco_robot.pusher_model`)."""
        from robogs.format.shapes import BOX_BUDGET
        from robogs.physics.engines.mujoco_robot import RobotPusher, pusher_model, pusher_reach

        frames, bodies, tilt, joints, rig = pusher_model(
            np.concatenate(self.ee_rot),
            pusher.get("offset_m"),
            {n: np.concatenate(v) for n, v in self.rel.items()},
            self.joints,
            budget_mm=float(ds.budgets[BOX_BUDGET]),
            reach_m=pusher_reach(pusher),
            where=where or f"dataset {ds.root}",
        )
        return RobotPusher(
            self.urdf,
            self.link,
            frames,
            root=Path(ds.root),
            spread_m=rig.spread_m,
            spread_rad=rig.spread_rad,
            moved_m=rig.moved_m,
            budget_m=rig.budget_m,
            tilt=tilt,
            joints=joints,
            bodies=bodies,
        )

    def dof_values(
        self, ds: Any, ep: Any, rp: Any, ee_t_ns: np.ndarray, ee_quat: np.ndarray
    ) -> np.ndarray:
        """An episode's robot-pusher servo DOFs [E, J] at its EE stamps ``ee_t_ns``
        (:func:`robogs.physics.engines.mujoco_robot.dof_values`; the joints interpolated
        linearly at those stamps, :func:`link_frames`)."""
        from robogs.format.frames import quat_to_matrix
        from robogs.physics.engines.mujoco_robot import dof_values

        links = None
        if rp.joints:
            _, T = link_frames(ds, ep, self.chain, t_query=ee_t_ns)
            links = {n: T[:, self.chain.link_index(n)] for n in self.links}
        return dof_values(rp, np.asarray(quat_to_matrix(ee_quat), dtype=float), links)


def _pushed_object(tracks: dict[str, ObjectTrack], ee_t: np.ndarray, ee_pos: np.ndarray) -> str:
    """The tracked object the end effector comes closest to (horizontal distance [m] from the
    EE to the object's tracked centre, the EE interpolated at the object's stamps)."""
    if not tracks:
        raise FormatError("no rigid object has rows in object_poses", where="object_poses")

    def closest(o: ObjectTrack) -> float:
        ex = np.interp(o.t_ns, ee_t, ee_pos[:, 0])
        ey = np.interp(o.t_ns, ee_t, ee_pos[:, 1])
        return float(np.min(np.hypot(o.pos[:, 0] - ex, o.pos[:, 1] - ey)))

    return min(tracks, key=lambda n: (closest(tracks[n]), n))


def _clip_others(tr: Trajectory) -> Trajectory:
    """The other tracked objects' poses within a (split) trajectory's time span."""
    if not tr.others:
        return tr
    a = min(int(tr.t_ns[0]), int(tr.ee_t_ns[0]))
    b = max(int(tr.t_ns[-1]), int(tr.ee_t_ns[-1]))
    out = {}
    for n, o in tr.others.items():
        m = (o.t_ns >= a) & (o.t_ns <= b)
        out[n] = ObjectTrack(o.t_ns[m], o.pos[m], o.quat[m])
    return replace(tr, others=out)

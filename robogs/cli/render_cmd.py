"""``robogs render DATASET OUT``: render a new joint trajectory through the binding.

::

    robogs render scene/ out/ --joints traj.csv              # t_ns, position.<joint> rows
    robogs render scene/ out/ --from-episode ep000 --edit elbow_joint=+0.1
    robogs render scene/ out/ --joints traj.parquet --camera cam0 --camera new_cam.json
    robogs render scene/ out/ --from-episode ep000 --orbit 1
    robogs render scene/ out/ --joints traj.csv --simulate       # objects pushed in simulation
    robogs render scene/ lr/ --joints traj.csv --format lerobot  # straight into LeRobot v3
    robogs render scene/ vid/ --joints traj.csv --format video --normals  # plain files

OUT is a robogs dataset sharing the source's robot, assets, physics and cameras, with one
rendered episode (RGB video, panoptic labels, depth, 2-D boxes, the commanded joints, FK end-
effector poses and the object poses); see :mod:`robogs.format.render_trajectory`. Objects are
replayed from the source episode, or with ``--simulate`` rolled out by a physics engine
(:mod:`robogs.physics.engines`) from the pusher motion of the commanded joints
(:func:`simulate_objects`). ``--format lerobot`` writes the rendered episode (and with
``--with-recorded`` the source's episodes too, marked ``recorded``) as a LeRobot v3 dataset
instead (:mod:`robogs.convert.export.lerobot`, rendered episodes marked ``rendered``).
``--format video`` writes a plain folder readable without robogs (:func:`write_video_folder`:
``<camera>/rgb.mp4``, ``labels/``, ``depth/`` and with ``--normals`` ``normals/`` PNGs per frame,
``frames.csv``, ``boxes.csv``, ``labels.json``, ``video.json``). ``--normals`` adds the
rendered surface normals (:class:`robogs.format.render_trajectory.RenderedFrame`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "add_arguments",
    "run",
    "SimulationSetup",
    "simulation_setup",
    "simulate_objects",
    "write_video_folder",
    "VIDEO_FORMAT",
]

#: ``format`` of ``video.json``: marks a folder written by ``robogs render --format video``
VIDEO_FORMAT = "robogs-render-video"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Declare ``robogs render``'s arguments."""
    p.add_argument("dataset", type=Path, help="source dataset folder")
    p.add_argument("out", type=Path, help="dataset folder to create")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--joints", type=Path, metavar="FILE", help="Parquet or CSV: t_ns, position.<joint>"
    )
    src.add_argument(
        "--from-episode", metavar="EP", dest="from_episode", help="the recorded joints of EP"
    )
    p.add_argument(
        "--edit",
        action="append",
        default=[],
        metavar="JOINT=OFFSET",
        help="with --from-episode: add OFFSET (rad or m) to a joint (repeatable)",
    )
    p.add_argument(
        "--episode",
        help="with --joints: episode whose objects are replayed (default: the only one)",
    )
    p.add_argument(
        "--camera",
        action="append",
        default=None,
        metavar="NAME|FILE.json",
        help="a recorded camera by name, or a camera JSON file with intrinsics and T_world_cam "
        "(repeatable; default: every recorded camera)",
    )
    p.add_argument(
        "--orbit",
        type=float,
        metavar="N",
        help="add a camera circling the robot N times over the trajectory",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=30.0,
        help="frame rate with --joints or --orbit (--from-episode keeps the recorded frame "
        "stamps); default 30",
    )
    p.add_argument(
        "--simulate",
        action="store_true",
        help="simulate the free object from the commanded pusher motion (physics engine, the "
        "dataset's physics.json) instead of replaying its recorded poses",
    )
    p.add_argument(
        "--engine", default="auto", help="with --simulate: physics engine (default auto)"
    )
    p.add_argument(
        "--format",
        choices=("robogs", "lerobot", "video"),
        default="robogs",
        help="robogs dataset (default), a LeRobot v3 dataset, or a plain folder of videos, "
        "label/depth PNGs and CSVs (video) at OUT",
    )
    p.add_argument(
        "--normals",
        action="store_true",
        help="also write the rendered surface normals (camera frame, RGB PNGs n*0.5+0.5; "
        "--format robogs or video)",
    )
    p.add_argument(
        "--with-recorded",
        action="store_true",
        dest="with_recorded",
        help="with --format lerobot: also export the source's recorded episodes (same cameras)",
    )
    p.add_argument(
        "--state",
        choices=("joints", "ee"),
        default="joints",
        help="with --format lerobot: observation.state / action as joints or EE poses",
    )
    p.add_argument(
        "--backend",
        default="auto",
        help="render backend: auto (numba on CPU when installed, else torch), torch, numba",
    )
    p.add_argument("--force", action="store_true", help="replace OUT if it is a robogs dataset")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def run(args: argparse.Namespace) -> int:
    """Render; 0 on success (errors are ``RobogsError``, printed by the dispatcher)."""
    from robogs.format import Dataset
    from robogs.format.errors import InputError
    from robogs.format.render_trajectory import (
        episode_trajectory,
        parse_edits,
        read_joint_trajectory,
        render_dataset,
    )

    src = Dataset.open(args.dataset)
    from robogs.format.kinematics import Chain

    chain = Chain.from_urdf(src.urdf(load_meshes=False))
    if args.edit and not args.from_episode:
        raise InputError("--edit applies to --from-episode", where="--edit")
    stamps = None
    if args.from_episode:
        ep = src.episode(args.from_episode)
        traj = episode_trajectory(ep, chain, parse_edits(args.edit, chain.joint_names))
        episode = ep.id
    else:
        traj = read_joint_trajectory(args.joints, chain)
        episode = args.episode
    names, files = [], []
    for c in args.camera or []:
        (files if c.endswith(".json") else names).append(c)
    if args.from_episode and not files and args.orbit is None:
        cams = names or src.camera_names
        ep = src.episode(episode)
        if len(cams) == 1 and cams[0] in ep.camera_streams:
            stamps = ep.frames(cams[0]).column("t_ns").to_numpy()
    cameras = names if (names or files or args.orbit is not None) else None

    def progress(done: int, total: int) -> None:
        if not args.quiet:
            print(f"\rrendering {done}/{total} frames", end="", file=sys.stderr, flush=True)

    if args.with_recorded and args.format != "lerobot":
        raise InputError("--with-recorded applies to --format lerobot", where="--with-recorded")
    if args.normals and args.format == "lerobot":
        raise InputError("--normals applies to --format robogs or video", where="--normals")
    poses, objects_source, sim_notes = None, None, []
    if args.simulate:
        poses, objects_source, sim_notes = simulate_objects(
            src, src.episode(episode), traj, engine=args.engine
        )
    taken = {e["id"] for e in src.manifest.get("episodes", [])}
    new_episode = next(
        f"render{i:03d}" for i in range(len(taken) + 1) if f"render{i:03d}" not in taken
    )
    render_kw: dict[str, Any] = dict(
        episode=episode,
        cameras=cameras,
        camera_files=files,
        orbit=args.orbit,
        frame_stamps=stamps,
        fps=args.fps,
        backend=args.backend,
        progress=progress,
        object_poses=poses,
        objects_source=objects_source,
        new_episode=new_episode,
        normals=args.normals,
    )
    if args.format == "video":
        summary, report = _render_video(src, traj, args, render_kw), None
    elif args.format == "lerobot":
        summary, report = _render_lerobot(src, traj, args, render_kw)
    else:
        summary = render_dataset(src, args.out, traj, overwrite=args.force, **render_kw)
        report = None
    if not args.quiet:
        print(file=sys.stderr)
    frames = ", ".join(f"{c}: {n}" for c, n in summary.frames.items())
    what = "LeRobot v3 dataset " if report is not None else ""
    what = "video folder " if args.format == "video" else what
    print(
        f"wrote {what}{args.out} (episode {summary.episode}; frames {frames}; joints {traj.source})"
    )
    for w in summary.warnings:
        print(f"robogs render: warning: {w}", file=sys.stderr)
    for n in [*sim_notes, *summary.notes, *(report.notes if report is not None else [])]:
        print(f"  note: {n}", file=sys.stderr)
    return 0


def _render_lerobot(
    src: Any, traj: Any, args: argparse.Namespace, kw: dict[str, Any]
) -> tuple[Any, Any]:
    """Render into a temporary robogs dataset beside OUT, export it as LeRobot v3 at OUT."""
    import shutil
    import tempfile

    from robogs.convert.export import export
    from robogs.format.render_trajectory import render_dataset

    out = Path(args.out)
    if out.exists() and not args.force:
        from robogs.format.errors import DatasetExistsError

        raise DatasetExistsError("output exists", path=out, hint="pass --force to replace it")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.render-", dir=out.parent))
    try:
        summary = render_dataset(src, tmp / "ds", traj, keep_episodes=args.with_recorded, **kw)
        episode = None if args.with_recorded else summary.episode
        report = export(
            "lerobot",
            tmp / "ds",
            out,
            force=args.force,
            episode=episode,
            state=args.state,
            labels=True,
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return summary, report


def _render_video(src: Any, traj: Any, args: argparse.Namespace, kw: dict[str, Any]) -> Any:
    """Render into a temporary dataset beside OUT, write the video folder from it, rename it
    into place (OUT is replaced only with ``--force`` and only if it is such a folder)."""
    import json
    import shutil
    import tempfile

    from robogs.format.errors import DatasetExistsError
    from robogs.format.render_trajectory import render_dataset

    out = Path(args.out)
    if out.exists() or out.is_symlink():
        marker = out / "video.json"
        ours = False
        if out.is_dir() and not out.is_symlink() and marker.is_file():
            try:
                ours = json.loads(marker.read_text()).get("format") == VIDEO_FORMAT
            except (OSError, ValueError, AttributeError):
                ours = False
        if not args.force:
            raise DatasetExistsError("output exists", path=out, hint="pass --force to replace it")
        if not ours:
            raise DatasetExistsError(
                "output exists and is not a robogs render video folder; refusing to replace it",
                path=out,
                hint="choose another OUT",
            )
    if not out.parent.is_dir():
        from robogs.format.errors import InputError

        raise InputError("the parent folder of OUT does not exist", path=out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.render-", dir=out.parent))
    try:
        summary = render_dataset(src, tmp / "ds", traj, **kw)
        write_video_folder(tmp / "ds", summary.episode, tmp / "video")
        if out.exists():
            out.rename(tmp / "old")
        try:
            (tmp / "video").rename(out)
        except OSError:
            if (tmp / "old").exists():
                (tmp / "old").rename(out)  # put the replaced folder back
            raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    summary.out = out
    return summary


def write_video_folder(dataset: str | Path, episode: str, out: str | Path) -> None:
    """Write episode ``episode`` of a rendered dataset as a plain folder at ``out`` (new).

    Per camera: ``<cam>/rgb.mp4`` (the dataset's video, copied), ``<cam>/labels/<frame:06d>.png``
    (the dataset's 16-bit panoptic label PNGs, byte for byte), ``<cam>/depth/<frame:06d>.png``
    (uint16 mm, 0: no hit), ``<cam>/normals/<frame:06d>.png`` where the dataset has normals, and
    ``<cam>/frames.csv`` (``frame_index,t_ns``; int64 ns, dataset clock). Beside them
    ``boxes.csv`` (pixel edges, max exclusive), ``labels.json`` (label id -> link or object) and
    ``video.json`` (the layout, units, cameras).
    """
    import csv
    import json
    import shutil

    from robogs.format import Dataset

    ds = Dataset.open(dataset)
    ep = ds.episode(episode)
    out = Path(out)
    out.mkdir()
    cams: dict[str, Any] = {}
    for cam in sorted(ep.camera_streams):
        cdir = out / cam
        cdir.mkdir()
        shutil.copyfile(ep.video_path(cam), cdir / "rgb.mp4")
        fr = ep.frames(cam)
        idx = fr.column("frame_index").to_numpy()
        with open(cdir / "frames.csv", "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["frame_index", "t_ns"])
            w.writerows(zip(idx.tolist(), fr.column("t_ns").to_numpy().tolist(), strict=True))
        lab = _pq_read(ep.labels_path(cam))
        images = {"labels": (lab.column("frame_index"), lab.column("png"))}
        for kind in ("depth", "normals"):
            if ep.has(f"{kind}/{cam}"):
                t = ep.table(f"{kind}/{cam}")
                images[kind] = (t.column("frame_index"), t.column("png"))
        for kind, (fi, png) in images.items():
            (cdir / kind).mkdir()
            for k, blob in zip(fi.to_pylist(), png.to_pylist(), strict=True):
                (cdir / kind / f"{int(k):06d}.png").write_bytes(blob)
        m = ds.camera(cam)
        d = m.to_dict()
        if ep.camera_streams[cam].get("extrinsics"):
            d["extrinsics_csv"] = f"{cam}/extrinsics.csv"
            x = _pq_read(ds.resolve(ep.camera_streams[cam]["extrinsics"]))
            with open(cdir / "extrinsics.csv", "w", newline="", encoding="utf-8") as fh:
                w = csv.writer(fh)
                w.writerow(x.column_names)
                w.writerows(zip(*(x.column(c).to_pylist() for c in x.column_names), strict=True))
        cams[cam] = {"frames": len(idx), "images": sorted(images), "camera": d}
    rows = ep.table("boxes2d").to_pylist() if ep.has("boxes2d") else []
    cols = ["t_ns", "camera", "frame_index", "label_id", "x_min", "y_min", "x_max", "y_max"]
    with open(out / "boxes.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            w.writerow([r[c] if isinstance(r[c], str) else int(r[c]) for c in cols])
    labels = {
        str(int(s["label_id"])): {
            "name": s["target"],
            "kind": s["kind"],
            "category": s["category"],
            "instance": s["instance"],
        }
        for s in ep.table("segments").to_pylist()
    }
    (out / "labels.json").write_text(json.dumps({"0": None, **labels}, indent=1) + "\n")
    doc = {
        "format": VIDEO_FORMAT,
        "version": 1,
        "source": ds.manifest.get("provenance", {}).get("rendered", {}).get("source"),
        "episode": episode,
        "rgb": "<camera>/rgb.mp4 (mp4v); video frame k is row k of <camera>/frames.csv",
        "frames": "<camera>/frames.csv: frame_index,t_ns (int64 ns, dataset clock)",
        "labels": "<camera>/labels/<frame:06d>.png: uint16 panoptic label ids (labels.json; "
        "0: nothing)",
        "depth": "<camera>/depth/<frame:06d>.png: uint16 depth along the camera z axis in "
        "millimetres; 0 = no hit",
        "normals": "<camera>/normals/<frame:06d>.png (with --normals): 8-bit RGB, "
        "n * 0.5 + 0.5 of the unit surface normal in the camera frame (OpenCV axes: x right, "
        "y down, z forward, facing the camera), the rendered splat normals; (0, 0, 0) = none",
        "boxes": "boxes.csv: 2-D boxes per label, pixel edges, max exclusive",
        "cameras": cams,
    }
    (out / "video.json").write_text(json.dumps(doc, indent=1) + "\n")


def _pq_read(path: Path) -> Any:
    """A Parquet file as a ``pyarrow.Table``."""
    import pyarrow.parquet as pq

    return pq.read_table(path)


@dataclass
class SimulationSetup:
    """What ``robogs render --simulate`` rolls out (:func:`simulation_setup`).

    Attributes:
        engine: the engine's name; reason: why ``auto`` chose it ("" when named).
        physics: the dataset's physics.json; obj: the free object; link: the pusher link.
        dt: the step [s]; drive: the pusher on the step grid, poses wanted at the trajectory's
            stamps; start: ``{obj: ObjectState}`` at rest at the recorded pose.
        shapes: the object shapes and, with ``objects.pusher.geometry = "robot"``, the robot
            pusher measured over the commanded trajectory (``meshes["pusher"]``).
    """

    engine: str
    reason: str
    physics: dict[str, Any]
    obj: str
    link: str
    dt: float
    drive: Any
    start: dict[str, Any]
    shapes: Any


def simulation_setup(
    src: Any, ep: Any, traj: Any, *, engine: str = "auto", dt: float = 1e-3
) -> SimulationSetup:
    """The engine, drive, start and shapes :func:`simulate_objects` rolls out.

    The pusher is ``objects.pusher.link`` of physics.json (default ``robot.ee_link``), moved by
    ``objects.pusher.offset_m`` (m, link frame) as :func:`robogs.physics.recording.
    load_recording` reads it; its pose is forward kinematics of the commanded joints (with the
    physics revision's fitted joint offsets), linearly interpolated onto a grid of step ``dt``
    (s); the drive carries the median spacing of those stamps (``Drive.sample_dt``), over
    which the MuJoCo engine smooths its servo targets. With ``objects.pusher.geometry =
    "robot"`` the robot's links push, measured over the commanded trajectory's forward
    kinematics and checked (links fixed in the pusher frame within the dataset's derived
    budget, else the end effector's tilt and the moving joints below the pusher link become
    servo DOFs, ``Drive.pusher_dofs``) by the code that does it for ``compare``
    (:func:`robogs.physics.recording.commanded_robot_pusher`). The free object (the only
    ``rigid`` one) starts at rest at its recorded pose in ``ep`` at the trajectory's first stamp
    (clamped).

    Raises:
        InputError: no physics.json, no single rigid object, no pusher link, no engine able to
            represent the scene, or no recorded pose to start the object from.
    """
    import torch

    from robogs.format.errors import InputError
    from robogs.format.frames import matrix_to_quat, quat_to_matrix
    from robogs.format.interp import interp_pose
    from robogs.format.kinematics import Chain, dataset_fitted_chain
    from robogs.physics.engines import ObjectState, choose_engine, make_drive
    from robogs.physics.engines.base import quat_yaw
    from robogs.physics.recording import commanded_robot_pusher, with_robot_pusher

    if not isinstance(src.manifest.get("physics"), str):
        raise InputError("--simulate needs physics.json", path=src.manifest_path, where="physics")
    physics = src.physics()
    objects = physics.get("objects") or {}
    rigid = [k for k, v in objects.items() if isinstance(v, dict) and v.get("equation") == "rigid"]
    if len(rigid) != 1:
        raise InputError(
            f"--simulate needs exactly one rigid object in physics.json, found {len(rigid)}",
            path=src.resolve("physics.json"),
            where="objects",
        )
    obj = rigid[0]
    pusher = objects.get("pusher") or {}
    link = pusher.get("link") or (src.manifest.get("robot") or {}).get("ee_link")
    chain, _ = dataset_fitted_chain(src, Chain.from_urdf(src.urdf(load_meshes=False)))
    if not isinstance(link, str) or link not in chain.link_names:
        raise InputError(
            f"--simulate needs the pusher link (objects.pusher.link or robot.ee_link), got {link!r}",
            path=src.manifest_path,
            where="robot/ee_link",
        )
    if not ep.has("object_poses"):
        raise InputError(
            f"--simulate starts {obj!r} from its recorded pose; episode {ep.id!r} has none",
            where=f"episodes/{ep.id}",
        )
    with torch.no_grad():
        T = chain.forward(torch.as_tensor(traj.q, dtype=torch.float64))
        base = (src.manifest.get("robot") or {}).get("base_link")
        if isinstance(base, str) and base in chain.link_names and base != chain.link_names[0]:
            T = torch.linalg.inv(T[:, chain.link_index(base)]).unsqueeze(1) @ T
        Te = T[:, chain.link_index(link)]
    from robogs.format.shapes import BOX_BUDGET, load_object_meshes, object_shapes

    rp = commanded_robot_pusher(src, chain, T.numpy())
    shapes = with_robot_pusher(
        object_shapes(physics, load_object_meshes(src), float(src.budgets[BOX_BUDGET])),
        rp,
        "commanded trajectory",
    )
    name, reason = engine, ""
    if engine == "auto":  # the shapes as the fit sees them (a box-shaped mesh is its box)
        name, reason = choose_engine(physics, shapes.meshes)
    pos = Te[:, :3, 3].numpy().copy()
    quat = matrix_to_quat(Te[:, :3, :3]).numpy()
    if pusher.get("offset_m") is not None:
        pos = pos + np.einsum(
            "nij,j->ni", quat_to_matrix(quat), np.asarray(pusher["offset_m"], float)
        )
    t_s = (traj.t_ns - traj.t_ns[0]) * 1e-9
    grid = np.arange(int(np.ceil(t_s[-1] / dt)) + 2) * dt
    p_grid = np.stack([np.interp(grid, t_s, pos[:, a]) for a in range(3)], -1)
    yaw_grid = np.interp(grid, t_s, np.unwrap(quat_yaw(quat)))
    dofs = None  # the robot pusher's moving joints and tilt, as load_recording gives them
    if rp is not None and rp.dofs:
        from robogs.physics.engines.mujoco_robot import dof_values

        Tn = T.numpy()
        vals = dof_values(
            rp,
            Tn[:, chain.link_index(link), :3, :3],
            {n: Tn[:, chain.link_index(n)] for n in rp.frames},
        )
        dofs = np.stack([np.interp(grid, t_s, v) for v in vals.T], -1)[None]
    tab = ep.table("object_poses")
    m = np.asarray(tab.column("object").to_pylist()) == obj
    if m.sum() == 0:
        raise InputError(f"episode {ep.id!r} has no recorded pose of {obj!r}", where="object_poses")
    p0, q0 = interp_pose(
        traj.t_ns[:1],
        tab.column("t_ns").to_numpy()[m].astype(np.int64),
        np.stack([tab.column(c).to_numpy()[m] for c in ("x", "y", "z")], -1),
        np.stack([tab.column(c).to_numpy()[m] for c in ("qw", "qx", "qy", "qz")], -1),
        outside="clamp",
    )
    drive = make_drive(  # the servos are smoothed over the stamps' own interval
        dt,
        p_grid[None],
        yaw_grid[None],
        t_s[None],
        p0,
        quat_yaw(q0),
        sample_dt=float(np.median(np.diff(t_s))) if len(t_s) > 1 else np.nan,
        pusher_dofs=dofs,
    )
    return SimulationSetup(
        name, reason, physics, obj, link, dt, drive, {obj: ObjectState(p0, q0)}, shapes
    )


def simulate_objects(
    src: Any,
    ep: Any,
    traj: Any,
    *,
    engine: str = "auto",
    dt: float = 1e-3,
) -> tuple[dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], str, list[str]]:
    """Object poses rolled out by a physics engine from the pusher motion of ``traj``
    (:func:`simulation_setup` says what moves and how the object starts); the engine uses the
    dataset's physics.json parameters as they are (``robogs physics fit`` writes fitted ones
    there).

    Returns:
        ``{object: (t_ns [N], position [N, 3] m, quaternion [N, 4] wxyz)}`` at the trajectory's
        stamps, a one-line description for the provenance, and notes from the engine.

    Raises:
        InputError: as :func:`simulation_setup`.
    """
    from robogs.physics.engines import get_engine

    st = simulation_setup(src, ep, traj, engine=engine, dt=dt)
    sim = get_engine(st.engine)(
        st.physics, object_name=st.obj, meshes=st.shapes.meshes, dt=st.dt, threads=1
    )
    pred = sim.rollout(st.drive, st.start)
    out = {st.obj: (traj.t_ns.copy(), pred.pos[st.obj][0, 0], pred.quat[st.obj][0, 0])}
    rev = st.physics.get("revision")
    desc = (
        f"simulated by the {st.engine} engine from the commanded pusher motion ({st.link}; "
        f"physics revision {rev}, dt {dt:g} s, start at rest at the recorded pose)"
    )
    return out, desc, [*st.shapes.notes, *pred.notes]

"""``robogs render DATASET OUT``: render a new joint trajectory through the binding.

::

    robogs render scene/ out/ --joints traj.csv              # t_ns, position.<joint> rows
    robogs render scene/ out/ --from-episode ep000 --edit elbow_joint=+0.1
    robogs render scene/ out/ --joints traj.parquet --camera cam0 --camera new_cam.json
    robogs render scene/ out/ --from-episode ep000 --orbit 1

OUT is a robogs dataset sharing the source's robot, assets, physics and cameras, with one
rendered episode (RGB video, panoptic labels, depth, 2-D boxes, the commanded joints, FK end-
effector poses and the replayed object poses); see :mod:`robogs.format.render_trajectory`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "run"]


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
    p.add_argument("--backend", default="torch", help="render backend (default torch)")
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

    summary = render_dataset(
        src,
        args.out,
        traj,
        episode=episode,
        cameras=cameras,
        camera_files=files,
        orbit=args.orbit,
        frame_stamps=stamps,
        fps=args.fps,
        backend=args.backend,
        overwrite=args.force,
        progress=progress,
    )
    if not args.quiet:
        print(file=sys.stderr)
    frames = ", ".join(f"{c}: {n}" for c, n in summary.frames.items())
    print(f"wrote {summary.out} (episode {summary.episode}; frames {frames}; joints {traj.source})")
    for w in summary.warnings:
        print(f"robogs render: warning: {w}", file=sys.stderr)
    for n in summary.notes:
        print(f"  note: {n}", file=sys.stderr)
    return 0

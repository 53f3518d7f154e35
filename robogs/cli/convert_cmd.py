"""``robogs convert SRC OUT``: ingest a bag, MCAP, video, image folder or capture into a dataset.

Exit codes: 0 converted, 2 usage error or unusable input (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from robogs.convert.registry import available_converters, get_converter
from robogs.format.errors import InputError

__all__ = ["add_arguments", "run"]

_UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``robogs convert``."""
    parser.add_argument(
        "src",
        nargs="?",
        type=Path,
        help="bag, MCAP, ROS 2 bag folder, video, image folder, "
        "nerfstudio transforms.json or COLMAP model",
    )
    parser.add_argument("out", nargs="?", type=Path, help="dataset folder to create")
    parser.add_argument(
        "--from", dest="fmt", metavar="FORMAT", help="source format (default: detected)"
    )
    parser.add_argument(
        "--list-formats", action="store_true", help="list the source formats and exit"
    )
    parser.add_argument("--force", action="store_true", help="replace an existing dataset at OUT")
    g = parser.add_argument_group("bags and MCAP")
    g.add_argument(
        "--map",
        type=Path,
        metavar="YAML",
        help="topic -> role mapping (YAML); for a tabular joint log, its column mapping",
    )
    g.add_argument(
        "--topic",
        action="append",
        default=[],
        metavar="ROLE=TOPIC",
        help="give TOPIC a role, e.g. object_pose:box=/mocap/box/pose, ee_pose:tool0=/tip_pose, "
        "generic=/x (decoded table) or ignore=/rosout; the roles table at the end says why each "
        "topic got its role",
    )
    g.add_argument("--world-frame", metavar="FRAME", help="TF frame that is the dataset world")
    g.add_argument(
        "--tf-object",
        action="append",
        default=[],
        metavar="NAME=FRAME",
        help="write TF frame FRAME as object NAME's poses (repeatable; replaces the default "
        "choice of every moving frame that is not a robot link or camera)",
    )
    g.add_argument(
        "--no-tf-objects", action="store_true", help="do not write moving TF frames as objects"
    )
    g.add_argument(
        "--tf-camera",
        action="append",
        default=[],
        metavar="CAM=FRAME",
        help="TF frame (OpenCV axes) of camera CAM, instead of its images' frame_id",
    )
    g.add_argument(
        "--tf-tolerance-ms",
        type=float,
        default=100.0,
        metavar="MS",
        help="how far a stamp may lie outside a moving TF frame's samples (default 100 ms)",
    )
    g = parser.add_argument_group("robot")
    g.add_argument("--urdf", type=Path, help="robot URDF (copied with its meshes into robot/)")
    g.add_argument(
        "--package",
        action="append",
        default=[],
        metavar="NAME=FOLDER",
        help="folder of a package:// name used by the URDF's meshes",
    )
    g = parser.add_argument_group("videos and image folders")
    g.add_argument(
        "--camera", type=Path, metavar="FILE", help="calibration (ROS/OpenCV YAML, ROS INI)"
    )
    g.add_argument(
        "--camera-name", metavar="NAME", help="camera name (default: from the calibration or file)"
    )
    g.add_argument(
        "--stamps", type=Path, metavar="CSV", help="frame stamps: CSV with frame_index,t_ns"
    )
    g.add_argument(
        "--assume-fps",
        type=float,
        metavar="FPS",
        help="derive frame stamps as i/FPS (recorded as stamp_source 'derived')",
    )
    g.add_argument(
        "--offset-ns", type=int, default=0, help="added to container/sidecar stamps (ns)"
    )
    g.add_argument(
        "--joints", type=Path, metavar="CSV", help="joint log: t_ns, position.<joint> ..."
    )
    g.add_argument("--no-video", action="store_true", help="write frames tables only (no rgb.mp4)")
    g = parser.add_argument_group("static captures (nerfstudio, COLMAP)")
    g.add_argument(
        "--images", type=Path, metavar="DIR", help="image folder (default: next to the model)"
    )
    g.add_argument("--world-up", choices=_UP_AXES, help="source world's up axis, rotated to +z")
    g.add_argument(
        "--sfm",
        action="store_true",
        help="SRC is images, a video or a dataset without camera poses: recover the poses by "
        "structure from motion (pycolmap; the 'sfm' extra); docs/reconstruct.md",
    )
    g.add_argument(
        "--sfm-threads", type=int, default=1, metavar="N", help="CPU threads for --sfm (default 1)"
    )
    parser.add_argument("--episode", default="ep000", help="episode id (default ep000)")
    p = parser.add_mutually_exclusive_group()
    p.add_argument(
        "--progress", dest="progress", action="store_true", default=None, help="show progress"
    )
    p.add_argument("--no-progress", dest="progress", action="store_false", help="hide progress")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="SRC is a quoted glob of bags: one Ray task per bag, all into one dataset "
        "(episode epKKKK per bag); no ADDRESS starts a local cluster, 'auto' joins the running "
        "one. A glob without --ray converts the bags one after another (docs/scale.md)",
    )


def _pairs(items: list[str], flag: str) -> dict[str, Path]:
    out: dict[str, Path] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name or not value:
            raise InputError(f"{flag} expects NAME=FOLDER, got {item!r}", where=flag)
        out[name] = Path(value)
    return out


def _summary(ds, out: Path) -> dict:
    prov = ds.manifest.get("provenance", {})
    eps = ds.episodes
    return {
        "dataset": str(out),
        "converter": prov.get("converter"),
        "episodes": [
            {"id": e.id, "start_ns": e.start_ns, "end_ns": e.end_ns, "streams": sorted(e.streams)}
            for e in eps
        ],
        "cameras": ds.camera_names,
        "robot": bool(ds.manifest.get("robot")),
        "dropped": prov.get("dropped", []),
        "undecodable": prov.get("undecodable", []),
        "issues": prov.get("issues", []),
        "notes": prov.get("notes", []),
        "roles": [
            {
                "topic": topic,
                "type": rec.get("type"),
                "role": rec.get("role"),
                "messages": rec.get("messages", 0),
                "written": rec.get("written", 0),
                "reason": rec.get("reason"),
            }
            for topic, rec in sorted((prov.get("topics") or {}).items())
        ],
        "decoded": prov.get("decoded"),
        "packages": (prov.get("robot") or {}).get("packages"),
    }


def _print_roles(roles: list[dict]) -> None:
    """The role of every topic and why it was chosen (override with --topic ROLE=TOPIC)."""
    rows = [r for r in roles if r.get("reason")]
    if not rows:
        return
    print("  roles (override with --topic ROLE=TOPIC or --map):")
    w_topic = min(max(len(r["topic"]) for r in rows), 40)
    w_role = min(max(len(str(r["role"])) for r in rows), 32)
    for r in rows:
        print(
            f"    {r['topic']:<{w_topic}}  {str(r['role']):<{w_role}}  "
            f"{r['written']}/{r['messages']}  {r['reason']}"
        )


def run(args: argparse.Namespace) -> int:
    """Run ``robogs convert``; returns the exit code."""
    from robogs.convert.ingest.context import ConvertOptions
    from robogs.convert.ingest.convert import convert_path
    from robogs.convert.ingest.roles import (
        load_frame_map,
        load_role_map,
        parse_frame_flags,
        parse_topic_flags,
    )

    if args.list_formats:
        for name in available_converters():
            print(f"{name:12s} {get_converter(name).description}")
        return 0
    if args.src is None or args.out is None:
        print("robogs convert: error: SRC and OUT are required", file=sys.stderr)
        return 2
    from robogs.convert.registry import detect_format

    roles = {}
    tf_objects: dict[str, str] = {}
    tf_cameras: dict[str, str] = {}
    sfm = getattr(args, "sfm", False)
    fmt = args.fmt or (detect_format(args.src).name if args.src.exists() and not sfm else None)
    tabular = fmt == "tabular"
    if args.map is not None and not tabular:
        roles.update({t: str(r) for t, r in load_role_map(args.map).items()})
        tf_objects, tf_cameras = load_frame_map(args.map)
    tf_objects.update(parse_frame_flags(args.tf_object, "--tf-object"))
    tf_cameras.update(parse_frame_flags(args.tf_camera, "--tf-camera"))
    if not args.tf_tolerance_ms >= 0:
        raise InputError("--tf-tolerance-ms must be >= 0", where="--tf-tolerance-ms")
    roles.update({t: str(r) for t, r in parse_topic_flags(args.topic).items()})
    if args.assume_fps is not None and not args.assume_fps > 0:
        raise InputError("--assume-fps must be positive", where="--assume-fps")
    progress = sys.stderr.isatty() if args.progress is None else bool(args.progress)
    opts = ConvertOptions(
        roles=roles,
        urdf=args.urdf,
        package_roots=_pairs(args.package, "--package"),
        episode=args.episode,
        world_frame=args.world_frame,
        camera_file=args.camera,
        camera_name=args.camera_name,
        stamps_csv=args.stamps,
        assume_fps=args.assume_fps,
        offset_ns=args.offset_ns,
        joints_csv=args.joints,
        images=args.images,
        world_up=args.world_up,
        video=not args.no_video,
        mapping=args.map if tabular else None,
        tf_objects=tf_objects,
        tf_auto_objects=not args.no_tf_objects,
        tf_cameras=tf_cameras,
        tf_tolerance_ns=int(round(args.tf_tolerance_ms * 1e6)),
        progress=progress,
        command="robogs convert " + " ".join(shlex.quote(a) for a in sys.argv[2:])
        if sys.argv[1:2] == ["convert"]
        else None,
    )
    if sfm:
        from robogs.convert.ingest.sfm import convert_sfm

        ds, res = convert_sfm(
            args.src, args.out, options=opts, force=args.force, threads=args.sfm_threads
        )
        print(
            f"wrote {args.out} (structure from motion: {res.registered} of {res.total} images "
            f"registered, {res.points} points, reprojection {res.reprojection_px:.2f} px; "
            "frame arbitrary: run robogs reconstruct --align apply)"
        )
        return 0
    if getattr(args, "ray", None) is not None or any(c in str(args.src) for c in "*?["):
        from robogs.convert.distributed import run_many

        return run_many(args, opts)
    ds = convert_path(args.src, args.out, fmt=args.fmt, options=opts, force=args.force)
    summary = _summary(ds, args.out)
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"wrote {args.out} ({summary['converter']})")
    for e in summary["episodes"]:
        print(
            f"  episode {e['id']}: {', '.join(e['streams'])} "
            f"({(e['end_ns'] - e['start_ns']) / 1e9:.3f} s)"
        )
    if summary["cameras"]:
        print(f"  cameras: {', '.join(summary['cameras'])}")
    print(f"  robot: {'yes' if summary['robot'] else 'no'}")
    for d in summary["dropped"]:
        reasons = "; ".join(f"{k} x{v}" for k, v in d["reasons"].items())
        print(f"  not converted: {d['topic']} ({d['type']}) x{d['messages']}: {reasons}")
    for u in summary["undecodable"]:
        print(
            f"  undecodable: {u['topic']} ({u['schema']}, {u['message_encoding']}) x{u['messages']}"
        )
    for i in summary["issues"]:
        print(
            f"  issue: {i['topic']}: {i['problem']} x{i['count']} (first stamps {i['stamps_ns'][:3]})"
        )
    for n in summary["notes"]:
        print(f"  note: {n}")
    _print_roles(summary["roles"])
    dec = summary["decoded"]
    if dec:
        print(
            f"  decoded: {dec['messages']} messages of {dec['topics']} topics, "
            f"{dec['undecodable']} undecodable"
            + (f"; custom types: {', '.join(dec['custom_types'])}" if dec["custom_types"] else "")
            + (f"; ignored: {', '.join(dec['ignored_topics'])}" if dec["ignored_topics"] else "")
        )
    for name, pkg in sorted((summary["packages"] or {}).items()):
        print(f"  package://{name}: {pkg['path']} ({pkg['how']})")
    return 0

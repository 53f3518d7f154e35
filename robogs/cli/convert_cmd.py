"""``robogs convert SRC OUT``: ingest a bag, MCAP, video, image folder or capture into a dataset.

Exit codes: 0 converted, 2 usage error or unusable input (one line on stderr, no traceback).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from robogs.format.errors import InputError

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare the options of ``robogs convert``: the shared core, then each converter's own
    group (its registry entry's ``options.add_arguments``)."""
    from robogs.convert.ingest.option_flags import add_video_flag
    from robogs.convert.registry import available_converters, options_of

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
    g = parser.add_argument_group("shared by the converters")
    g.add_argument(
        "--map",
        type=Path,
        metavar="YAML",
        help="read by the source's converter: for a bag/MCAP a topic -> role (and TF frame) "
        "mapping; for a tabular joint log its column mapping",
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
    g.add_argument("--urdf", type=Path, help="robot URDF (copied with its meshes into robot/)")
    g.add_argument(
        "--package",
        action="append",
        default=[],
        metavar="NAME=FOLDER",
        help="folder of a package:// name used by the URDF's meshes",
    )
    g.add_argument(
        "--split-at-gaps",
        nargs="?",
        const="auto",
        default=None,
        metavar="SECONDS",
        help="cut each episode where every stream pauses longer than SECONDS (default: 10x the "
        "median period of the densest stream, printed) into episodes <episode>_000, ...",
    )
    add_video_flag(g)  # read by bags, videos and captures (each declares it once)
    # each converter adds its own group (registry: Converter.options)
    seen: set[int] = set()
    for conv in available_converters().values():
        spec = options_of(conv)
        if spec is not None and id(spec.add_arguments) not in seen:
            seen.add(id(spec.add_arguments))
            spec.add_arguments(parser)
    g = parser.add_argument_group("structure from motion")
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
        "(episode epKKKK per bag, cut into epKKKK_000, ... with --split-at-gaps); no ADDRESS "
        "starts a local cluster, 'auto' joins the running "
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
        "split_at_gaps": prov.get("split_at_gaps"),
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


def _split_gap(value: str | None) -> tuple[bool, float | None]:
    """``--split-at-gaps [SECONDS]`` -> (split, gap in s or None for the derived one)."""
    if value is None:
        return False, None
    if value == "auto":
        return True, None
    try:
        gap = float(value)
    except ValueError:
        gap = float("nan")
    if not (gap > 0 and gap < 1e9):
        raise InputError(
            f"--split-at-gaps expects a positive number of seconds, got {value!r}",
            where="--split-at-gaps",
        )
    return True, gap


def _source_format(args: argparse.Namespace, sfm: bool) -> str | None:
    """The converter that will run: ``--from``, else detected (the first match of a glob)."""
    from robogs.convert.registry import detect_format

    if args.fmt:
        return args.fmt
    if sfm:
        return "colmap"  # the poses recovered by --sfm are converted as a COLMAP model
    src = args.src
    if not src.exists() and any(c in str(src) for c in "*?["):
        import glob

        first = sorted(glob.glob(str(src)))[:1]
        src = Path(first[0]) if first else src
    return detect_format(src).name if src.exists() else None


def _print_cuts(records: list[dict] | None) -> None:
    """The cut table of ``--split-at-gaps``: the gap, then each piece and the pause after it."""
    for rec in records or []:
        how = (
            f"derived: {rec['gap_s'] / rec['median_period_s']:.0f} x the median period "
            f"{rec['median_period_s'] * 1e3:.3g} ms of {rec['densest']}"
            if rec["derived"]
            else "given"
        )
        print(
            f"  split {rec['episode']} at pauses > {rec['gap_s']:.3g} s ({how}): "
            f"{len(rec['episodes'])} episode(s)"
        )
        cuts = rec["cuts"]
        for k, e in enumerate(rec["episodes"]):
            pause = (
                f"  then pause {cuts[k]['pause_s']:.3f} s, cut at {cuts[k]['cut_ns']}"
                if k < len(cuts)
                else ""
            )
            print(
                f"    {e['id']:<16} {e['start_ns']} .. {e['end_ns']} "
                f"({(e['end_ns'] - e['start_ns']) / 1e9:.3f} s){pause}"
            )


def run(args: argparse.Namespace) -> int:
    """Run ``robogs convert``; returns the exit code."""
    from robogs.convert.ingest.context import ConvertOptions
    from robogs.convert.ingest.convert import convert_path
    from robogs.convert.ingest.roles import parse_topic_flags
    from robogs.convert.registry import available_converters, get_converter, options_of

    if args.list_formats:
        for name in available_converters():
            print(f"{name:12s} {get_converter(name).description}")
        return 0
    if args.src is None or args.out is None:
        print("robogs convert: error: SRC and OUT are required", file=sys.stderr)
        return 2
    sfm = getattr(args, "sfm", False)
    fmt = _source_format(args, sfm)
    spec = options_of(get_converter(fmt)) if fmt else None
    split, gap_s = _split_gap(args.split_at_gaps)
    progress = sys.stderr.isatty() if args.progress is None else bool(args.progress)
    opts = ConvertOptions(
        roles={t: str(r) for t, r in parse_topic_flags(args.topic).items()},
        urdf=args.urdf,
        package_roots=_pairs(args.package, "--package"),
        episode=args.episode,
        progress=progress,
        split_gaps=split,
        split_gap_s=gap_s,
        source=spec.options_from_args(args) if spec is not None else None,
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
        # one task per bag; with --split-at-gaps each task cuts its own bag
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
    _print_cuts(summary["split_at_gaps"])
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

"""``robogs export FORMAT DATASET OUT``: write a dataset out in another format, atomically.

Formats come from :func:`robogs.convert.export.available_exporters` (built-in: urdf, usd, mcap,
ply, rerun; more through the ``robogs.exporters`` entry-point group). A flag a format does
not take is a usage error. OUT is written to a temporary sibling and renamed into place; an
existing OUT is replaced only with ``--force``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robogs.format.errors import InputError

if TYPE_CHECKING:
    from robogs.convert.export import ExportReport

__all__ = ["add_arguments", "run", "options_from_args", "print_report"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare ``robogs export``'s arguments."""
    from robogs.convert.export import available_exporters

    formats = available_exporters()
    parser.add_argument(
        "format",
        choices=sorted(formats),
        metavar="FORMAT",
        help="; ".join(f"{n}: {e.help}" for n, e in formats.items()),
    )
    parser.add_argument("dataset", type=Path, metavar="DATASET", help="dataset folder")
    parser.add_argument("out", type=Path, metavar="OUT", help="output file (folder for urdf)")
    parser.add_argument("--force", action="store_true", help="replace OUT if it exists")
    parser.add_argument("--episode", help="episode id (mcap, ply, rerun; default: the only one)")
    parser.add_argument(
        "--t-ns",
        type=int,
        dest="t_ns",
        help="ply: pose the splats at this dataset time, ns (default: rest state)",
    )
    parser.add_argument(
        "--with-binding",
        action="store_true",
        default=None,
        dest="with_binding",
        help="ply: append the binding columns",
    )
    parser.add_argument(
        "--sh-degree",
        type=int,
        dest="sh_degree",
        metavar="D",
        help="ply: write SH of degree D, higher bands zero-padded (3 for the reference 3DGS "
        "loader; default: the data's degree)",
    )
    parser.add_argument(
        "--no-objects",
        action="store_false",
        default=None,
        dest="objects",
        help="urdf, usd: leave out the scene objects",
    )
    parser.add_argument(
        "--image-format",
        choices=("png", "jpeg"),
        dest="image_format",
        help="mcap: encoding of camera frames (default png, lossless)",
    )
    parser.add_argument(
        "--max-hz",
        type=float,
        dest="max_hz",
        help="rerun: downsampling rate of transforms and images (default 60; 0 = all)",
    )
    parser.add_argument(
        "--rerender",
        action="store_true",
        default=None,
        help="rerun: add labels re-rendered from the bound splats and their difference to the "
        "recorded labels (slow: seconds per frame on a CPU)",
    )
    parser.add_argument(
        "--rerender-stride",
        type=int,
        dest="rerender_stride",
        metavar="K",
        help="rerun: re-render every K-th labelled frame (default 10)",
    )
    parser.add_argument(
        "--state",
        choices=("joints", "ee"),
        help="lerobot: observation.state / action from joint positions (default) or EE poses",
    )
    parser.add_argument(
        "--fps", type=int, help="lerobot: rate of the regular frame grid (default: camera rate)"
    )
    parser.add_argument(
        "--with-labels",
        action="store_true",
        default=None,
        dest="labels",
        help="lerobot: add panoptic label (and rendered depth) image features",
    )
    parser.add_argument("--json", action="store_true", help="print the report as JSON")


_OPTION_FLAGS = {
    "episode": "--episode",
    "t_ns": "--t-ns",
    "with_binding": "--with-binding",
    "sh_degree": "--sh-degree",
    "objects": "--no-objects",
    "image_format": "--image-format",
    "max_hz": "--max-hz",
    "rerender": "--rerender",
    "rerender_stride": "--rerender-stride",
    "state": "--state",
    "fps": "--fps",
    "labels": "--with-labels",
}


def options_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The format options the user set (flags left at their default are not passed)."""
    return {k: getattr(args, k) for k in _OPTION_FLAGS if getattr(args, k, None) is not None}


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def print_report(report: ExportReport, *, as_json: bool = False) -> None:
    """Print what was written: one line per note, or the report as JSON."""
    size = _size(report.out)
    if as_json:
        doc = {
            "out": str(report.out),
            "bytes": size,
            "files": report.files,
            "notes": report.notes,
            "facts": report.facts,
        }
        print(json.dumps(doc, indent=2, default=str))
        return
    print(f"wrote {report.out} ({size / 1e6:.2f} MB, {len(report.files)} file(s))")
    for note in report.notes:
        print(f"  note: {note}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    """Export; 0 on success (errors are ``RobogsError``, printed by the dispatcher)."""
    from robogs.convert.export import export, get_exporter

    options = options_from_args(args)
    accepted = get_exporter(args.format).options()
    unknown = [_OPTION_FLAGS[k] for k in options if k not in accepted]
    if unknown:
        raise InputError(
            f"{', '.join(unknown)} does not apply to the {args.format} export",
            hint=f"{args.format} takes {', '.join(_OPTION_FLAGS[k] for k in sorted(accepted) if k in _OPTION_FLAGS) or 'no options'}",
        )
    if args.format == "mjcf":  # the robot pusher is measured by the physics (h80)
        from robogs.physics.export_pusher import robot_pusher_paths

        paths = robot_pusher_paths(args.dataset)
        if paths is not None:
            options["robot_pusher"] = paths
    report = export(args.format, args.dataset, args.out, force=args.force, **options)
    print_report(report, as_json=args.json)
    return 0

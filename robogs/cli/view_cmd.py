"""``robogs view DATASET``: write a Rerun recording of a dataset and open it in the viewer.

Without ``--out`` the recording goes to a temporary file and the viewer is started; with
``--out X.rrd`` it is kept there and the viewer starts only with ``--spawn``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from robogs.format.errors import InputError

__all__ = ["add_arguments", "run", "viewer_command"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare ``robogs view``'s arguments."""
    parser.add_argument("dataset", type=Path, metavar="DATASET", help="dataset folder")
    parser.add_argument("--out", type=Path, help="keep the recording here (.rrd)")
    parser.add_argument(
        "--spawn",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="start the Rerun viewer on the recording (default: only without --out)",
    )
    parser.add_argument("--episode", help="episode id (default: the first)")
    parser.add_argument(
        "--max-hz",
        type=float,
        default=60.0,
        dest="max_hz",
        help="downsampling rate of transforms and images (0 = all samples)",
    )
    parser.add_argument(
        "--rerender",
        action="store_true",
        help="add labels re-rendered from the bound splats (slow: seconds per frame on a CPU)",
    )
    parser.add_argument(
        "--rerender-stride",
        type=int,
        default=10,
        dest="rerender_stride",
        metavar="K",
        help="re-render every K-th labelled frame (default 10)",
    )
    parser.add_argument("--force", action="store_true", help="replace --out if it exists")


def viewer_command(rrd: Path) -> list[str]:
    """The command that opens ``rrd`` in the Rerun viewer shipped with rerun-sdk."""
    exe = shutil.which("rerun")
    return [exe, str(rrd)] if exe else [sys.executable, "-m", "rerun", str(rrd)]


def run(args: argparse.Namespace) -> int:
    """Write the recording, then start the viewer if asked."""
    from robogs.cli.export_cmd import print_report
    from robogs.convert.export import export

    out = args.out
    force = args.force
    if out is None:
        out = (
            Path(tempfile.mkdtemp(prefix="robogs-view-"))
            / f"{Path(args.dataset).resolve().name}.rrd"
        )
    spawn = args.spawn if args.spawn is not None else args.out is None
    report = export(
        "rerun",
        args.dataset,
        out,
        force=force,
        episode=args.episode,
        max_hz=args.max_hz,
        rerender=args.rerender,
        rerender_stride=args.rerender_stride,
    )
    print_report(report)
    if spawn:
        try:
            subprocess.Popen(viewer_command(out), start_new_session=True)  # noqa: S603 - fixed command
        except OSError as exc:
            raise InputError(
                f"could not start the Rerun viewer ({exc.strerror})",
                path=out,
                hint="open the file with 'rerun FILE.rrd' on a machine with a display",
            ) from None
        print(f"opened {out} in the Rerun viewer")
    return 0

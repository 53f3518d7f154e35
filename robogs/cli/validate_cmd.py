"""``robogs validate DATASET`` (short form ``robogs-validate``): check a dataset against the spec.

Exit codes: 0 no finding at or above ``--fail-on``; 1 some; 2 usage error or
unreadable input (no manifest, malformed manifest JSON, unknown budget name).

The binding checks re-render camera frames. By default they compare as many frames as a
time budget allows (``--rerender-budget``, default 4 s for all camera streams together, at
the per-frame cost measured on the dataset) and say so in a note under the report; ``--full``
compares every frame. ``--json-out FILE`` writes the JSON report beside the text output of
the same run. Threads (torch, OpenMP, BLAS and the label decoder) follow ``--threads``
(handled by :mod:`robogs.cli.main`; default: the cores this process may use).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from robogs.format.errors import RobogsError

__all__ = ["add_arguments", "run"]


def _csv(text: str) -> list[str]:
    return [p.strip() for p in text.split(",") if p.strip()]


def _budget(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"budget {name!r}: {value!r} is not a number") from None
    if not number >= 0:
        raise argparse.ArgumentTypeError(f"budget {name!r} must be a non-negative number")
    return name.strip(), number


def _stride(text: str) -> int:
    try:
        k = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if k < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {k}")
    return k


def _seconds(text: str) -> float:
    try:
        f = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds > 0, got {text!r}") from None
    if not f > 0.0 or f == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds > 0, got {text}")
    return f


def _scale(text: str) -> float:
    try:
        f = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 4], got {text!r}") from None
    if not 0.0 < f <= 4.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 4], got {text}")
    return f


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``validate`` options to ``parser``."""
    parser.add_argument(
        "dataset", nargs="?", type=Path, help="dataset folder (holding manifest.json)"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object to stdout")
    parser.add_argument(
        "--json-out",
        type=Path,
        metavar="FILE",
        help="also write the JSON report to FILE (atomically), beside the text output",
    )
    parser.add_argument("--junit", type=Path, metavar="FILE", help="also write JUnit XML to FILE")
    parser.add_argument(
        "--markdown", type=Path, metavar="FILE", help="also write a Markdown report to FILE"
    )
    parser.add_argument(
        "--select",
        type=_csv,
        action="extend",
        default=[],
        metavar="CODES",
        help="run only these checks: codes, prefixes or groups, comma-separated (e.g. T,G007,schema)",
    )
    parser.add_argument(
        "--ignore",
        type=_csv,
        action="extend",
        default=[],
        metavar="CODES",
        help="leave out these checks (same syntax as --select)",
    )
    parser.add_argument(
        "--fail-on",
        choices=("error", "warning", "info", "never"),
        default="error",
        help="exit 1 when a finding is at or above this severity (default: error)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="read only the manifest and parquet footers (no hashing, no table bodies)",
    )
    parser.add_argument(
        "--budget",
        type=_budget,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a budget, e.g. --budget geometry.fk_ee_mm=1.0 (repeatable)",
    )
    parser.add_argument(
        "--stride",
        type=_stride,
        metavar="N",
        help="binding checks: candidate frames are every N-th camera frame (default 1)",
    )
    parser.add_argument(
        "--full",
        action="store_true",
        help="binding checks: re-render every candidate frame and fit on 8 frames, "
        "whatever it costs (default: stay within --rerender-budget)",
    )
    parser.add_argument(
        "--rerender-budget",
        type=_seconds,
        metavar="S",
        help="binding checks: wall seconds the re-rendering of all camera streams should take; "
        "frame counts follow from the per-frame cost measured on the dataset (default 4)",
    )
    parser.add_argument(
        "--scale",
        type=_scale,
        metavar="F",
        help="binding checks: re-render at F times the camera resolution, in (0, 4] (default 1)",
    )
    parser.add_argument(
        "--ray",
        nargs="?",
        const="local",
        metavar="ADDRESS",
        help="split per-episode and per-file checks into Ray tasks (same findings as one "
        "process): no ADDRESS starts a local cluster, 'auto' joins the running one "
        "(needs pip install 'robogs[scale]'; docs/scale.md)",
    )
    parser.add_argument(
        "--episodes-per-task",
        type=_stride,
        default=None,
        metavar="N",
        help="with --ray: episodes per task (default 25)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument(
        "--list-checks",
        action="store_true",
        help="list the registered checks and exit (with --markdown FILE: write the catalogue table)",
    )


def _err(msg: str) -> int:
    print(f"robogs validate: error: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    """Validate ``args.dataset``; returns the exit code."""
    from rich.console import Console

    from robogs.format.checks import available_checks
    from robogs.format.report_formats import (
        catalogue_markdown,
        render_check_list,
        write_atomic,
    )
    from robogs.format.validate import validate

    if args.list_checks:
        checks = list(available_checks().values())
        if args.json:
            import json

            print(
                json.dumps(
                    [
                        {
                            "code": c.code,
                            "group": c.group,
                            "severity": c.severity,
                            "title": c.title,
                            "quick": not c.needs_full,
                            "budget": c.budget,
                            "unit": c.unit,
                            "quantity": c.quantity,
                            "hint": c.hint,
                        }
                        for c in checks
                    ],
                    indent=2,
                )
            )
        else:
            render_check_list(checks, Console())
        if args.markdown is not None:
            from robogs.format.validate import RUNNER_CODES

            write_atomic(args.markdown, catalogue_markdown(checks, RUNNER_CODES))
        return 0
    if args.dataset is None:
        return _err("the DATASET folder is required (or --list-checks)")
    if args.full and args.rerender_budget is not None:
        return _err("--full compares every frame; leave out --rerender-budget")
    for out in (args.json_out, args.junit, args.markdown):
        if out is not None and not out.parent.is_dir():
            return _err(f"cannot write report {out}: folder {out.parent} does not exist")
    progress = not args.no_progress and not args.json and sys.stderr.isatty()
    options = {k: getattr(args, k) for k in ("stride", "scale") if getattr(args, k) is not None}
    if args.full:
        options["full"] = True
    if args.rerender_budget is not None:
        options["budget_s"] = args.rerender_budget
    if getattr(args, "ray", None):
        from robogs.cli.scale_cmd import validate_ray

        try:
            report = validate_ray(args, progress=progress, options=options)
        except RobogsError as exc:
            return _err(exc.one_line())
        return _emit(args, report)
    try:
        report = validate(
            args.dataset,
            select=args.select,
            ignore=args.ignore,
            quick=args.quick,
            budgets=dict(args.budget),
            progress=progress,
            options=options,
            label_threads=_threads(args),
        )
    except RobogsError as exc:
        return _err(exc.one_line())
    return _emit(args, report)


def _emit(args: argparse.Namespace, report) -> int:
    """Print and write the report; the exit code."""
    from rich.console import Console

    from robogs.format.report_formats import (
        render_text,
        to_json,
        to_junit,
        to_markdown,
        write_atomic,
    )

    text = to_json(report) + "\n"
    if args.json:
        sys.stdout.write(text)
    else:
        render_text(report, Console(highlight=False))
    try:
        if args.json_out is not None:
            write_atomic(args.json_out, text)
        if args.junit is not None:
            write_atomic(args.junit, to_junit(report, fail_on=args.fail_on))
        if args.markdown is not None:
            write_atomic(args.markdown, to_markdown(report))
    except OSError as exc:
        return _err(f"cannot write report: {exc}")
    return 1 if report.failed(args.fail_on) else 0


def _threads(args: argparse.Namespace) -> int:
    """Label-decoder threads: the count ``robogs.cli.main`` gave torch, OpenMP and BLAS.

    ``--threads`` if given, else an exported ``OMP_NUM_THREADS`` (which ``main`` sets), else the
    cores this process may use (:func:`robogs.cli.threads.resolve_threads`).
    """
    from robogs.cli.threads import resolve_threads

    n = getattr(args, "threads", None)
    return resolve_threads(n if isinstance(n, int) and n >= 1 else None)

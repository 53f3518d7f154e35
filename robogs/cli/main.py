"""``robogs <verb>`` entry point.

Each verb lives in its own module, imported only when used, exposing
``add_arguments(parser)`` and ``run(args) -> int``. Exit codes: 0 clean,
1 findings at or above ``--fail-on`` (or a failed comparison), 2 usage error or
unreadable input. A ``RobogsError`` is printed as one line, never a traceback.

``--threads N`` (anywhere on the line, every verb, ``robogs-validate`` too) sizes the
torch, OpenMP and BLAS pools; default: the cores this process may use. It is applied before
the verb module, and so numpy and torch, is imported (:mod:`robogs.cli.threads`), which is
why this module imports nothing heavy at its top.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from robogs.cli import threads

__all__ = ["main", "validate_main", "VERBS"]

#: verb -> (module implementing it, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "synth": (
        "robogs.cli.synth_cmd",
        "generate a synthetic scene (optionally with a hidden physical effect)",
    ),
    "validate": ("robogs.cli.validate_cmd", "check a dataset against the spec"),
    "migrate": ("robogs.cli.migrate_cmd", "rewrite a dataset into the sharded (chunked) layout"),
    "convert": (
        "robogs.cli.convert_cmd",
        "convert a bag, MCAP, video, capture or joint log into a dataset",
    ),
    "export": (
        "robogs.cli.export_cmd",
        "export a dataset to URDF, USD, MCAP, splat PLY or Rerun",
    ),
    "view": ("robogs.cli.view_cmd", "write a Rerun recording of a dataset and open it"),
    "render": (
        "robogs.cli.render_cmd",
        "render a new joint trajectory through the binding into a dataset",
    ),
    "compare": (
        "robogs.cli.physics_cmd",
        "residuals of the physics model against the measurements",
    ),
    "diagnose": ("robogs.cli.physics_cmd", "rank the physical effects the model is missing"),
    "fit": ("robogs.cli.physics_cmd", "add effects, refit and write a new physics revision"),
    "report": ("robogs.cli.physics_cmd", "HTML report with residual plots before and after"),
    "physics": (
        "robogs.cli.physics_init_cmd",
        "physics.json from the data: init, show, set KEY=VALUE",
    ),
    "reconstruct": (
        "robogs.cli.reconstruct_cmd",
        "fill splats, meshes and binding from multi-view frames",
    ),
    "evaluate": ("robogs.cli.reconstruct_cmd", "image and mesh quality metrics"),
    "roles": (
        "robogs.cli.roles_cmd",
        "list stream roles with reasons; set: re-role a generic stream",
    ),
    "plugins": (
        "robogs.cli.plugins_cmd",
        "list the checks, converters, exporters, effects, backends and layers, with status",
    ),
    "demo": (
        "robogs.cli.demo_cmd",
        "synthesise the default scene, validate it and write the report",
    ),
}


def _load(verb: str):
    from robogs.format.errors import RobogsError

    module_name, _ = VERBS[verb]
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise RobogsError(
            f"'{verb}' is not available in this installation ({exc.name} missing)",
            hint="reinstall robogs with its dependencies",
        ) from None


def _parser(verbs: Sequence[str]) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="robogs", description="Real2Sim digital twins of robot-arm scenes."
    )
    _threads_option(parser)
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for verb in verbs:
        _, help_text = VERBS[verb]
        p = sub.add_parser(verb, help=help_text, description=help_text)
        p.set_defaults(_verb=verb)
    return parser


def _threads_option(p: argparse.ArgumentParser) -> None:
    if any("--threads" in a.option_strings for a in p._actions):
        return  # the verb has its own, with the same meaning
    p.add_argument(
        "--threads",
        type=int,
        default=None,
        metavar="N",
        help="torch, OpenMP and BLAS threads (default: the cores this process may use, "
        f"here {threads.available_cores()}; OMP_NUM_THREADS if exported)",
    )


def _strip_global_threads(argv: list[str]) -> list[str]:
    """``robogs --threads N VERB ...`` -> ``VERB ...`` (the value was already applied)."""
    while argv and (argv[0] == "--threads" or argv[0].startswith("--threads=")):
        argv = argv[2:] if argv[0] == "--threads" else argv[1:]
    return argv


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``robogs [--threads N] VERB ...``; returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        n = threads.resolve_threads(threads.parse_threads(argv))
    except ValueError as exc:
        print(f"robogs: error: {exc}", file=sys.stderr)
        return 2
    with threads.applied(n):
        return _main(_strip_global_threads(argv))


def _main(argv: list[str]) -> int:
    from robogs.format.errors import RobogsError

    parser = _parser(list(VERBS))
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in VERBS:
        if argv and argv[0] not in ("-h", "--help"):
            print(
                f"robogs: unknown verb {argv[0]!r}; choose from {', '.join(VERBS)}", file=sys.stderr
            )
            return 2
        parser.print_help()
        return 0 if argv else 2
    verb = argv[0]
    try:
        module = _load(verb)
        p = argparse.ArgumentParser(prog=f"robogs {verb}", description=VERBS[verb][1])
        if hasattr(module, "add_arguments_for"):
            module.add_arguments_for(verb, p)
        else:
            module.add_arguments(p)
        _threads_option(p)
        try:
            args = p.parse_args(argv[1:])
        except SystemExit as exc:  # argparse prints its own usage message
            return 0 if exc.code == 0 else 2
        args.verb = verb
        return int(module.run(args) or 0)
    except RobogsError as exc:
        print(f"robogs {verb}: error: {exc.one_line()}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"robogs {verb}: interrupted; nothing was changed", file=sys.stderr)
        return 130


def validate_main(argv: Sequence[str] | None = None) -> int:
    """``robogs-validate DATASET`` — the short form of ``robogs validate``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    return main(["validate", *argv])


def _entry() -> None:  # pragma: no cover - console script shim
    sys.exit(main())

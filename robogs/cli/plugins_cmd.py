"""``robogs plugins``: every extension point's entries, with status, source and reason.

Lists the registries of :mod:`robogs.format.plugins` (checks, converters, exporters, effects,
render backends, Rerun layers), built-in entries and installed plug-ins alike. A registry
whose module cannot be imported (an optional dependency missing) is shown as one unavailable
line. ``--compare-backend NAME`` renders a small seeded scene with backend ``NAME`` and with
the brute-force ``dense`` oracle and prints the largest difference, so a backend author can
check a plug-in end to end.

Exit codes: 0 listed (or the backend agrees with the oracle), 1 the backend disagrees,
2 usage error or an unavailable backend.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from typing import Any

from robogs.format.errors import RobogsError
from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, PluginError

__all__ = ["add_arguments", "run", "REGISTRIES", "all_entries", "compare_backend"]

#: registry kind -> module holding its ``REGISTRY`` (imported only when listed)
REGISTRIES: dict[str, str] = {
    "checks": "robogs.format.checks.registry",
    "converters": "robogs.convert.registry",
    "exporters": "robogs.convert.export",
    "effects": "robogs.physics.effects",
    "backends": "robogs.format.render.backends",
    "layers": "robogs.format.qa.rerun_log",
}

#: largest |rgb| and |alpha| difference to the dense oracle accepted by --compare-backend
#: (the built-in tiled backend stays below 1e-6 on the probe scene in float64)
COMPARE_TOL = 1e-4


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Declare ``robogs plugins``' arguments."""
    parser.add_argument(
        "--kind",
        action="append",
        choices=sorted(REGISTRIES),
        help="list only this registry (repeatable; default: all)",
    )
    parser.add_argument("--json", action="store_true", help="machine-readable output")
    parser.add_argument(
        "--compare-backend",
        metavar="NAME",
        dest="compare_backend",
        help="render a seeded probe scene with backend NAME and with 'dense'; print the difference",
    )


def all_entries(kinds: list[str] | None = None) -> list[Entry[Any]]:
    """Entries of the chosen registries (default: all), registry by registry."""
    out: list[Entry[Any]] = []
    for kind in kinds or list(REGISTRIES):
        try:
            registry = importlib.import_module(REGISTRIES[kind]).REGISTRY
        except ImportError as exc:
            out.append(Entry(kind, "*", None, "unavailable", f"cannot import: {exc}", "builtin"))
            continue
        out.extend(registry.entries())
    return out


def compare_backend(name: str, *, n: int = 64, seed: int = 0) -> dict[str, Any]:
    """Render ``n`` seeded Gaussians with backend ``name`` and with ``dense`` (float64, CPU).

    Returns:
        ``{"backend", "gaussians", "width", "height", "max_abs_rgb", "max_abs_alpha"}``.

    Raises:
        InputError / PluginError: unknown or unavailable backend.
    """
    import torch

    from robogs.format.render import Camera, Gaussians, render
    from robogs.format.render.backends import get_backend

    get_backend(name)  # unknown or unavailable: a clear error before any work
    gen = torch.Generator().manual_seed(seed)
    dt = torch.float64
    means = torch.randn(n, 3, generator=gen, dtype=dt) * 0.3
    means[:, 2] += 2.0  # in front of the camera at the origin, looking along +z
    g = Gaussians(
        means=means,
        quats=torch.randn(n, 4, generator=gen, dtype=dt),
        log_scales=torch.log(torch.rand(n, 3, generator=gen, dtype=dt) * 0.08 + 0.01),
        opacity_logits=torch.randn(n, generator=gen, dtype=dt),
        sh=torch.randn(n, 1, 3, generator=gen, dtype=dt) * 0.4,
    )
    cam = Camera(
        width=40, height=30, fx=40.0, fy=40.0, cx=20.0, cy=15.0, T_world_cam=torch.eye(4, dtype=dt)
    )
    try:
        out = render(g, cam, backend=name)
    except RobogsError:
        raise
    except Exception as exc:  # a plug-in's bug, reported in one line
        raise PluginError(
            f"render backend {name!r} raised {type(exc).__name__}: {exc}",
            hint="fix the backend; it must return a RenderOutput for a pinhole camera",
        ) from None
    ref = render(g, cam, backend="dense")
    return {
        "backend": name,
        "gaussians": n,
        "width": cam.width,
        "height": cam.height,
        "max_abs_rgb": float((out.rgb - ref.rgb).abs().max()),
        "max_abs_alpha": float((out.alpha - ref.alpha).abs().max()),
    }


def _print_table(entries: list[Entry[Any]]) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="robogs plug-ins", show_lines=False)
    for col in ("kind", "name", "status", "source", "reason"):
        table.add_column(col)
    for e in entries:
        status = "ok" if e.ok else "[red]unavailable[/red]"
        table.add_row(e.kind, e.name, status, e.source, e.reason)
    Console(width=160).print(table)
    groups = ", ".join(sorted(set(ENTRY_POINT_GROUPS.values())))
    print(f"entry-point groups: {groups}")


def run(args: argparse.Namespace) -> int:
    """List the registries (or compare a backend); returns the exit code."""
    if args.compare_backend:
        res = compare_backend(args.compare_backend)
        bad = max(res["max_abs_rgb"], res["max_abs_alpha"]) > COMPARE_TOL
        if args.json:
            print(json.dumps({**res, "tolerance": COMPARE_TOL, "agrees": not bad}))
        else:
            print(
                f"backend {res['backend']!r} vs dense on {res['gaussians']} Gaussians, "
                f"{res['width']}x{res['height']} px: max |d rgb| = {res['max_abs_rgb']:.3g}, "
                f"max |d alpha| = {res['max_abs_alpha']:.3g} "
                f"({'disagrees' if bad else 'agrees'}, tolerance {COMPARE_TOL:g})"
            )
        return 1 if bad else 0
    entries = all_entries(args.kind)
    if args.json:
        rows = [
            {
                "kind": e.kind,
                "name": e.name,
                "status": e.status,
                "source": e.source,
                "reason": e.reason,
            }
            for e in entries
        ]
        json.dump(rows, sys.stdout, indent=2)
        print()
    else:
        _print_table(entries)
    return 0

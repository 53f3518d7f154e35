"""Options of the tabular converter and its command-line flags.

The convert CLI calls :func:`add_arguments` on its parser and :func:`options_from_args` on the
parsed arguments, and hands the :class:`TabularOptions` to the converter as the shared
``ConvertOptions``'s ``source`` (:func:`from_convert_options` reads it back). ``--map`` is
shared with the bag converters (a role map there): it is read here, not added.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError

__all__ = ["TabularOptions", "add_arguments", "from_convert_options", "options_from_args"]


@dataclass(frozen=True)
class TabularOptions:
    """User choices for a tabular joint log (all optional).

    Attributes:
        mapping: column map YAML (``--map``); None: the automatic layouts.
        gap_s: a forward time jump longer than this (s) starts a new segment; None: the map's
            ``gap_s``, else max(1 s, 50 median steps).
        meshes_optional: a URDF whose meshes do not resolve is copied without its mesh
            geometry (a provenance note) instead of failing the conversion.
    """

    mapping: Path | None = None
    gap_s: float | None = None
    meshes_optional: bool = False

    def __post_init__(self) -> None:
        if self.gap_s is not None and not (math.isfinite(self.gap_s) and self.gap_s > 0):
            raise InputError(
                f"gap_s must be a positive number of seconds, got {self.gap_s!r}",
                where="--gap-s",
            )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the tabular-only flags (``--gap-s``, ``--meshes-optional``) to ``parser``."""
    group = parser.add_argument_group("tabular joint logs (CSV/Parquet)")
    group.add_argument(
        "--gap-s",
        type=float,
        default=None,
        metavar="SECONDS",
        help="a time jump longer than this starts a new segment "
        "(default: the map's gap_s, else max(1 s, 50 median steps))",
    )
    group.add_argument(
        "--meshes-optional",
        action="store_true",
        help="copy a URDF whose meshes do not resolve without its meshes (a provenance note)",
    )


def options_from_args(args: argparse.Namespace) -> TabularOptions:
    """The :class:`TabularOptions` of parsed arguments (``--map``, ``--gap-s``,
    ``--meshes-optional``; a flag the parser does not have counts as not given)."""
    mapping = getattr(args, "map", None)
    return TabularOptions(
        mapping=Path(mapping) if mapping is not None else None,
        gap_s=getattr(args, "gap_s", None),
        meshes_optional=bool(getattr(args, "meshes_optional", False)),
    )


def from_convert_options(options: Any) -> TabularOptions:
    """The tabular options of a ``ConvertOptions``: its ``source`` when that is a
    :class:`TabularOptions`, else built from the per-converter fields it answers
    (``mapping``, ``gap_s``, ``meshes_optional``; the 0.2 flat keywords)."""
    source = getattr(options, "source", None)
    if isinstance(source, TabularOptions):
        return source
    mapping = getattr(options, "mapping", None)
    return TabularOptions(
        mapping=Path(mapping) if mapping is not None else None,
        gap_s=getattr(options, "gap_s", None),
        meshes_optional=bool(getattr(options, "meshes_optional", False)),
    )

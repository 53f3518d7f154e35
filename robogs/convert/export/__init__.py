"""Exporters: a robogs dataset out to URDF, USD, MCAP, splat PLY and Rerun.

An exporter is a function ``fn(dataset, out, **options) -> ExportReport`` that writes ``out``
(a file or a folder, declared at registration) from a :class:`robogs.format.Dataset`. It is
called through :func:`export`, which makes the write atomic: ``fn`` writes a hidden temporary
sibling of ``out`` that is renamed into place only when it returns, and an existing ``out``
is replaced only with ``force=True``.

Users add formats without editing robogs, either by calling :func:`register_exporter` or by
declaring an entry point in the group ``robogs.exporters`` whose object is an
:class:`Exporter` (or a callable, registered as a file exporter)::

    [project.entry-points."robogs.exporters"]
    gltf = "my_package.gltf_export:EXPORTER"
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Literal

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, Registry

from .atomic import atomic_output

__all__ = [
    "ENTRY_POINT_GROUP",
    "Exporter",
    "ExportReport",
    "available_exporters",
    "exporter_entries",
    "REGISTRY",
    "export",
    "get_exporter",
    "register_exporter",
]

ENTRY_POINT_GROUP = ENTRY_POINT_GROUPS["exporters"]


@dataclass
class ExportReport:
    """What an exporter wrote and anything worth telling the user.

    Attributes:
        out: the final output path.
        files: paths written (relative to ``out`` for folder outputs; ``[out.name]`` for files).
        notes: one-line remarks (skipped streams, validator summaries).
        facts: machine-readable figures (message counts, validator errors, ...).
    """

    out: Path
    files: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    facts: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Exporter:
    """A registered export format.

    Attributes:
        name: format key (``robogs export NAME ...``).
        fn: ``fn(dataset, out, **options) -> ExportReport``; ``out`` is the temporary path.
        output: ``"file"`` or ``"folder"``.
        suffix: default suffix of a file output (kept on the temporary file, so libraries
            that pick the encoding from the suffix still do).
        help: one line for ``--help``.
    """

    name: str
    fn: Callable[..., ExportReport]
    output: Literal["file", "folder"] = "file"
    suffix: str = ""
    help: str = ""

    def options(self) -> set[str]:
        """Keyword options ``fn`` accepts (everything after ``dataset, out``)."""
        params = list(inspect.signature(self.fn).parameters.values())[2:]
        return {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}


_BUILTIN = {
    "urdf": "robogs.convert.export.urdf_physics",
    "usd": "robogs.convert.export.usd_physics",
    "mcap": "robogs.convert.export.ros2_mcap",
    "ply": "robogs.convert.export.splat_ply",
    "rerun": "robogs.convert.export.rerun_rrd",
    "mjcf": "robogs.convert.export.mjcf",
    "lerobot": "robogs.convert.export.lerobot",
}


def _adopt(reg: Registry[Exporter], name: str, obj: object) -> None:
    """A ``robogs.exporters`` entry point: an :class:`Exporter`, a module that registers
    exporters on import, or a function (registered as a file exporter under the entry name)."""
    if isinstance(obj, ModuleType):
        return
    if not isinstance(obj, Exporter) and not callable(obj):
        raise TypeError(f"entry point {name!r} is a {type(obj).__name__}, not an Exporter")
    register_exporter(name, obj)  # type: ignore[arg-type]


#: the exporter registry (keys: format names; a built-in module is imported when its name is asked)
REGISTRY: Registry[Exporter] = Registry(
    "exporters",
    ENTRY_POINT_GROUP,
    noun="export format",
    builtins=_BUILTIN,
    adopt=_adopt,
    module_of=lambda e: e.fn.__module__,
    unknown_where="FORMAT",
)


def register_exporter(
    name: str,
    fn: Callable[..., ExportReport] | Exporter,
    *,
    output: Literal["file", "folder"] = "file",
    suffix: str = "",
    help: str = "",
    replace: bool = False,
) -> Exporter:
    """Register an export format.

    Args:
        name: format key, e.g. ``"gltf"``.
        fn: the exporter function, or a ready :class:`Exporter`.
        output: whether ``out`` is a ``"file"`` or a ``"folder"``.
        suffix: default file suffix (e.g. ``".usda"``).
        help: one line shown by ``robogs export --help``.
        replace: allow replacing an existing registration.

    Returns:
        The registered :class:`Exporter`.

    Raises:
        RegistrationError: the name is taken by another exporter and ``replace`` is False.
    """
    exp = fn if isinstance(fn, Exporter) else Exporter(name, fn, output, suffix, help)
    return REGISTRY.register(name, exp, replace=replace)


def available_exporters() -> dict[str, Exporter]:
    """``name -> Exporter`` of every usable export format (built-in and ``robogs.exporters``
    entry points), by name; :func:`exporter_entries` also lists the unavailable ones."""
    return REGISTRY.available()


def exporter_entries() -> list[Entry[Exporter]]:
    """Every entry of the exporter registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


def get_exporter(name: str) -> Exporter:
    """The exporter registered as ``name`` (imports only that built-in's module).

    Raises:
        InputError: no such format.
        PluginError: its plug-in or an optional dependency failed to load.
    """
    return REGISTRY.get(name)


def export(
    fmt: str,
    dataset: Dataset | str | Path,
    out: str | Path,
    *,
    force: bool = False,
    **options: Any,
) -> ExportReport:
    """Export ``dataset`` to ``out`` in format ``fmt``, atomically.

    Args:
        fmt: a registered format (``urdf``, ``usd``, ``mcap``, ``ply``, ``rerun``, ...).
        dataset: an open dataset or its folder.
        out: output file or folder.
        force: replace an existing ``out``.
        **options: format options; an option the format does not take raises.

    Returns:
        The exporter's :class:`ExportReport`, with ``out`` the final path.

    Raises:
        DatasetExistsError: ``out`` exists and ``force`` is False.
        InputError: unknown format or option, or the dataset lacks what the format needs.
    """
    exp = get_exporter(fmt)
    unknown = sorted(set(options) - exp.options())
    if unknown:
        raise InputError(
            f"format {fmt!r} takes no option {', '.join(unknown)}",
            hint=f"its options: {', '.join(sorted(exp.options())) or 'none'}",
        )
    ds = dataset if isinstance(dataset, Dataset) else Dataset.open(dataset)
    out = Path(out)
    with atomic_output(
        out, folder=exp.output == "folder", force=force, sources=[ds.root], fmt=fmt
    ) as tmp:
        report = exp.fn(ds, tmp, **options)
    report.out = out
    return report

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
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Literal

from robogs.format import Dataset
from robogs.format.errors import InputError, RobogsError

from .atomic import atomic_output

__all__ = [
    "ENTRY_POINT_GROUP",
    "Exporter",
    "ExportReport",
    "available_exporters",
    "export",
    "get_exporter",
    "register_exporter",
]

ENTRY_POINT_GROUP = "robogs.exporters"


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


_REGISTRY: dict[str, Exporter] = {}
_BUILTIN = {
    "urdf": "robogs.convert.export.urdf_physics",
    "usd": "robogs.convert.export.usd_physics",
    "mcap": "robogs.convert.export.ros2_mcap",
    "ply": "robogs.convert.export.splat_ply",
    "rerun": "robogs.convert.export.rerun_rrd",
}
_loaded_entry_points = False


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
    """
    exp = fn if isinstance(fn, Exporter) else Exporter(name, fn, output, suffix, help)
    if name in _REGISTRY and not replace and _REGISTRY[name].fn is not exp.fn:
        raise InputError(
            f"an exporter named {name!r} is already registered", hint="pass replace=True"
        )
    _REGISTRY[name] = exp
    return exp


def _load_builtin(name: str) -> None:
    if name in _BUILTIN and name not in _REGISTRY:
        import_module(_BUILTIN[name])  # registers itself on import


def _load_entry_points() -> None:
    global _loaded_entry_points
    if _loaded_entry_points:
        return
    _loaded_entry_points = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _REGISTRY:
            continue
        try:
            obj = ep.load()
        except Exception as exc:  # a broken plugin must not break the built-in formats
            raise RobogsError(
                f"exporter plugin {ep.name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}",
                hint="fix or uninstall the package that declares it",
            ) from None
        register_exporter(ep.name, obj)


def available_exporters() -> dict[str, Exporter]:
    """All export formats: built-in ones and those declared in ``robogs.exporters``."""
    for name in _BUILTIN:
        _load_builtin(name)
    _load_entry_points()
    return dict(sorted(_REGISTRY.items()))


def get_exporter(name: str) -> Exporter:
    """The exporter registered as ``name``.

    Raises:
        InputError: no such format.
    """
    _load_builtin(name)
    if name not in _REGISTRY:
        _load_entry_points()
    if name not in _REGISTRY:
        raise InputError(
            f"unknown export format {name!r}",
            hint=f"choose from {', '.join(available_exporters())}",
        )
    return _REGISTRY[name]


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
    with atomic_output(out, folder=exp.output == "folder", force=force) as tmp:
        report = exp.fn(ds, tmp, **options)
    report.out = out
    return report

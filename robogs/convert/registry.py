"""Registry of ingest converters, keyed by source format name.

A converter is a name, a ``detect(path) -> bool`` predicate, and a
``convert(src, ctx)`` function that fills an :class:`~robogs.convert.ingest.context.IngestContext`
(a dataset writer plus the provenance record). The built-in converters register
themselves when this registry is first used; third-party packages add theirs
through the entry-point group ``robogs.converters``: an entry point may load to a
:class:`Converter` (registered as is) or to a callable taking no argument that
calls :func:`register_converter` itself.

Example:
    >>> from robogs.convert.registry import available_converters
    >>> "mcap" in available_converters()
    True
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import TYPE_CHECKING

from robogs.format.errors import InputError

if TYPE_CHECKING:
    from .ingest.context import IngestContext

__all__ = [
    "Converter",
    "ENTRY_POINT_GROUP",
    "register_converter",
    "available_converters",
    "get_converter",
    "detect_format",
]

ENTRY_POINT_GROUP = "robogs.converters"

#: modules under ``robogs.convert.ingest`` that register the built-in converters on import
_BUILTIN_MODULES = (
    "robogs.convert.ingest.rosbag_source",
    "robogs.convert.ingest.mcap_source",
    "robogs.convert.ingest.video",
    "robogs.convert.ingest.nerfstudio",
    "robogs.convert.ingest.colmap",
    "robogs.convert.ingest.tabular",
)

DetectFn = Callable[[Path], bool]
ConvertFn = Callable[[Path, "IngestContext"], None]


@dataclass(frozen=True)
class Converter:
    """One source format.

    Attributes:
        name: the format name used by ``robogs convert --from NAME``.
        detect: ``detect(path) -> bool``; True when ``path`` looks like this format.
        convert: ``convert(src, ctx)``; writes the dataset content through ``ctx.writer``.
        description: one line for listings.
        priority: detection order, higher first (a folder with ``transforms.json``
            is nerfstudio before it is an image folder).
    """

    name: str
    detect: DetectFn
    convert: ConvertFn
    description: str = ""
    priority: int = 0


_REGISTRY: dict[str, Converter] = {}
_LOADED = False


def register_converter(
    name: str,
    detect: DetectFn,
    convert: ConvertFn,
    *,
    description: str = "",
    priority: int = 0,
    replace: bool = False,
) -> Converter:
    """Add a converter to the registry.

    Args:
        name: format name (``[a-z0-9_-]``).
        detect: predicate on the source path.
        convert: ``convert(src, ctx)``.
        description: one line for listings.
        priority: detection order, higher first.
        replace: allow replacing an existing converter of that name.

    Returns:
        The registered :class:`Converter`.

    Raises:
        ValueError: a converter of that name exists and ``replace`` is False.
    """
    if not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ValueError(f"invalid converter name {name!r}")
    if name in _REGISTRY and not replace:
        raise ValueError(f"converter {name!r} is already registered (pass replace=True)")
    conv = Converter(name, detect, convert, description, priority)
    _REGISTRY[name] = conv
    return conv


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for mod in _BUILTIN_MODULES:
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:
            if exc.name != mod:  # a real missing dependency, not an absent optional module
                warnings.warn(f"converter module {mod} unavailable: {exc}", stacklevel=2)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            obj = ep.load()
            if isinstance(obj, Converter):
                if obj.name not in _REGISTRY:
                    _REGISTRY[obj.name] = obj
            elif callable(obj):
                obj()
        except Exception as exc:  # a broken plugin must not break the built-ins
            warnings.warn(f"converter entry point {ep.name!r} failed to load: {exc}", stacklevel=2)


def available_converters() -> list[str]:
    """Names of all registered converters (built-in and entry points), sorted."""
    _load()
    return sorted(_REGISTRY)


def get_converter(name: str) -> Converter:
    """The converter called ``name``.

    Raises:
        InputError: no such converter.
    """
    _load()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise InputError(
            f"unknown source format {name!r}",
            where="--from",
            hint=f"choose from {', '.join(sorted(_REGISTRY))}",
        ) from None


def detect_format(path: str | Path) -> Converter:
    """The converter for ``path``, found by asking each ``detect`` in priority order.

    Raises:
        InputError: the path does not exist or no converter recognises it.
    """
    _load()
    p = Path(path)
    if not p.exists():
        raise InputError("source does not exist", path=p)
    for conv in sorted(_REGISTRY.values(), key=lambda c: (-c.priority, c.name)):
        try:
            if conv.detect(p):
                return conv
        except OSError:
            continue
    raise InputError(
        "cannot tell the source format",
        path=p,
        hint=f"pass --from with one of {', '.join(sorted(_REGISTRY))}",
    )

"""Registry of ingest converters, keyed by source format name.

A converter is a name, a ``detect(path) -> bool`` predicate, and a
``convert(src, ctx)`` function that fills an :class:`~robogs.convert.ingest.context.IngestContext`
(a dataset writer plus the provenance record). The built-in converters register
themselves when this registry is first used; third-party packages add theirs
through the entry-point group ``robogs.converters``: an entry point may load to a
:class:`Converter` (registered as is), a module, or a callable taking no argument that
calls :func:`register_converter` itself. A plug-in that fails to load is listed as
unavailable (see :mod:`robogs.format.plugins`).

Example:
    >>> from robogs.convert.registry import available_converters
    >>> "mcap" in available_converters()
    True
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from robogs.format.errors import InputError
from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, RegistrationError, Registry

if TYPE_CHECKING:
    from .ingest.context import IngestContext

__all__ = [
    "Converter",
    "ENTRY_POINT_GROUP",
    "register_converter",
    "available_converters",
    "converter_entries",
    "REGISTRY",
    "get_converter",
    "detect_format",
]

ENTRY_POINT_GROUP = ENTRY_POINT_GROUPS["converters"]

#: modules under ``robogs.convert.ingest`` that register the built-in converters on import
_BUILTIN_MODULES = (
    "robogs.convert.ingest.rosbag_source",
    "robogs.convert.ingest.mcap_source",
    "robogs.convert.ingest.video",
    "robogs.convert.ingest.nerfstudio",
    "robogs.convert.ingest.colmap",
    "robogs.convert.ingest.tabular",
    "robogs.convert.ingest.lerobot",
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


def _adopt(reg: Registry[Converter], name: str, obj: object) -> None:
    """A ``robogs.converters`` entry point: a :class:`Converter`, a module that registers
    converters on import, or a callable taking no argument that registers them."""
    if isinstance(obj, Converter):
        reg.register(obj.name, obj)
    elif isinstance(obj, ModuleType):
        return
    elif callable(obj):
        obj()
    else:
        raise TypeError(f"entry point {name!r} is a {type(obj).__name__}, not a Converter")


#: the converter registry (keys: format names)
# Declared like the exporter registry (convert/export/__init__.py): same call by design.
REGISTRY: Registry[Converter] = Registry(
    "converters",
    ENTRY_POINT_GROUP,
    noun="source format",
    builtins=_BUILTIN_MODULES,
    adopt=_adopt,
    module_of=lambda c: c.convert.__module__,
    unknown_where="--from",
)


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
        RegistrationError: a malformed name, or a converter of that name exists and
            ``replace`` is False (also a ``ValueError``).
    """
    if not name or not all(c.isalnum() or c in "_-" for c in name):
        raise RegistrationError(f"invalid converter name {name!r}")
    return REGISTRY.register(
        name, Converter(name, detect, convert, description, priority), replace=replace
    )


def available_converters() -> dict[str, Converter]:
    """``name -> Converter`` of every usable converter (built-in and entry points), by name;
    :func:`converter_entries` also lists the unavailable ones with the reason."""
    return REGISTRY.available()


def converter_entries() -> list[Entry[Converter]]:
    """Every entry of the converter registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


def get_converter(name: str) -> Converter:
    """The converter called ``name``.

    Raises:
        InputError: no such converter.
        PluginError: its plug-in or an optional dependency failed to load.
    """
    return REGISTRY.get(name)


def detect_format(path: str | Path) -> Converter:
    """The converter for ``path``, found by asking each ``detect`` in priority order.

    Raises:
        InputError: the path does not exist or no converter recognises it.
    """
    p = Path(path)
    if not p.exists():
        raise InputError("source does not exist", path=p)
    convs = available_converters()
    for conv in sorted(convs.values(), key=lambda c: (-c.priority, c.name)):
        try:
            if conv.detect(p):
                return conv
        except OSError:
            continue
    raise InputError(
        "cannot tell the source format",
        path=p,
        hint=f"pass --from with one of {', '.join(convs)}",
    )

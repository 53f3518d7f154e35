"""Registry of ingest converters, keyed by source format name.

A converter is a name, a ``detect(path) -> bool`` predicate, a
``convert(src, ctx)`` function that fills an :class:`~robogs.convert.ingest.context.IngestContext`
(a dataset writer plus the provenance record), and optionally its own options
(:class:`ConverterOptions`: a dataclass, ``add_arguments(parser)`` and
``options_from_args(args)``), which the convert CLI adds as one argument group. The built-in converters register
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

import argparse
import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from robogs.format.errors import InputError
from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, RegistrationError, Registry

if TYPE_CHECKING:
    from .ingest.context import IngestContext

__all__ = [
    "Converter",
    "ConverterOptions",
    "ENTRY_POINT_GROUP",
    "register_converter",
    "available_converters",
    "converter_entries",
    "REGISTRY",
    "get_converter",
    "detect_format",
    "options_of",
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
class ConverterOptions:
    """A converter's own options and command-line flags.

    Attributes:
        type: the frozen dataclass of its options (``ConvertOptions.source`` when it runs).
        add_arguments: ``add_arguments(parser)``: adds its flags as one argument group.
        options_from_args: ``options_from_args(args) -> type``; raises ``InputError`` on a
            bad flag.
    """

    type: type
    add_arguments: Callable[[argparse.ArgumentParser], None]
    options_from_args: Callable[[argparse.Namespace], Any]

    @classmethod
    def from_module(cls, module: str, type_name: str) -> ConverterOptions:
        """The options of a module exposing ``type_name``, ``add_arguments`` and
        ``options_from_args``."""
        mod = importlib.import_module(module)
        return cls(getattr(mod, type_name), mod.add_arguments, mod.options_from_args)


#: options of the built-in converters whose modules do not declare them (adapter)
_BUILTIN_OPTIONS: dict[str, tuple[str, str]] = {
    "video": ("robogs.convert.ingest.video_options", "VideoOptions"),
    "images": ("robogs.convert.ingest.video_options", "VideoOptions"),
    "nerfstudio": ("robogs.convert.ingest.capture_options", "CaptureOptions"),
    "colmap": ("robogs.convert.ingest.capture_options", "CaptureOptions"),
    "tabular": ("robogs.convert.ingest.tabular.options", "TabularOptions"),
}


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
        options: its own options and flags (None: it takes only the shared core).
    """

    name: str
    detect: DetectFn
    convert: ConvertFn
    description: str = ""
    priority: int = 0
    options: ConverterOptions | None = None


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
    options: ConverterOptions | None = None,
    replace: bool = False,
) -> Converter:
    """Add a converter to the registry.

    Args:
        name: format name (``[a-z0-9_-]``).
        detect: predicate on the source path.
        convert: ``convert(src, ctx)``.
        description: one line for listings.
        priority: detection order, higher first.
        options: the converter's own options dataclass and flags.
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
        name, Converter(name, detect, convert, description, priority, options), replace=replace
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


def options_of(conv: Converter) -> ConverterOptions | None:
    """The options of ``conv``: its own, else the built-in adapter's (None: core only)."""
    if conv.options is not None:
        return conv.options
    spec = _BUILTIN_OPTIONS.get(conv.name)
    if spec is None or conv.convert.__module__.partition(".ingest")[0] != "robogs.convert":
        return None
    return ConverterOptions.from_module(*spec)

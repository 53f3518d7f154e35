"""Bounded, safe YAML reading for the small YAML inputs of the converters.

Calibrations, role maps, column maps and ROS 2 ``metadata.yaml`` are read with a
``yaml.SafeLoader`` that also refuses anchors and aliases (none of these files needs them, and
a "billion laughs" of nested aliases costs nothing to parse but explodes whatever walks the
result), after a size limit and a strict UTF-8 decode. Every failure — bad UTF-8, bad YAML,
nesting deeper than the parser can recurse — is one :class:`InputError` naming the file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from robogs.format.errors import InputError

__all__ = ["NoAliasSafeLoader", "read_yaml", "load_yaml_text"]


class NoAliasSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that raises on an alias (``*name``) instead of sharing the node."""

    def compose_node(self, parent: Any, index: Any) -> Any:  # noqa: D102 - PyYAML hook
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(
                None, None, f"YAML alias *{event.anchor} is not allowed", event.start_mark
            )
        return super().compose_node(parent, index)


def load_yaml_text(
    text: str, *, path: str | Path, what: str, loader: type[yaml.SafeLoader] = NoAliasSafeLoader
) -> Any:
    """Parse ``text`` with ``loader`` (a SafeLoader subclass).

    Raises:
        InputError: invalid YAML, aliases, or nesting too deep to parse.
    """
    if not issubclass(loader, yaml.SafeLoader):
        raise TypeError(f"{loader.__name__} is not a yaml.SafeLoader subclass")
    try:
        return yaml.load(text, Loader=loader)  # noqa: S506 - SafeLoader subclasses only
    except yaml.YAMLError as exc:
        raise InputError(
            f"{what} is not valid YAML ({str(exc).splitlines()[0]})",
            path=path,
            hint="fix the syntax; anchors, aliases and python tags are not supported",
        ) from None
    except RecursionError:
        raise InputError(
            f"{what} is nested too deeply",
            path=path,
            hint="this is not a robogs input file, or it is corrupt",
        ) from None


def read_yaml(
    path: str | Path,
    *,
    what: str,
    max_bytes: int,
    loader: type[yaml.SafeLoader] = NoAliasSafeLoader,
) -> Any:
    """Read a small UTF-8 YAML file safely (size limit, strict UTF-8, no aliases).

    Raises:
        InputError: missing or unreadable, too large, not UTF-8, not valid YAML.
    """
    p = Path(path)
    try:
        if p.stat().st_size > max_bytes:
            raise InputError(
                f"{what} is over the {max_bytes}-byte limit",
                path=p,
                hint="this is not a robogs input file, or it is corrupt",
            )
        raw = p.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} not found", path=p) from None
    except OSError as exc:
        raise InputError(f"cannot read {what} ({exc.strerror})", path=p) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{what} is not UTF-8 text", path=p, where=f"byte {exc.start}") from None
    return load_yaml_text(text, path=p, what=what, loader=loader)

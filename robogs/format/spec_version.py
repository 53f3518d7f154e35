"""The spec version this library reads and writes, and the migration hook.

Policy (semver): a reader accepts any dataset with the same major version; a
newer minor version is read with a finding for unknown fields; a newer major
version is refused. Older major versions are upgraded in memory by registered
migrations, never on disk unless the user re-writes the dataset.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .errors import FormatError, VersionError
from .schemas import SCHEMA_NAMES, load_schema

__all__ = [
    "SPEC_VERSION",
    "installed_spec_version",
    "parse_version",
    "check_readable",
    "register_migration",
    "migrate",
]

_ID_VERSION = re.compile(r"/spec/(\d+\.\d+\.\d+)/[a-z]+\.schema\.json$")


def installed_spec_version() -> str:
    """The spec version of the installed JSON Schemas, read from their ``$id``s.

    Every schema's ``$id`` is ``https://robogs.dev/spec/<MAJOR.MINOR.PATCH>/<name>.schema.json``;
    they must agree, or the installation is inconsistent.
    """
    found: dict[str, str] = {}
    for name in SCHEMA_NAMES:
        sid = str(load_schema(name).get("$id", ""))
        m = _ID_VERSION.search(sid)
        if not m:
            raise FormatError(
                f"schema {name!r} has an $id without a spec version: {sid!r}",
                hint="reinstall robogs",
            )
        found[name] = m.group(1)
    if len(set(found.values())) != 1:
        raise FormatError(
            f"the installed schemas disagree on the spec version: {found}", hint="reinstall robogs"
        )
    return next(iter(found.values()))


#: The spec version this robogs reads and writes, from the installed schemas.
SPEC_VERSION = installed_spec_version()

Migration = Callable[[dict[str, Any]], dict[str, Any]]
_MIGRATIONS: dict[int, Migration] = {}


def parse_version(text: str, *, path: str | Path | None = None) -> tuple[int, int, int]:
    """Parse ``MAJOR.MINOR.PATCH`` into a tuple of ints."""
    parts = str(text).split(".")
    if len(parts) != 3 or not all(p.isdigit() for p in parts):
        raise VersionError(
            f"spec_version {text!r} is not MAJOR.MINOR.PATCH",
            path=path,
            where="spec_version",
            hint=f"write a semantic version such as {SPEC_VERSION!r}",
        )
    return int(parts[0]), int(parts[1]), int(parts[2])


def check_readable(version: str, *, path: str | Path | None = None) -> tuple[int, int, int]:
    """Refuse datasets whose major version is newer than this reader's."""
    theirs = parse_version(version, path=path)
    ours = parse_version(SPEC_VERSION)
    if theirs[0] > ours[0]:
        raise VersionError(
            f"dataset uses spec {version}, this robogs reads spec {SPEC_VERSION} (major {ours[0]})",
            path=path,
            where="spec_version",
            hint="upgrade robogs (pip install -U robogs) to read this dataset",
        )
    if theirs[0] < ours[0] and theirs[0] not in _MIGRATIONS:
        raise VersionError(
            f"dataset uses spec {version}; no migration to spec {SPEC_VERSION} is registered",
            path=path,
            where="spec_version",
            hint="convert it with the robogs release that wrote it, or register a migration",
        )
    return theirs


def register_migration(from_major: int, fn: Migration) -> None:
    """Register ``fn`` to upgrade a manifest dict from ``from_major`` to the next major."""
    _MIGRATIONS[from_major] = fn


def migrate(manifest: dict[str, Any], *, path: str | Path | None = None) -> dict[str, Any]:
    """Upgrade a manifest dict step by step to the current major version (in memory)."""
    major = check_readable(str(manifest.get("spec_version", "")), path=path)[0]
    ours = parse_version(SPEC_VERSION)[0]
    while major < ours:
        manifest = _MIGRATIONS[major](dict(manifest))
        major = parse_version(manifest["spec_version"], path=path)[0]
    return manifest

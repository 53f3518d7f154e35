"""Safe resolution of paths read from data files.

A path in a manifest, URDF or sidecar is always relative to the dataset root,
uses forward slashes, and never leaves the root — not through ``..``, an
absolute path, a URI scheme, or a symlink.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from .errors import PathEscapeError

__all__ = ["resolve_inside", "check_relpath"]


def check_relpath(rel: str, *, source: str | Path | None = None, where: str | None = None) -> str:
    """Check the spelling of a dataset-relative path and return it normalised.

    Raises:
        PathEscapeError: absolute paths, URI schemes, backslashes, ``..`` parts, NUL bytes.
    """
    hint = "paths in a dataset are relative to its root, with '/' separators and no '..'"
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        raise PathEscapeError(f"invalid path {rel!r}", path=source, where=where, hint=hint)
    if (
        "://" in rel
        or rel.startswith(("/", "\\"))
        or "\\" in rel
        or (len(rel) > 1 and rel[1] == ":")
    ):
        raise PathEscapeError(
            f"path {rel!r} is not relative to the dataset root", path=source, where=where, hint=hint
        )
    parts = PurePosixPath(rel).parts
    if any(p == ".." for p in parts):
        raise PathEscapeError(
            f"path {rel!r} escapes the dataset root", path=source, where=where, hint=hint
        )
    return str(PurePosixPath(*[p for p in parts if p != "."]))


def resolve_inside(
    root: Path, rel: str, *, source: str | Path | None = None, where: str | None = None
) -> Path:
    """Resolve ``rel`` against ``root``, following symlinks, and refuse escapes."""
    clean = check_relpath(rel, source=source, where=where)
    root_r = Path(root).resolve()
    full = (root_r / clean).resolve()
    if full != root_r and root_r not in full.parents:
        raise PathEscapeError(
            f"path {rel!r} resolves outside the dataset root (symlink?)",
            path=source,
            where=where,
            hint="replace the symlink with the file itself",
        )
    return full

"""Safe resolution of paths read from data files.

A path in a manifest, URDF or sidecar is always relative to the dataset root,
uses forward slashes, and never leaves the root — not through ``..``, an
absolute path, a URI scheme, or a symlink.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from .errors import PathEscapeError

__all__ = ["resolve_inside", "check_relpath", "NAME_MAX_BYTES", "PATH_MAX_BYTES"]

#: longest file or folder name (bytes, UTF-8) a dataset may use: Linux NAME_MAX, the smallest
#: common limit (ext4, XFS, APFS, NTFS all allow 255)
NAME_MAX_BYTES = 255
#: longest dataset-relative path (bytes): leaves room for the root under Linux PATH_MAX (4096)
PATH_MAX_BYTES = 1024


def check_relpath(rel: str, *, source: str | Path | None = None, where: str | None = None) -> str:
    """Check the spelling of a dataset-relative path and return it normalised.

    Raises:
        PathEscapeError: absolute paths, URI schemes, backslashes, ``..`` parts, NUL bytes,
            names longer than :data:`NAME_MAX_BYTES` or paths longer than :data:`PATH_MAX_BYTES`
            (the file system would refuse them with ENAMETOOLONG).
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
    split = rel.split("/")
    # no empty or "." part: the split is what PurePosixPath gives, and rel its normal form
    simple = "" not in split and "." not in split
    parts = tuple(split) if simple else PurePosixPath(rel).parts
    long = [p for p in parts if len(p.encode("utf-8", "surrogatepass")) > NAME_MAX_BYTES]
    if long or len(rel.encode("utf-8", "surrogatepass")) > PATH_MAX_BYTES:
        what = (
            f"a name of {len(long[0].encode('utf-8', 'surrogatepass'))} bytes"
            if long
            else (f"{len(rel.encode('utf-8', 'surrogatepass'))} bytes")
        )
        raise PathEscapeError(
            f"path {rel[:60]!r}... is too long ({what}; at most {NAME_MAX_BYTES} bytes a name, "
            f"{PATH_MAX_BYTES} in all)",
            path=source,
            where=where,
            hint="shorten the file name",
        )
    if any(p == ".." for p in parts):
        raise PathEscapeError(
            f"path {rel!r} escapes the dataset root", path=source, where=where, hint=hint
        )
    return rel if simple else str(PurePosixPath(*[p for p in parts if p != "."]))


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

"""Replacing an output safely: what ``--force`` may replace, and crash-safe swaps.

``--force`` must never destroy data robogs did not write. A folder is replaced only when it is a
robogs dataset (its ``manifest.json`` says ``"format": "robogs"`` with a ``spec_version``) or a
robogs export (it holds :data:`EXPORT_MARKER`); a file only when it is a plain file. Nothing is
ever replaced that is, holds or lies inside one of the command's sources.

A swap exchanges the new and the old version in one ``renameat2(RENAME_EXCHANGE)`` call where
the kernel offers it, so a crash leaves one complete version at the final path. Elsewhere it is
two renames through a ``.<name>.old-<tag>`` sibling, and :func:`recover` (run before every
write) puts an orphaned ``old`` back, then removes leftovers, with a note on each.
"""

from __future__ import annotations

import ctypes
import errno
import json
import logging
import os
import shutil
import stat
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .errors import DatasetExistsError, FormatError, RobogsError
from .jsonio import read_json

__all__ = [
    "EXPORT_MARKER",
    "check_replaceable",
    "exchange",
    "inside_source",
    "remove_path",
    "recover",
    "sibling_versions",
    "write_export_marker",
]

_LOG = logging.getLogger("robogs")

#: file written inside every folder export, so that a later ``--force`` knows robogs wrote it
EXPORT_MARKER = ".robogs-export.json"

_AT_FDCWD = -100
_RENAME_EXCHANGE = 2
_renameat2: Any = None


def exchange(a: Path, b: Path) -> bool:
    """Swap two existing paths atomically (Linux ``renameat2``); False where unsupported."""
    global _renameat2
    if _renameat2 is None:
        try:
            fn = ctypes.CDLL(None, use_errno=True).renameat2
            fn.argtypes = [
                ctypes.c_int,
                ctypes.c_char_p,
                ctypes.c_int,
                ctypes.c_char_p,
                ctypes.c_uint,
            ]
            fn.restype = ctypes.c_int
            _renameat2 = fn
        except (AttributeError, OSError):
            _renameat2 = False
    if _renameat2 is False:
        return False
    if _renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, f"cannot swap {a} and {b}: {os.strerror(err)}")


def sibling_versions(target: Path, kind: str, suffix: str = "") -> list[Path]:
    """Hidden ``.<name>.<kind>-<8 hex><suffix>`` siblings of ``target``, oldest first.

    The name is compared literally (never used as a glob pattern), so ``run[1]`` matches only
    its own siblings. ``kind`` is ``tmp`` (a version being built) or ``old`` (the previous
    version during a swap).
    """
    target = Path(target)
    stem = target.name[: len(target.name) - len(suffix)] if suffix else target.name
    head = f".{stem}.{kind}-"
    out = []
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    for name in names:
        if not name.startswith(head) or not name.endswith(suffix):
            continue
        tag = name[len(head) : len(name) - len(suffix)] if suffix else name[len(head) :]
        if len(tag) == 8 and all(c in "0123456789abcdef" for c in tag):
            out.append(target.parent / name)
    stamped = []
    for p in out:  # another process may remove one between the listing and the stat
        try:
            stamped.append((p.lstat().st_mtime_ns, p.name, p))
        except OSError:
            continue
    return [p for _, _, p in sorted(stamped)]


def remove_path(path: Path) -> None:
    """Remove a file, link or folder tree if it is there (temp and previous versions)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def recover(target: Path, *, suffix: str = "", stale_tmp_s: float | None = None) -> None:
    """Complete or undo a swap a crash interrupted, and clean up leftovers (with a note).

    Args:
        target: the output path.
        suffix: the output's suffix, kept after the tag in the sibling names.
        stale_tmp_s: also remove ``tmp`` siblings older than this (s); None keeps them (a
            writer that holds the target's lock removes its own).
    """
    target = Path(target)
    if stale_tmp_s is not None:
        now = time.time()
        for p in sibling_versions(target, "tmp", suffix):
            try:
                age = now - p.lstat().st_mtime
            except OSError:
                continue
            if age > stale_tmp_s:
                remove_path(p)
                _LOG.warning("robogs: note: removed %s, left %.0f s ago by a killed run", p, age)
    olds = sibling_versions(target, "old", suffix)
    if olds and not (target.exists() or target.is_symlink()):
        os.rename(olds[-1], target)
        _LOG.warning("robogs: note: restored %s from %s (an interrupted swap)", target, olds[-1])
        olds = olds[:-1]
    for p in olds:
        remove_path(p)
        _LOG.warning("robogs: note: removed %s, left by an interrupted swap", p)


def _is_robogs_dataset(folder: Path) -> bool:
    m = folder / "manifest.json"
    try:
        if not stat.S_ISREG(os.lstat(m).st_mode):  # a link is never taken as a manifest
            return False
        doc = read_json(m, what="manifest")
    except (OSError, RobogsError):
        return False
    return isinstance(doc, dict) and doc.get("format") == "robogs" and "spec_version" in doc


def _is_robogs_export(folder: Path) -> bool:
    marker = folder / EXPORT_MARKER
    try:
        return stat.S_ISREG(os.lstat(marker).st_mode)
    except OSError:
        return False


def inside_source(path: Path, sources: Iterable[str | Path]) -> Path | None:
    """The source that ``path`` is, or lies inside (resolved), or None."""
    real = Path(path).absolute().resolve()
    for src in sources:
        s = Path(src).absolute().resolve()
        if s == real or s in real.parents:
            return s
    return None


def _related(a: Path, b: Path) -> bool:
    """True when one of the two resolved paths is the other or lies inside it."""
    return a == b or a in b.parents or b in a.parents


def check_replaceable(
    out: Path, *, folder: bool, sources: Iterable[str | Path] = (), what: str = "output"
) -> None:
    """Refuse (before any work) to replace ``out`` unless robogs wrote it and it is not a source.

    Args:
        out: the path ``--force`` would replace (it may not exist).
        folder: the new output is a folder (dataset or folder export), else a file.
        sources: paths the command reads; ``out`` may not be one, hold one or lie in one.

    Raises:
        DatasetExistsError: ``out`` is not something robogs may replace, with the reason.
    """
    out = Path(out).absolute()
    if not (out.exists() or out.is_symlink()):
        return
    if out.is_symlink():
        raise DatasetExistsError(
            f"{what} is a symbolic link; --force does not replace links",
            path=out,
            hint="write to the link's target path instead, or remove the link yourself",
        )
    real = out.resolve()
    for src in sources:
        s = Path(src).absolute().resolve()
        if _related(real, s):
            raise DatasetExistsError(
                f"{what} {'is' if real == s else 'holds or lies inside'} the source {s}; "
                "--force never replaces a command's own input",
                path=out,
                hint="choose an output path outside the source",
            )
    if real.is_dir():
        if _is_robogs_dataset(real) or _is_robogs_export(real):
            return
        raise DatasetExistsError(
            f"{what} is a folder that robogs did not write (no robogs manifest.json or "
            f"{EXPORT_MARKER}); --force replaces only robogs datasets and exports",
            path=out,
            hint="choose another path, or move that folder away yourself",
        )
    if folder or not stat.S_ISREG(os.stat(real).st_mode):
        raise DatasetExistsError(
            f"{what} is a file, not a robogs dataset; --force will not replace it with a folder"
            if folder
            else f"{what} is not a regular file",
            path=out,
            hint="choose another path",
        )


def write_export_marker(folder: Path, *, fmt: str, source: str | Path) -> None:
    """Mark a folder export as written by robogs (see :func:`check_replaceable`)."""
    try:
        (Path(folder) / EXPORT_MARKER).write_text(
            json.dumps({"format": "robogs-export", "export": fmt, "source": str(source)}) + "\n",
            encoding="utf-8",
        )
    except OSError as exc:
        raise FormatError(f"cannot write {EXPORT_MARKER}: {exc.strerror}", path=folder) from None

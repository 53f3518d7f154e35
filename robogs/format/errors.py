"""Exceptions raised by robogs for user-facing problems.

Every error names the file, the place inside it, and a hint for the fix. The CLI
turns a :class:`RobogsError` into one line on stderr and exit code 2; it never
prints a traceback for these.
"""

from __future__ import annotations

import errno
from pathlib import Path

__all__ = [
    "RobogsError",
    "FormatError",
    "VersionError",
    "PathEscapeError",
    "DatasetExistsError",
    "LockError",
    "ConcurrentEditError",
    "InputError",
    "OutputError",
    "output_error",
]


class RobogsError(Exception):
    """Base class of all robogs errors.

    Args:
        message: what went wrong, in one sentence.
        path: the file or folder concerned, if any.
        where: the place inside the file (a JSON pointer, row, column, topic, stamp...).
        hint: how to fix it.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        where: str | None = None,
        hint: str | None = None,
    ) -> None:
        self.message = message
        self.path = str(path) if path is not None else None
        self.where = where
        self.hint = hint
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message as one line: ``path: where: message (hint: ...)``."""
        parts = []
        if self.path:
            parts.append(self.path)
        if self.where:
            parts.append(str(self.where))
        parts.append(self.message)
        text = ": ".join(parts)
        if self.hint:
            text += f" (hint: {self.hint})"
        return text


class FormatError(RobogsError):
    """A file does not follow the robogs format (malformed, truncated, wrong type)."""


class VersionError(RobogsError):
    """A dataset declares a spec version this reader cannot read."""


class PathEscapeError(RobogsError):
    """A path read from a data file points outside the dataset root."""


class DatasetExistsError(RobogsError):
    """The output dataset already exists and overwriting was not requested."""


class LockError(RobogsError):
    """Another writer holds the dataset."""


class ConcurrentEditError(LockError):
    """The dataset changed on disk between the moment it was read and the commit of an edit."""


class OutputError(RobogsError):
    """Writing an output failed (disk full, read-only, name too long, busy); inputs are intact."""


#: errno -> (what happened, what to do) for errors met while writing
_OS_CAUSES: dict[int, tuple[str, str]] = {
    errno.ENOSPC: ("the disk is full", "free some space or write to another disk"),
    errno.EDQUOT: ("the disk quota is exceeded", "free some space or write to another disk"),
    errno.EFBIG: ("the file is too large for this file system", "write to another file system"),
    errno.EROFS: ("the file system is read-only", "write to a writable folder"),
    errno.EACCES: ("permission denied", "write to a folder you may write to"),
    errno.EPERM: ("operation not permitted", "write to a folder you may write to"),
    errno.ENAMETOOLONG: ("the name is too long", "choose a shorter output name"),
    errno.EBUSY: ("the file or folder is busy (in use or a mount point)", "close what uses it"),
    errno.EXDEV: ("it lies on another file system", "write beside the output folder"),
}


def output_error(exc: OSError, *, path: str | Path | None, action: str) -> OutputError:
    """An :class:`OutputError` for an ``OSError`` met while ``action`` (e.g. "writing")."""
    what, hint = _OS_CAUSES.get(
        exc.errno or -1, (exc.strerror or str(exc), "check the output folder and retry")
    )
    return OutputError(
        f"{action} failed: {what}; nothing was changed",
        path=exc.filename or path,
        hint=hint,
    )


class InputError(RobogsError):
    """A source file given to a converter or command is unusable."""

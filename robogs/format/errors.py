"""Exceptions raised by robogs for user-facing problems.

Every error names the file, the place inside it, and a hint for the fix. The CLI
turns a :class:`RobogsError` into one line on stderr and exit code 2; it never
prints a traceback for these.
"""

from __future__ import annotations

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


class InputError(RobogsError):
    """A source file given to a converter or command is unusable."""

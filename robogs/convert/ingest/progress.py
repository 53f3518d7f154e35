"""A progress bar on stderr (rich) that costs nothing when switched off."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["ProgressReporter"]


class ProgressReporter:
    """One rich progress task at a time, updated every ``every`` steps.

    Args:
        enabled: draw the bar (on stderr); when False every call is a no-op.
        every: coalesce this many ``advance`` calls into one redraw.
    """

    def __init__(self, enabled: bool, *, every: int = 512) -> None:
        self.enabled = enabled
        self.every = every
        self._progress: Any = None
        self._task: Any = None
        self._pending = 0

    def start(self, description: str, total: float | None, *, unit: str = "msgs") -> None:
        """Begin a task of ``total`` steps (``None`` when unknown)."""
        if not self.enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.stop()
        self._progress = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn(unit),
            TextColumn("{task.fields[extra]}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=Console(file=sys.stderr),
            transient=False,
        )
        self._progress.start()
        self._task = self._progress.add_task(description, total=total, extra="")
        self._pending = 0

    def advance(self, n: int = 1, *, extra: str | None = None) -> None:
        """Count ``n`` steps done; ``extra`` replaces the trailing text (e.g. MB read)."""
        if self._progress is None:
            return
        self._pending += n
        if self._pending >= self.every or extra is not None:
            kw = {} if extra is None else {"extra": extra}
            self._progress.update(self._task, advance=self._pending, **kw)
            self._pending = 0

    def stop(self) -> None:
        """Finish the current task (flushing pending steps)."""
        if self._progress is None:
            return
        if self._pending:
            self._progress.update(self._task, advance=self._pending)
        self._progress.stop()
        self._progress = None
        self._task = None
        self._pending = 0

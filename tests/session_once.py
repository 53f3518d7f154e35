"""Run an expensive test input once per pytest session, also under pytest-xdist.

Without xdist (``worker_id == "master"``) the work runs in a fresh folder of the session. Under
it the workers share one run in the session's base folder (``basetemp.parent``) through a file
lock, its result stored beside it (pytest-xdist docs, "Making session-scoped fixtures execute
only once"); the stored file is written whole, then renamed, so a reader never sees half.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")

__all__ = ["once_per_session"]


def once_per_session(
    name: str,
    basetemp: Path,
    worker_id: str,
    run: Callable[[Path], T],
    dump: Callable[[T], bytes],
    load: Callable[[bytes], T],
) -> tuple[Path, T]:
    """``(folder, result)`` of ``run(folder)``, run once per session in ``folder`` (``name``
    under the session's temporary folders); ``dump``/``load`` store the result for the other
    workers."""
    if worker_id == "master":
        folder = basetemp / name
        folder.mkdir(exist_ok=True)
        return folder, run(folder)
    from filelock import FileLock

    root = basetemp.parent
    folder, done = root / name, root / f"{name}.result"
    with FileLock(str(root / f"{name}.lock")):
        if not done.is_file():
            folder.mkdir(exist_ok=True)
            tmp = done.with_suffix(".tmp")
            tmp.write_bytes(dump(run(folder)))
            tmp.replace(done)
        return folder, load(done.read_bytes())

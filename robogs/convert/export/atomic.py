"""Atomic output: write a hidden temporary sibling, then rename it into place.

The temporary path sits in the same folder as the output (same filesystem, so the final
``os.rename`` is atomic) and keeps the output's suffix, so libraries that choose an encoding
from the file name (USD's ``.usda``/``.usdc``, Rerun's ``.rrd``) behave as for the final path.
If the block raises, the temporary path is removed and the output is untouched. An existing
output is replaced only with ``force``, and only when robogs wrote it
(:func:`robogs.format.replace.check_replaceable`); the swap is one ``renameat2`` exchange where
available, else two renames that :func:`robogs.format.replace.recover` completes after a crash.
"""

from __future__ import annotations

import os
import re
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from robogs.format.errors import DatasetExistsError, InputError, output_error
from robogs.format.replace import (
    check_replaceable,
    exchange,
    inside_source,
    recover,
    remove_path,
    write_export_marker,
)

__all__ = ["atomic_output", "final_path"]


_TMP = re.compile(r"^\.(?P<stem>.+)\.tmp-[0-9a-f]{8}(?P<suffix>.*)$")


def final_path(tmp: str | Path) -> Path:
    """The output path a temporary path of :func:`atomic_output` will be renamed to (``tmp``
    itself when it is not one), for exporters that name things after the final output."""
    tmp = Path(tmp)
    m = _TMP.match(tmp.name)
    return tmp.with_name(m.group("stem") + m.group("suffix")) if m else tmp


@contextmanager
def atomic_output(
    out: str | Path,
    *,
    folder: bool,
    force: bool = False,
    sources: Sequence[str | Path] = (),
    fmt: str = "export",
) -> Iterator[Path]:
    """Yield a temporary path to write; swap it into ``out`` when the block succeeds.

    Args:
        out: the final file or folder.
        folder: create the temporary path as an (empty) folder; otherwise it is a file path
            that does not exist yet. A folder export gets
            :data:`~robogs.format.replace.EXPORT_MARKER`, so a later ``--force`` may replace it.
        force: replace an existing ``out`` — only a robogs export or dataset, or a plain file,
            and never one of ``sources`` or a path holding or inside one.
        sources: the command's inputs (the dataset being exported).
        fmt: the export format, recorded in the folder marker.

    Raises:
        DatasetExistsError: ``out`` exists and may not be replaced (checked before any work).
        InputError: the parent folder of ``out`` does not exist.
    """
    out = Path(out).absolute()
    parent = out.parent
    if not parent.is_dir():
        raise InputError(
            "parent folder of the output does not exist", path=parent, hint="create it first"
        )
    # a swap a crash interrupted: restore or clean, with a note; temp outputs of a killed export
    # are removed once an hour old (a younger one may belong to a running export)
    recover(out, suffix=out.suffix, stale_tmp_s=3600.0)
    if out.exists() or out.is_symlink():
        if not force:
            raise DatasetExistsError(
                "output already exists", path=out, hint="choose another path or pass --force"
            )
        check_replaceable(out, folder=folder, sources=sources)
    elif inside_source(out, sources) is not None:
        raise InputError(
            "the output lies inside the dataset being exported",
            path=out,
            hint="write exports outside the dataset folder",
        )
    tag = uuid.uuid4().hex[:8]
    tmp = parent / f".{out.stem}.tmp-{tag}{out.suffix}"
    try:  # writability is known before the export's work: a read-only parent fails here
        if folder:
            tmp.mkdir()
        else:
            tmp.touch(exist_ok=False)
            tmp.unlink()
    except OSError as exc:
        raise output_error(exc, path=out, action="creating the export") from None
    try:
        yield tmp
        if not tmp.exists():
            raise InputError("the exporter wrote nothing", path=out)
        if folder:
            write_export_marker(tmp, fmt=fmt, source=next(iter(sources), ""))
        if out.exists() and exchange(tmp, out):
            remove_path(tmp)  # tmp now holds the previous version
        else:
            old = None
            if out.exists() or out.is_symlink():
                old = parent / f".{out.stem}.old-{tag}{out.suffix}"
                os.rename(out, old)  # a crash here leaves `old`: the next run restores it
            try:
                os.rename(tmp, out)
            except OSError:
                if old is not None:
                    os.rename(old, out)
                raise
            if old is not None:
                remove_path(old)
    except OSError as exc:  # a full disk or read-only folder while writing the export
        name = getattr(exc, "filename", None)
        if name is None or str(Path(name).absolute()).startswith((str(tmp), str(out))):
            raise output_error(exc, path=out, action="writing the export") from None
        raise
    finally:
        remove_path(tmp)

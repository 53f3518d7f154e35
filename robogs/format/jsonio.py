"""Bounded, strict JSON reading and deterministic JSON writing."""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path
from typing import Any

from .errors import FormatError

__all__ = ["read_json", "read_regular_bytes", "dumps_json", "MAX_JSON_BYTES"]

MAX_JSON_BYTES = 64 * 1024 * 1024


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name} is not valid JSON")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"duplicate key {k!r}")
        out[k] = v
    return out


def read_regular_bytes(path: Path, *, max_bytes: int, what: str) -> bytes:
    """The bytes of a regular file, read through one descriptor and never more than ``max_bytes``.

    FIFOs, devices, sockets and folders are refused before anything is read (a FIFO is opened
    non-blocking, so it cannot hang the caller); the size is checked on the opened descriptor
    and the read is capped, so a file that grows or lies about its size cannot exhaust memory.

    Raises:
        FormatError: missing, not a regular file, over ``max_bytes``, or unreadable.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise FormatError(
            f"{what} is missing", path=path, hint="restore it or re-create the dataset"
        ) from None
    except OSError as exc:
        raise FormatError(
            f"{what} cannot be opened ({exc.strerror or exc})",
            path=path,
            hint="check the file's permissions and name",
        ) from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = (
                "a folder"
                if stat.S_ISDIR(st.st_mode)
                else "a FIFO"
                if stat.S_ISFIFO(st.st_mode)
                else "a device or socket"
            )
            raise FormatError(
                f"{what} is {kind}, not a regular file",
                path=path,
                hint="replace it with the file the writer produced",
            )
        if st.st_size > max_bytes:
            raise FormatError(
                f"{what} is {st.st_size} bytes, over the {max_bytes}-byte limit",
                path=path,
                hint="this is not a robogs sidecar, or it was corrupted",
            )
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > max_bytes:
                raise FormatError(
                    f"{what} holds more than {max_bytes} bytes",
                    path=path,
                    hint="this is not a robogs sidecar, or it was corrupted",
                )
        return b"".join(chunks)
    except OSError as exc:
        raise FormatError(f"{what} cannot be read ({exc.strerror or exc})", path=path) from None
    finally:
        os.close(fd)


def read_json(
    path: Path,
    *,
    max_bytes: int = MAX_JSON_BYTES,
    what: str = "JSON file",
    root: Path | None = None,
) -> Any:
    """Read a JSON document, refusing huge files, NaN/Infinity, duplicate keys and bad text.

    With ``root``, the path must resolve inside it (a symlink out of the dataset is refused
    before the file is opened). Only regular files are read (see :func:`read_regular_bytes`).

    Raises:
        FormatError: naming the file and the line/column of the problem.
    """
    path = Path(path)
    if root is not None:
        from .paths import resolve_inside

        rel = os.path.relpath(os.path.abspath(path), os.path.abspath(root))
        resolve_inside(Path(root), Path(rel).as_posix(), source=path, where=what)
    raw = read_regular_bytes(path, max_bytes=max_bytes, what=what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(
            f"{what} is not UTF-8 text", path=path, where=f"byte {exc.start}"
        ) from None
    try:
        return json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"{what} is not valid JSON: {exc.msg}",
            path=path,
            where=f"line {exc.lineno} column {exc.colno}",
            hint="fix the syntax or restore the file from the writer's output",
        ) from None
    except (ValueError, RecursionError) as exc:
        raise FormatError(f"{what} is not valid JSON: {exc}", path=path) from None


def _clean(obj: Any) -> Any:
    if isinstance(obj, float) and not math.isfinite(obj):
        raise FormatError(
            f"refusing to write non-finite number {obj} to JSON",
            hint="check the upstream computation",
        )
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _clean(obj.tolist())
    return obj


def dumps_json(obj: Any) -> str:
    """Serialise with sorted keys and two-space indent (stable hashes, readable diffs)."""
    return json.dumps(_clean(obj), indent=2, sort_keys=True, ensure_ascii=False) + "\n"

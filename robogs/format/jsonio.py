"""Bounded, strict JSON reading and deterministic JSON writing."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from .errors import FormatError

__all__ = ["read_json", "dumps_json", "MAX_JSON_BYTES"]

MAX_JSON_BYTES = 64 * 1024 * 1024


def _reject_constant(name: str) -> float:
    raise ValueError(f"non-finite number {name} is not valid JSON")


def read_json(path: Path, *, max_bytes: int = MAX_JSON_BYTES, what: str = "JSON file") -> Any:
    """Read a JSON document, refusing huge files, NaN/Infinity and malformed text.

    Raises:
        FormatError: naming the file and the line/column of the problem.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise FormatError(
            f"{what} is missing", path=path, hint="restore it or re-create the dataset"
        ) from None
    if size > max_bytes:
        raise FormatError(
            f"{what} is {size} bytes, over the {max_bytes}-byte limit",
            path=path,
            hint="this is not a robogs sidecar, or it was corrupted",
        )
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(
            f"{what} is not UTF-8 text", path=path, where=f"byte {exc.start}"
        ) from None
    try:
        return json.loads(text, parse_constant=_reject_constant)
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

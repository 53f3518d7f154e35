"""Reading a tabular joint log: one CSV or Parquet file into named columns, stamps to int64 ns.

CSV cells stay text until a column is used, so decimal seconds become exact nanoseconds
(:func:`to_ns`); lines before the header and truncated rows at the end of a file are dropped
and counted, a short row inside the file is an error. :func:`guess_time_unit` tells the unit of
a time column whose name does not say it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format.errors import InputError

__all__ = [
    "RawLog",
    "SUFFIXES",
    "TIME_SCALE",
    "detect_tabular",
    "guess_time_unit",
    "log_files",
    "read_log_file",
    "to_float",
    "to_ns",
]

#: file suffixes read as logs
SUFFIXES = (".csv", ".parquet", ".pq")
#: ns per time unit
TIME_SCALE = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
#: (unit, seconds per unit) for the time-unit guess
_UNITS_S = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))


def guess_time_unit(values: np.ndarray) -> tuple[str, str]:
    """The unit of a time column from its values, and why (a phrase for the provenance).

    Unix-epoch stamps are recognised by magnitude (2001..2286 is 1e9..1e10 s, 1e12..1e13 ms,
    1e15..1e16 us, 1e18..1e19 ns). Otherwise the unit is the one whose median step gives a
    sampling rate between 1 Hz and 20 kHz closest (in log scale) to 200 Hz, typical of arm logs.

    Raises:
        ValueError: fewer than two distinct finite values.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    steps = np.diff(v)
    steps = steps[steps > 0]
    if v.size < 2 or steps.size == 0:
        raise ValueError("fewer than two increasing stamps")
    first = float(np.median(np.abs(v[: min(v.size, 101)])))
    for unit, lo in (("s", 1e9), ("ms", 1e12), ("us", 1e15), ("ns", 1e18)):
        if lo <= first < 10 * lo:
            return unit, f"Unix-epoch values near {first:.4g}"
    dt = float(np.median(steps))
    best: tuple[float, str, float] | None = None
    for unit, sec in _UNITS_S:
        rate = 1.0 / (dt * sec)
        if 1.0 <= rate <= 20_000.0:
            score = abs(math.log10(rate) - math.log10(200.0))
            if best is None or score < best[0]:
                best = (score, unit, rate)
    if best is None:
        raise ValueError(f"median step {dt:g} gives no sampling rate between 1 Hz and 20 kHz")
    return best[1], f"median step {dt:g} -> {best[2]:.4g} Hz"


@dataclass
class RawLog:
    """A file's columns as text (CSV) or arrays (Parquet), with their source line numbers."""

    columns: list[str]
    data: dict[str, np.ndarray]
    lines: np.ndarray  # [N] 1-based line (CSV) or row (Parquet) of each kept row
    kind: str
    dropped: dict[str, list[int]] = field(default_factory=dict)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip().strip('"') for f in (line.split(delim) if delim else line.split())]


def _find_header(lines: list[str], path: Path) -> tuple[int, str | None]:
    for i, line in enumerate(lines[:200]):
        if not line.strip():
            continue
        for delim in (",", ";", "\t", None):
            fields = _split(line, delim)
            if len(fields) < 2 or any(_is_number(f) or not f for f in fields):
                continue
            # the next non-empty line must have as many fields, mostly numbers
            for nxt in lines[i + 1 : i + 6]:
                if not nxt.strip():
                    continue
                vals = _split(nxt, delim)
                if len(vals) == len(fields) and sum(
                    _is_number(v) or v == "" for v in vals
                ) >= 0.8 * len(vals):
                    return i, delim
                break
    raise InputError(
        "no header line followed by numeric rows in the first 200 lines",
        path=path,
        hint="the file needs one header line naming the columns",
    )


def _read_csv(path: Path) -> RawLog:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read the log ({exc.strerror})", path=path) from None
    lines = text.splitlines()
    h, delim = _find_header(lines, path)
    columns = _split(lines[h], delim)
    if len(set(columns)) != len(columns):
        dup = sorted({c for c in columns if columns.count(c) > 1})
        raise InputError(f"duplicate column names {dup}", path=path, where=f"line {h + 1}")
    dropped: dict[str, list[int]] = {}
    if h:
        dropped["lines before the header"] = list(range(1, h + 1))
    rows: list[list[str]] = []
    line_no: list[int] = []
    short: list[tuple[int, int]] = []
    for k in range(h + 1, len(lines)):
        line = lines[k]
        if not line.strip():
            continue
        fields = _split(line, delim)
        if len(fields) != len(columns):
            short.append((k + 1, len(fields)))
            continue
        rows.append(fields)
        line_no.append(k + 1)
    if short:
        last_good = line_no[-1] if line_no else h + 1
        interior = [(ln, n) for ln, n in short if ln < last_good]
        if interior:
            ln, n = interior[0]
            col = columns[min(n, len(columns) - 1)]
            raise InputError(
                f"row has {n} fields but the header has {len(columns)} (columns of different lengths)",
                path=path,
                where=f"line {ln}, column {col!r}",
                hint="repair or remove the row; only truncated rows at the end of a file are dropped",
            )
        dropped["truncated rows at the end of the file"] = [ln for ln, _ in short]
    arr = np.array(rows, dtype=object).reshape(len(rows), len(columns))
    data = {c: arr[:, i].astype(str) for i, c in enumerate(columns)}
    return RawLog(columns, data, np.asarray(line_no, dtype=np.int64), "csv", dropped)


def _read_parquet(path: Path) -> RawLog:
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise InputError(
            f"unreadable parquet log ({str(exc).splitlines()[0][:200]})", path=path
        ) from None
    data = {}
    for name in table.schema.names:
        col = table.column(name)
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            data[name] = col.to_numpy(zero_copy_only=False)
        else:
            data[name] = np.asarray(col.cast(pa.string()).to_pylist(), dtype=object).astype(str)
    return RawLog(
        list(table.schema.names), data, np.arange(1, table.num_rows + 1, dtype=np.int64), "parquet"
    )


def to_float(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Float array and a mask of unparseable (non-empty, non-numeric) entries."""
    if values.dtype.kind in "iuf":
        return values.astype(np.float64), np.zeros(len(values), dtype=bool)
    v = np.char.strip(values.astype(str))
    empty = (v == "") | (np.char.lower(v) == "nan") | (np.char.lower(v) == "na")
    clean = np.where(empty, "nan", v)
    try:
        return clean.astype(np.float64), np.zeros(len(v), dtype=bool)
    except ValueError:
        out = np.full(len(v), np.nan)
        bad = np.zeros(len(v), dtype=bool)
        for i, s in enumerate(clean):
            try:
                out[i] = float(s)
            except ValueError:
                bad[i] = True
        return out, bad


def to_ns(values: np.ndarray, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Exact int64 ns from decimal text (or numbers); mask of unparseable/NaN entries."""
    scale = TIME_SCALE[unit]
    limit = (2**63 - 1) // scale  # larger magnitudes do not fit int64 nanoseconds
    if values.dtype.kind in "iu":
        ok = (values <= limit) & (values >= -limit)
        return np.where(ok, values, 0).astype(np.int64) * scale, ~ok
    if values.dtype.kind == "f":
        ok = np.isfinite(values) & (np.abs(values) < limit)
        return np.where(ok, np.round(np.where(ok, values, 0.0) * scale), 0).astype(np.int64), ~ok
    out = np.zeros(len(values), dtype=np.int64)
    bad = np.zeros(len(values), dtype=bool)
    digits = len(str(scale)) - 1
    for i, s in enumerate(np.char.strip(values.astype(str))):
        m = re.fullmatch(r"([+-]?)(\d*)(?:\.(\d*))?", s)
        if m and (m.group(2) or m.group(3)):
            whole = (m.group(2) or "0").lstrip("0") or "0"
            if len(whole) > 19:  # beyond int64 in any unit
                bad[i] = True
                continue
            frac = (m.group(3) or "")[:digits].ljust(digits, "0") if digits else ""
            v = int(whole) * scale + (int(frac) if frac else 0)
            if v >= 2**63:
                bad[i] = True
                continue
            out[i] = -v if m.group(1) == "-" else v
            continue
        try:
            f = float(s)
        except ValueError:
            bad[i] = True
            continue
        if not math.isfinite(f) or abs(f) >= limit:
            bad[i] = True
        else:
            out[i] = int(round(f * scale))
    return out, bad


def read_log_file(path: Path) -> RawLog:
    """Read one CSV or Parquet log (columns as text for CSV)."""
    if path.suffix.lower() == ".csv":
        return _read_csv(path)
    return _read_parquet(path)


def log_files(log: Path) -> list[Path]:
    """The log files of ``log``: the file itself, or a folder's ``.csv``/``.parquet`` files by name.

    Raises:
        InputError: missing path, a file of another type, a folder without logs.
    """
    if log.is_file():
        if log.suffix.lower() not in SUFFIXES:
            raise InputError(
                "not a CSV or Parquet log",
                path=log,
                hint="pass a .csv or .parquet file or a folder",
            )
        return [log]
    if log.is_dir():
        files = sorted(p for p in log.iterdir() if p.is_file() and p.suffix.lower() in SUFFIXES)
        if not files:
            raise InputError("folder holds no .csv or .parquet file", path=log)
        return files
    raise InputError("log does not exist", path=log)


def detect_tabular(path: Path) -> bool:
    """True for a ``.csv``/``.parquet`` file or a folder holding only such logs (plus sidecars)."""
    path = Path(path)
    if path.is_file():
        return path.suffix.lower() in SUFFIXES
    if path.is_dir():
        files = [p for p in path.iterdir() if p.is_file()]
        logs = [p for p in files if p.suffix.lower() in SUFFIXES]
        return bool(logs) and all(
            p.suffix.lower() in SUFFIXES + (".json", ".yaml", ".yml", ".md", ".txt") for p in files
        )
    return False

"""Bounded-memory reading for the checks: parquet batches and exact streaming order statistics.

Checks over long streams (a 30-minute episode at 500 Hz is 900k rows) read their tables here,
one row group at a time, instead of through :meth:`CheckContext.table`, which caches whole
tables. Order statistics (medians, percentiles) over such streams are exact without holding
the values: :func:`kth_smallest` narrows a histogram over the bit patterns of non-negative
float64 values (which sort like the values) by a factor 4096 per pass over the data, and sorts
the remaining values once at most 65,536 of them are left. Memory is O(batch + 65,536) values
whatever the length of the stream.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ..tables import check_table_schema, null_problems
from .context import CheckContext, InputReported

__all__ = [
    "BATCH_ROWS",
    "batches",
    "entity_series",
    "kth_smallest",
    "next_smallest",
    "percentile",
    "median",
    "SampleWindow",
    "MedianSketch",
]

#: rows per batch read from a parquet table (the writer's row-group size)
BATCH_ROWS = 1 << 16
_BINS = 4096
_CAP = 1 << 16
_MAX_BITS = 0x7FF0000000000000  # bit pattern of +inf


def batches(
    ctx: CheckContext, rel: str, columns: Iterable[str], *, batch_rows: int = BATCH_ROWS
) -> Iterator[pa.RecordBatch]:
    """Record batches of some columns of a manifest table, read without caching.

    Raises:
        InputReported: the table is unsafe, missing, unreadable, off its kind's schema, or holds
            nulls where its kind forbids them (each reported by an integrity or schema check).
    """
    md = ctx.footer(rel)
    kind = ctx.table_kinds().get(rel)
    if kind is not None and check_table_schema(kind, md.schema.to_arrow_schema()):
        raise InputReported(rel)
    path = ctx.existing(rel)
    try:
        pf = pq.ParquetFile(path, pre_buffer=False)
        for batch in pf.iter_batches(
            batch_size=batch_rows, columns=list(columns), use_threads=False
        ):
            if kind is not None and null_problems(kind, batch):
                raise InputReported(rel)
            yield batch
    except (pa.ArrowException, OSError, ValueError):
        raise InputReported(rel) from None  # I006 reads every table and reports it


def entity_series(
    ctx: CheckContext, rel: str, entity: str, values: tuple[str, ...]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per entity of an interleaving table (``link``, ``object``, ``frame``): its ``t_ns`` [N]
    int64 and ``values`` [N, C] float64, in table order, read batch by batch.

    Raises:
        InputReported: as :func:`batches`.
    """
    parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for b in batches(ctx, rel, ("t_ns", entity, *values)):
        enc = b.column(1).dictionary_encode()
        codes = enc.indices.to_numpy(zero_copy_only=False)
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64)
        v = np.stack(
            [b.column(i + 2).to_numpy(zero_copy_only=False) for i in range(len(values))], axis=1
        ).astype(np.float64)
        for k, name in enumerate(enc.dictionary.to_pylist()):
            sel = codes == k
            parts.setdefault(str(name), []).append((t[sel], v[sel]))
    return {
        name: (np.concatenate([c[0] for c in chunks]), np.concatenate([c[1] for c in chunks]))
        for name, chunks in parts.items()
    }


def _bits(values: np.ndarray) -> np.ndarray:
    """Order-preserving int64 view of non-negative float64 values."""
    return np.ascontiguousarray(values, dtype=np.float64).view(np.int64)


def _value(bits: int) -> float:
    return float(np.array([bits], np.int64).view(np.float64)[0])


def kth_smallest(values: Callable[[], Iterable[np.ndarray]], k: int) -> float:
    """Exact ``k``-th smallest (0-based) of non-negative float64 values, in bounded memory.

    Args:
        values: called once per pass; yields the values in chunks (the same values each time).
        k: rank, ``0 <= k < n``.
    """
    lo, hi = 0, _MAX_BITS
    while lo < hi:
        width = -(-(hi - lo + 1) // _BINS)
        counts = np.zeros(_BINS, np.int64)
        kept: list[np.ndarray] | None = []
        n_kept = 0
        for chunk in values():
            b = _bits(chunk)
            b = b[(b >= lo) & (b <= hi)]
            if b.size == 0:
                continue
            counts += np.bincount((b - lo) // width, minlength=_BINS)
            if kept is not None:
                n_kept += b.size
                if n_kept <= _CAP:
                    kept.append(b)
                else:
                    kept = None
        if kept is not None:
            inside = np.concatenate(kept) if kept else np.zeros(0, np.int64)
            if not 0 <= k < inside.size:
                raise ValueError(f"rank {k} out of range for {inside.size} values")
            return _value(int(np.partition(inside, k)[k]))
        cum = np.cumsum(counts)
        j = int(np.searchsorted(cum, k, side="right"))
        if j >= _BINS:
            raise ValueError(f"rank {k} out of range for {int(cum[-1])} values")
        k -= int(cum[j - 1]) if j else 0
        lo, hi = lo + j * width, min(hi, lo + (j + 1) * width - 1)
    return _value(lo)


def next_smallest(values: Callable[[], Iterable[np.ndarray]], x: float, k: int) -> float:
    """The ``(k+1)``-th smallest value, given ``x``, the ``k``-th (one pass)."""
    n_le, above = 0, np.inf
    for chunk in values():
        c = np.asarray(chunk, np.float64)
        n_le += int(np.count_nonzero(c <= x))
        gt = c[c > x]
        if gt.size:
            above = min(above, float(gt.min()))
    return x if n_le > k + 1 else above


def median(values: Callable[[], Iterable[np.ndarray]], n: int) -> float:
    """``np.median`` of ``n`` non-negative values, exactly."""
    k = (n - 1) // 2
    a = kth_smallest(values, k)
    if n % 2:
        return a
    b = next_smallest(values, a, k)
    return float(np.mean(np.array([a, b])))


def percentile(values: Callable[[], Iterable[np.ndarray]], n: int, q: float) -> float:
    """``np.percentile(values, q)`` (linear method) of ``n`` non-negative values, exactly."""
    idx = (q / 100.0) * (n - 1)
    k = int(np.floor(idx))
    a = kth_smallest(values, k)
    if k + 1 >= n:
        return a
    b = next_smallest(values, a, k)
    t = idx - k
    d = b - a
    return b - d * (1 - t) if t >= 0.5 else a + d * t


class SampleWindow:
    """The rows of a time-sorted table around a query range, read batch by batch.

    ``around(t_lo, t_hi)`` returns the rows from the last one stamped at or before ``t_lo``
    to the first one stamped after ``t_hi`` (or the end), and never fewer than two when the
    table has two, so that linear interpolation at any time in the range brackets with the
    same two samples as over the whole table. Ranges should move forward; a range that
    starts before the rows kept restarts the read.

    Args:
        ctx: the check context.
        rel: table path (its ``t_ns`` must be strictly increasing).
        columns: value columns, stacked as [N, len(columns)] float64.
    """

    def __init__(self, ctx: CheckContext, rel: str, columns: tuple[str, ...]) -> None:
        self.ctx, self.rel, self.columns = ctx, rel, columns
        self._restart()

    def _restart(self) -> None:
        self._it = batches(self.ctx, self.rel, ("t_ns", *self.columns))
        self._done = False
        self.t = np.zeros(0, np.int64)
        self.values = np.zeros((0, len(self.columns)))

    def _more(self) -> None:
        try:
            b = next(self._it)
        except StopIteration:
            self._done = True
            return
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        v = np.stack(
            [b.column(i + 1).to_numpy(zero_copy_only=False) for i in range(len(self.columns))],
            axis=1,
        ).astype(np.float64, copy=False)
        self.t = np.concatenate([self.t, t])
        self.values = np.concatenate([self.values, v.reshape(t.size, len(self.columns))])

    def around(self, t_lo: int, t_hi: int) -> tuple[np.ndarray, np.ndarray]:
        """([M] int64 t_ns, [M, C] values) covering ``[t_lo, t_hi]`` as described above."""
        if self.t.size and t_lo < self.t[0]:
            self._restart()
        while not self._done and (self.t.size == 0 or self.t[-1] <= t_hi):
            self._more()
        i = int(np.searchsorted(self.t, t_lo, side="right")) - 1
        i = max(0, min(i, self.t.size - 2))
        self.t, self.values = self.t[i:], self.values[i:]
        return self.t, self.values


class MedianSketch:
    """Median of a stream of non-negative values: exact up to 65,536 values, then within 0.3 %.

    Beyond the cap the values go into a histogram of 256 bins per octave over
    [2**-60, 2**60] (values outside are clamped into the end bins; zeros are counted apart).
    """

    _CAP = 1 << 16
    _PER_OCTAVE = 256
    _LO, _HI = -60, 60

    def __init__(self) -> None:
        self.n = 0
        self._kept: list[np.ndarray] | None = []
        self._hist: np.ndarray | None = None
        self._zeros = 0

    @property
    def exact(self) -> bool:
        return self._hist is None

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, np.float64).ravel()
        self.n += values.size
        if self._kept is not None:
            self._kept.append(values)
            if self.n <= self._CAP:
                return
            values = np.concatenate(self._kept)
            self._kept = None
            self._hist = np.zeros((self._HI - self._LO) * self._PER_OCTAVE, np.int64)
        assert self._hist is not None
        pos = values[values > 0]
        self._zeros += values.size - pos.size
        b = np.floor((np.log2(pos) - self._LO) * self._PER_OCTAVE)
        b = np.clip(np.nan_to_num(b, nan=0.0), 0, self._hist.size - 1).astype(np.int64)
        self._hist += np.bincount(b, minlength=self._hist.size)

    def median(self) -> float:
        """``np.median`` of the values (exact), or the centre of the histogram bin holding it."""
        if self.n == 0:
            return float("nan")
        if self._kept is not None:
            return float(np.median(np.concatenate(self._kept)))
        assert self._hist is not None
        k = (self.n - 1) // 2
        if k < self._zeros:
            return 0.0
        j = int(np.searchsorted(np.cumsum(self._hist), k - self._zeros, side="right"))
        return float(2.0 ** (self._LO + (j + 0.5) / self._PER_OCTAVE))

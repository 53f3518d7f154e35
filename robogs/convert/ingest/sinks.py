"""Streaming writers for episode tables and camera streams (memory-bounded).

:class:`TableSink` writes one parquet table in ``t_ns`` order, chunk by chunk, while samples
arrive from one or more sources (topics) in log-time order. Header stamps within a source may
be slightly out of order ("monotonic-ish"), and sources may lag each other, so rows wait in a
reorder buffer until every active source has moved past them by ``reorder_ns``; then they are
sorted and written. A sample that goes back by more than ``jump_back_ns`` is a clock jump, and a
sample older than rows already written cannot be placed: both are dropped and recorded in the
provenance with topic and stamp. A jump forward by more than ``jump_forward_ns`` is recorded
(the sample is kept). "Back" and "forward" are measured from a source's *current time*, the
median of its last :data:`_RECENT` stamps as they arrived, not from its newest stamp: one message that
the recorder logged early (its stamp far ahead of its neighbours) would otherwise make every
following sample look like a jump back, and drop them (issue 19: 1 % of early-logged messages
dropped 69 % of good samples).

:class:`CameraSink` writes a camera's ``frames.parquet`` and ``rgb.mp4`` as frames are decoded;
video frames cannot be reordered, so a frame whose stamp is not after the previous one is
dropped and recorded.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format.errors import FormatError, InputError, output_error
from robogs.format.images import VideoWriter
from robogs.format.tables import check_table_schema

from .provenance import Provenance

__all__ = ["TableSink", "CameraSink", "SinkStats", "median_rate_hz"]

_RATE_SAMPLES = 2001
#: accepted stamps per source whose median is its current time (robust to one early-logged message)
_RECENT = 9


def median_rate_hz(stamps_ns: list[int] | np.ndarray) -> float | None:
    """Nominal rate (Hz) from the median positive stamp step; ``None`` when undefined."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    if t.size < 2:
        return None
    dt = np.diff(t)
    dt = dt[dt > 0]
    if dt.size == 0:
        return None
    return float(1e9 / np.median(dt))


@dataclass
class SinkStats:
    """What a sink wrote: ``rows``, first/last stamp (ns), nominal rate (Hz)."""

    rows: int
    start_ns: int | None
    end_ns: int | None
    rate_hz: float | None


class TableSink:
    """One parquet table of kind ``kind``: ``t_ns``, an optional label column, float columns.

    Args:
        path: output file (inside the writer's temp folder).
        kind: table kind from :data:`robogs.format.tables.TABLES` (checked up front).
        float_columns: names of the float64 value columns, in order.
        label_column: name of the string column holding each source's label (``object``,
            ``link``, ``frame``) or ``None``.
        provenance: where dropped samples are recorded.
        reorder_ns: how far behind the slowest active source rows wait before being written.
        jump_back_ns / jump_forward_ns: clock-jump thresholds (ns).
        chunk_rows: buffer size that triggers a flush.
        stale_ns: a source silent for this long (in its own stamps, relative to the newest
            source) stops holding the others back.
    """

    def __init__(
        self,
        path: Path,
        kind: str,
        float_columns: list[str],
        *,
        label_column: str | None = None,
        provenance: Provenance,
        reorder_ns: int = 1_000_000_000,
        jump_back_ns: int = 1_000_000_000,
        jump_forward_ns: int = 3600 * 1_000_000_000,
        chunk_rows: int = 1 << 16,
        stale_ns: int = 10_000_000_000,
    ) -> None:
        fields = [pa.field("t_ns", pa.int64(), nullable=False)]
        if label_column:
            fields.append(pa.field(label_column, pa.string()))
        fields += [pa.field(c, pa.float64()) for c in float_columns]
        self.schema = pa.schema(fields)
        problems = check_table_schema(kind, self.schema)
        if problems:
            raise FormatError(
                f"internal: {kind} columns do not match the spec: {'; '.join(problems)}"
            )
        self.path = path
        self.kind = kind
        self.float_columns = list(float_columns)
        self.label_column = label_column
        self.prov = provenance
        self.reorder_ns = reorder_ns
        self.jump_back_ns = jump_back_ns
        self.jump_forward_ns = jump_forward_ns
        self.chunk_rows = chunk_rows
        self.stale_ns = stale_ns
        self._t: list[int] = []
        self._lab: list[int] = []
        self._rows: list[tuple[float, ...] | list[float]] = []
        self._labels: list[str] = []
        self._label_idx: dict[str, int] = {}
        self._recent: dict[str, deque[int]] = {}  # accepted stamps (duplicates)
        self._arrivals: dict[str, deque[int]] = {}  # every stamp seen (current time)
        self._rate: dict[str, list[int]] = {}
        self._emitted_max: int | None = None
        self._writer: pq.ParquetWriter | None = None
        self.rows = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None
        self.written: dict[str, int] = {}
        #: column -> (count of NaN/inf values written, stamp of the first), noted on close
        self.nonfinite: dict[str, tuple[int, int]] = {}

    def add(
        self, source: str, t_ns: int, values: tuple[float, ...] | list[float], label: str = ""
    ) -> bool:
        """Queue one row; returns False when it was dropped (and recorded)."""
        recent = self._recent.get(source)
        arrivals = self._arrivals.setdefault(source, deque(maxlen=_RECENT))
        now = self._now(source) if arrivals else None
        arrivals.append(int(t_ns))
        if recent and now is not None:
            if t_ns in recent:
                self.prov.issue(source, "duplicate stamp (sample dropped)", t_ns)
                return False
            if t_ns < now - self.jump_back_ns:
                self.prov.issue(
                    source,
                    "clock jump backwards by more than "
                    f"{self.jump_back_ns / 1e9:g} s (sample dropped)",
                    t_ns,
                )
                return False
            if t_ns > now + self.jump_forward_ns:
                self.prov.issue(
                    source,
                    f"clock jump forward by more than {self.jump_forward_ns / 3.6e12:g} h",
                    t_ns,
                    drop=False,
                )
        if self._emitted_max is not None and t_ns < self._emitted_max:
            self.prov.issue(source, "stamp older than rows already written (sample dropped)", t_ns)
            return False
        self._recent.setdefault(source, deque(maxlen=_RECENT)).append(int(t_ns))
        rs = self._rate.setdefault(source, [])
        if len(rs) < _RATE_SAMPLES:
            rs.append(t_ns)
        idx = self._label_idx.get(label)
        if idx is None:
            idx = self._label_idx[label] = len(self._labels)
            self._labels.append(label)
        self._t.append(int(t_ns))
        self._lab.append(idx)
        self._rows.append(values)
        self.written[source] = self.written.get(source, 0) + 1
        if len(self._t) >= self.chunk_rows:
            self._flush(final=False)
        return True

    def _now(self, source: str) -> int:
        """A source's current time (ns): the median of its last stamps as they arrived."""
        return int(np.median(np.fromiter(self._arrivals[source], np.int64)))

    def _watermark(self) -> int:
        now = [self._now(s) for s in self._arrivals]
        newest = max(now)
        active = [t for t in now if t >= newest - self.stale_ns]
        return min(active) - self.reorder_ns

    def _flush(self, *, final: bool) -> None:
        if not self._t:
            return
        t = np.asarray(self._t, dtype=np.int64)
        order = np.argsort(t, kind="stable")
        if final:
            n_emit = t.size
        else:
            n_emit = int(np.searchsorted(t[order], self._watermark(), side="right"))
            if n_emit == 0:
                return
        emit, keep = order[:n_emit], order[n_emit:]
        vals = np.asarray(self._rows, dtype=np.float64).reshape(t.size, len(self.float_columns))
        lab = np.asarray(self._lab, dtype=np.int64)
        cols: list[pa.Array] = [pa.array(t[emit], type=pa.int64())]
        if self.label_column:
            cols.append(pa.array([self._labels[i] for i in lab[emit]], type=pa.string()))
        cols += [pa.array(vals[emit, j], type=pa.float64()) for j in range(vals.shape[1])]
        bad = ~np.isfinite(vals[emit])
        for j in np.flatnonzero(bad.any(axis=0)):  # kept as recorded; counted and noted
            col, rows = self.float_columns[j], np.flatnonzero(bad[:, j])
            n0, t0 = self.nonfinite.get(col, (0, int(t[emit[rows[0]]])))
            self.nonfinite[col] = (n0 + int(rows.size), t0)
        table = pa.Table.from_arrays(cols, schema=self.schema)
        try:  # a full disk is the output's fault, never "a corrupt input"
            if self._writer is None:
                self._writer = pq.ParquetWriter(self.path, self.schema, compression="zstd")
            self._writer.write_table(table, row_group_size=1 << 16)
        except OSError as exc:
            raise output_error(exc, path=self.path, action="writing a table") from None
        self.rows += n_emit
        first, last = int(t[emit[0]]), int(t[emit[-1]])
        self.start_ns = first if self.start_ns is None else self.start_ns
        self.end_ns = last
        self._emitted_max = last
        keep_sorted = np.sort(keep)  # keep arrival order among the rest
        self._t = [self._t[i] for i in keep_sorted]
        self._lab = [self._lab[i] for i in keep_sorted]
        self._rows = [self._rows[i] for i in keep_sorted]

    def rate_hz(self) -> float | None:
        """Nominal rate: the common per-source median rate, ``None`` if sources disagree by > 5 %."""
        rates = [r for r in (median_rate_hz(v) for v in self._rate.values()) if r is not None]
        if not rates:
            return None
        if max(rates) > 1.05 * min(rates):
            return None
        return float(np.mean(rates))

    def close(self) -> SinkStats:
        """Write the remaining rows and close the file (no file when no row was written)."""
        self._flush(final=True)
        for col, (n, t0) in sorted(self.nonfinite.items()):
            self.prov.note(
                f"{self.path.name}: {n} of {self.rows} values of {col} are NaN or inf (first at "
                f"t_ns {t0}); kept as recorded, robogs-validate reports them (I009)"
            )
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        return SinkStats(self.rows, self.start_ns, self.end_ns, self.rate_hz())

    def abort(self) -> None:
        """Close without flushing (the temp folder is discarded by the writer)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None


class CameraSink:
    """One camera stream: ``frames.parquet`` (t_ns, frame_index) and ``rgb.mp4``.

    Args:
        frames_path / video_path: output files.
        topic: source topic (for messages and provenance).
        provenance: where dropped frames are recorded.
        video: write the video (False: frames table only).
        fps_hint: container frame rate for the mp4 header (stamps live in the table).
    """

    def __init__(
        self,
        frames_path: Path,
        video_path: Path,
        *,
        topic: str,
        provenance: Provenance,
        video: bool = True,
        fps_hint: float = 30.0,
        chunk_rows: int = 1 << 14,
    ) -> None:
        self.frames_path = frames_path
        self.video_path = video_path
        self.topic = topic
        self.prov = provenance
        self.video = video
        self.fps_hint = fps_hint if fps_hint and fps_hint > 0 else 30.0
        self.chunk_rows = chunk_rows
        self.schema = pa.schema(
            [pa.field("t_ns", pa.int64(), nullable=False), pa.field("frame_index", pa.int64())]
        )
        self._vw: VideoWriter | None = None
        self._pw: pq.ParquetWriter | None = None
        self._t: list[int] = []
        self._rate: list[int] = []
        self.size: tuple[int, int] | None = None
        self.count = 0
        self.start_ns: int | None = None
        self.end_ns: int | None = None

    def accepts(self, t_ns: int) -> bool:
        """Whether a frame at ``t_ns`` can be appended (records a drop when not)."""
        if self.end_ns is not None and t_ns <= self.end_ns:
            self.prov.issue(
                self.topic, "frame stamp not after the previous frame (frame dropped)", t_ns
            )
            return False
        return True

    def add(self, t_ns: int, rgb: np.ndarray | None) -> None:
        """Append one frame (call :meth:`accepts` first). ``rgb`` is [H, W, 3] uint8."""
        if self.video:
            if rgb is None:
                raise FormatError("internal: video frame missing")
            h, w = int(rgb.shape[0]), int(rgb.shape[1])
            if self.size is None:
                self.size = (w, h)
                self._vw = VideoWriter(self.video_path, w, h, self.fps_hint)
            elif self.size != (w, h):
                raise InputError(
                    f"image size changed from {self.size[0]}x{self.size[1]} to {w}x{h}",
                    where=f"topic {self.topic} stamp {t_ns}",
                    hint="a camera stream must keep one resolution",
                )
            assert self._vw is not None
            self._vw.write(rgb)
        self._t.append(int(t_ns))
        if len(self._rate) < _RATE_SAMPLES:
            self._rate.append(int(t_ns))
        self.start_ns = t_ns if self.start_ns is None else self.start_ns
        self.end_ns = t_ns
        self.count += 1
        if len(self._t) >= self.chunk_rows:
            self._flush()

    def _flush(self) -> None:
        if not self._t:
            return
        n0 = self.count - len(self._t)
        table = pa.Table.from_arrays(
            [
                pa.array(self._t, type=pa.int64()),
                pa.array(np.arange(n0, self.count, dtype=np.int64)),
            ],
            schema=self.schema,
        )
        try:
            if self._pw is None:
                self._pw = pq.ParquetWriter(self.frames_path, self.schema, compression="zstd")
            self._pw.write_table(table)
        except OSError as exc:
            raise output_error(exc, path=self.frames_path, action="writing a table") from None
        self._t = []

    def close(self) -> SinkStats:
        self._flush()
        if self._pw is not None:
            self._pw.close()
            self._pw = None
        if self._vw is not None:
            self._vw.close()
            self._vw = None
        return SinkStats(self.count, self.start_ns, self.end_ns, median_rate_hz(self._rate))

    def abort(self) -> None:
        if self._pw is not None:
            self._pw.close()
            self._pw = None
        if self._vw is not None:
            self._vw.close()
            self._vw = None

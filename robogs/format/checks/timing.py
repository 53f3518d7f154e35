"""Time checks (T0xx): stamps, rates, gaps, jitter, coverage and cross-stream consistency.

Periodic-stream statistics follow one definition (per stream; per link for ``ee_poses``, per
object for ``object_poses``, per frame for ``wrenches``), robust to jitter that is a sizeable
fraction of the period (see :mod:`.clock`). With ``p0`` the median interval of a series:

* *lost samples* are counted from phase steps: an interval longer than ``1.5 p0`` loses
  ``round(step / p0)`` samples, ``step`` being the change of the median phase ``t_j - j p0``
  of the 10 samples before and after it; long intervals from jitter alone lose none (a single
  late stamp is jitter, T006, however long the interval before it);
* a *gap* is an interval longer than ``time.gap_factor * p0`` that also spans more than
  ``time.gap_factor`` slots (lost samples plus one, T003); gaps split the series into segments; *dropped samples* are those lost at shorter
  intervals (T004);
* the *nominal period* ``p`` is the time spanned by the segments over the slots they hold
  (samples plus dropped samples), which cancels the jitter (T002);
* *jitter* is a stamp's error against the stream's clock: its phase ``t_j - n_j p`` (``n_j``
  its slot) minus the median phase of the 21 samples around it (T005, T006). It is what
  misplaces a sample in time, so it compares with the time budgets directly; the deviation
  of an interval from the period counts two stamps' errors and is not used.

A stream whose ``nominal_rate_hz`` is ``null`` is declared aperiodic and is
left out of T002-T006. Series whose stamps are not increasing are reported by
T001 only.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ..findings import Finding
from ._common import MS, column, stream_tables
from .clock import chunks_with_context, find_drops, stamp_errors
from .context import ENTITY_COLUMNS, PERIODIC_KINDS, CheckContext, InputReported
from .registry import Check, check
from .streaming import batches, median, percentile

__all__: list[str] = []

_MAX_GAPS_PER_SERIES = 5
#: p99 jitter above this fraction of the period (but within budget) is reported as a note
_NOTE_JITTER = 0.25


@dataclass
class _Series:
    """One entity of one stream, with the facts of one scan of its stamps.

    The stamps themselves are not kept: later passes read them again in batches
    (:func:`_steps`), so memory does not grow with the length of a stream.
    """

    episode: str
    stream: str
    kind: str
    rel: str
    ent_col: str | None
    entity: str | None
    strict: bool
    periodic: bool
    nominal_hz: float | None
    n: int = 0
    bad_steps: int = 0
    first_bad: tuple[int, int, int] | None = None  # (t before, t after, row after)
    last: tuple[int, int] | None = None  # (t, row) of the last stamp scanned

    def absorb(self, t: np.ndarray, rows: np.ndarray) -> None:
        """Scan the next stamps of the series (table order)."""
        if self.last is not None:
            t = np.concatenate(([self.last[0]], t))
            rows = np.concatenate(([self.last[1]], rows))
        d = np.diff(t)
        bad = np.flatnonzero(d <= 0) if self.strict else np.flatnonzero(d < 0)
        if bad.size:
            if self.first_bad is None:
                i = int(bad[0])
                self.first_bad = (int(t[i]), int(t[i + 1]), int(rows[i + 1]))
            self.bad_steps += int(bad.size)
        self.n += t.size - (self.last is not None)
        self.last = (int(t[-1]), int(rows[-1]))


def _split(t: np.ndarray, keys: pa.ChunkedArray | None) -> list[tuple[str | None, np.ndarray]]:
    """Row indices of each entity (table order kept within an entity)."""
    if keys is None:
        return [(None, np.arange(t.size))]
    keys = pc.fill_null(pc.cast(keys, pa.string()), "<null>")
    enc = keys.combine_chunks().dictionary_encode()
    codes = enc.indices.to_numpy(zero_copy_only=False)
    names = enc.dictionary.to_pylist()
    order = np.argsort(codes, kind="stable")
    bounds = np.flatnonzero(np.diff(codes[order])) + 1
    return [(str(names[codes[g[0]]]), g) for g in np.split(order, bounds) if g.size]


def _keys(col: pa.Array) -> pa.Array:
    return pc.fill_null(pc.cast(col, pa.string()), "<null>")


def _scan(ctx: CheckContext, ent_col: str | None, **meta: object) -> list[_Series]:
    """The series of table ``meta['rel']`` (entities in order of first appearance), in one pass."""
    rel = str(meta["rel"])
    series: dict[str | None, _Series] = {}
    offset = 0
    for b in batches(ctx, rel, ("t_ns",) if ent_col is None else ("t_ns", ent_col)):
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        rows = np.arange(offset, offset + t.size)
        offset += t.size
        if ent_col is None:
            groups = [(None, t, rows)]
        else:
            enc = _keys(b.column(1)).dictionary_encode()
            codes = enc.indices.to_numpy(zero_copy_only=False)
            groups = [
                (str(name), t[codes == c], rows[codes == c])
                for c, name in enumerate(enc.dictionary.to_pylist())
            ]
        for entity, te, re in groups:
            if te.size:
                if entity not in series:
                    series[entity] = _Series(ent_col=ent_col, entity=entity, **meta)  # type: ignore[arg-type]
                series[entity].absorb(te, re)
    return list(series.values())


def _series(ctx: CheckContext) -> Iterator[_Series]:
    """Every stamped series of the dataset (cached per context: facts only, no stamps)."""
    yield from ctx.cached(("timing-series",), lambda: list(_build_series(ctx)))


def _build_series(ctx: CheckContext) -> Iterator[_Series]:
    for ep, name, st in ctx.streams():
        kind = st.get("kind")
        nominal = st.get("nominal_rate_hz", 0.0)
        periodic = nominal is not None and kind in PERIODIC_KINDS
        nominal_hz = float(nominal) if isinstance(nominal, int | float) and nominal > 0 else None
        if kind == "camera":
            rel, ent_col = st.get("frames"), None
        elif kind == "segments":
            continue
        else:
            rel, ent_col = st.get("path"), ENTITY_COLUMNS.get(str(kind))
        if not isinstance(rel, str):
            continue
        try:
            names = ctx.footer(rel).schema.to_arrow_schema().names
            if "t_ns" not in names:
                continue  # reported by S003
            yield from _scan(
                ctx,
                ent_col if ent_col in names else None,
                episode=ep.id,
                stream=name,
                kind=str(kind),
                rel=rel,
                strict=kind not in ("boxes2d", "generic"),
                periodic=periodic,
                nominal_hz=nominal_hz,
            )
        except InputReported:
            continue


def _steps(
    ctx: CheckContext, s: _Series
) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Consecutive stamps of a series, batch by batch: (period as float64 ns, t before,
    t after, row before, row after)."""
    prev: tuple[int, int] | None = None
    for t, rows in _stamps(ctx, s):
        if prev is not None:  # the step across the batch boundary
            t = np.concatenate(([prev[0]], t))
            rows = np.concatenate(([prev[1]], rows))
        prev = (int(t[-1]), int(rows[-1]))
        if t.size > 1:
            yield np.diff(t).astype(np.float64), t[:-1], t[1:], rows[:-1], rows[1:]


def _loc(s: _Series, **extra: object) -> dict[str, object]:
    loc: dict[str, object] = {"file": s.rel, "episode": s.episode, "stream": s.stream}
    if s.entity is not None:
        loc["link" if s.kind == "ee_poses" else "object"] = s.entity
    loc.update(extra)
    return loc


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "T001",
    group="time",
    severity="error",
    title="stamps increase within each stream",
    quantity="non-increasing steps",
    unit="steps",
    budget="",
    hint="sort the rows by t_ns and drop duplicates, or fix the stamping at the source",
)
def _monotonic(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for s in _series(ctx):
        if s.first_bad is None:
            continue
        t_before, t_after, row = s.first_bad
        what = "strictly increasing" if s.strict else "non-decreasing"
        ent = f" ({s.entity})" if s.entity is not None else ""
        yield chk.finding(
            f"stamps{ent} are not {what}: {s.bad_steps} steps, first at row {row} "
            f"({t_before} -> {t_after} ns)",
            value=s.bad_steps,
            budget=0,
            **_loc(s, t_ns=t_after, where=f"row {row}"),
        )


def _stamps(ctx: CheckContext, s: _Series) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Stamps of a series batch by batch: ([B] int64 t_ns, [B] table rows)."""
    offset = 0
    cols = ("t_ns",) if s.ent_col is None else ("t_ns", s.ent_col)
    for b in batches(ctx, s.rel, cols):
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        rows = np.arange(offset, offset + t.size)
        offset += t.size
        if s.ent_col is not None:
            mask = pc.equal(_keys(b.column(1)), s.entity).to_numpy(zero_copy_only=False)
            t, rows = t[mask], rows[mask]
        if t.size:
            yield t, rows


@dataclass
class _Periods:
    """Period statistics of one series (see the module docstring).

    ``gaps`` and ``first_drop`` hold (interval ns, t before, row before); ``drops`` the
    (global sample index, samples lost) of each place; jitter is in ms, its percentiles are
    computed on demand, exactly.
    """

    p0_ns: float
    period_ns: float
    n_gaps: int
    gaps: list[tuple[float, int, int]]
    drops: list[tuple[int, int]]
    first_drop: tuple[float, int, int] | None
    long_intervals: int
    n_jitter: int
    jitter_max_ms: float
    jitter_at: tuple[int, int] | None
    jitter_values: Callable[[], Iterator[np.ndarray]]
    _pct: dict[float, float] = field(default_factory=dict)

    @property
    def lost(self) -> int:
        return sum(n for _, n in self.drops)

    def jitter_pct(self, q: float) -> float:
        if q not in self._pct:
            self._pct[q] = percentile(self.jitter_values, self.n_jitter, q)
        return self._pct[q]


def _periods(ctx: CheckContext, s: _Series, gap_factor: float) -> _Periods | None:
    if not s.periodic or s.n < 3 or s.bad_steps:
        return None
    p0 = median(lambda: (d for d, *_ in _steps(ctx, s)), s.n - 1)
    if p0 <= 0:
        return None
    gaps: list[tuple[float, int, int]] = []
    drops: list[tuple[int, int]] = []
    gap_at: list[int] = []
    n_gaps = long_intervals = intervals = 0
    span = 0.0
    first_drop = None
    taken = 0  # global index up to which clusters of long intervals were examined
    for g0, (t, rows), lo, hi in chunks_with_context(_stamps(ctx, s)):
        k = np.arange(max(lo, 1), hi)
        d = (t[k] - t[k - 1]).astype(np.float64)
        span += float(d.sum())
        intervals += int(d.size)
        long_intervals += int(np.sum(d > 1.5 * p0))
        found, end = find_drops(t, max(lo, taken - g0), hi, p0, gap_factor)
        taken = max(taken, g0 + end)
        for i, lost, is_gap in found:
            where = (float(t[i] - t[i - 1]), int(t[i - 1]), int(rows[i - 1]))
            if is_gap:
                n_gaps += 1
                gap_at.append(g0 + i)
                span -= where[0]  # a gap's interval holds no known number of slots
                intervals -= 1
                if len(gaps) < _MAX_GAPS_PER_SERIES:
                    gaps.append(where)
                continue
            drops.append((g0 + i, lost))
            first_drop = first_drop or where
    slots = intervals + sum(n for _, n in drops)
    period = span / slots if slots and span > 0 else p0
    at = np.array([g for g, _ in drops], np.int64)
    cum = np.concatenate([[0], np.cumsum([n for _, n in drops])]).astype(np.int64)
    gap_idx = np.array(sorted(gap_at), np.int64)

    def errors() -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(|stamp error| ms, t, row) of the core samples, chunk by chunk."""
        for g0, (t, rows), lo, hi in chunks_with_context(_stamps(ctx, s)):
            g = np.arange(g0, g0 + t.size)
            slot = g + cum[np.searchsorted(at, g, side="right")]  # index plus samples lost
            breaks = np.isin(g, gap_idx)
            e = np.abs(stamp_errors(t, slot, lo, hi, period, breaks)) * MS
            yield e, t[lo:hi], rows[lo:hi]

    jmax, jitter_at = -1.0, None
    for e, t, rows in errors():
        if e.size and e.max() > jmax:
            i = int(np.argmax(e))
            jmax, jitter_at = float(e[i]), (int(t[i]), int(rows[i]))

    def jitter_values() -> Iterator[np.ndarray]:
        for e, *_ in errors():
            yield e

    return _Periods(
        p0,
        period,
        n_gaps,
        gaps,
        drops,
        first_drop,
        long_intervals,
        s.n,
        jmax,
        jitter_at,
        jitter_values,
    )


def _all_periods(ctx: CheckContext) -> Iterator[tuple[_Series, _Periods]]:
    gf = ctx.budget("time.gap_factor")
    for i, s in enumerate(_series(ctx)):
        per = ctx.cached(("timing-periods", i, gf), lambda s=s: _periods(ctx, s, gf))
        if per is not None:
            yield s, per


@check(
    "T002",
    group="time",
    severity="error",
    title="measured rate matches the nominal rate",
    quantity="relative rate error |f/f_nominal - 1|",
    unit="ratio",
    budget="time.rate_tolerance",
    hint="correct nominal_rate_hz in the manifest, or the stamps if they were synthesised from a wrong rate",
)
def _rate(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    tol = ctx.budget("time.rate_tolerance")
    for s, per in _all_periods(ctx):
        if s.nominal_hz is None:
            continue
        rate = 1e9 / per.period_ns
        err = abs(rate / s.nominal_hz - 1.0)
        if err > tol:
            yield chk.finding(
                f"measured rate {rate:.4g} Hz (time over slots, drops included), nominal "
                f"{s.nominal_hz:.4g} Hz",
                value=err,
                budget=tol,
                **_loc(s),
            )


@check(
    "T003",
    group="time",
    severity="error",
    title="no gaps in periodic streams",
    quantity="gap duration",
    unit="ms",
    budget="time.gap_factor",
    hint="the recorder lost samples; re-record, or split the episode at the gap",
)
def _gaps(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    gf = ctx.budget("time.gap_factor")
    for s, per in _all_periods(ctx):
        for dt, t_ns, row in per.gaps:
            yield chk.finding(
                f"gap of {dt * MS:.4g} ms ({dt / per.p0_ns:.1f} median periods of "
                f"{per.p0_ns * MS:.4g} ms) after t_ns {t_ns}",
                value=dt * MS,
                budget=gf * per.p0_ns * MS,
                **_loc(s, t_ns=t_ns, where=f"row {row}"),
            )
        if per.n_gaps > len(per.gaps):
            yield chk.finding(f"{per.n_gaps - len(per.gaps)} more gaps in this series", **_loc(s))


@check(
    "T004",
    group="time",
    severity="warning",
    title="no dropped samples in periodic streams",
    quantity="samples lost, counted from phase steps at intervals of 1.5 to gap_factor periods",
    unit="samples",
    hint="the sensor or recorder dropped samples; check its load and queue sizes",
)
def _drops(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for s, per in _all_periods(ctx):
        if per.first_drop is None:
            continue
        dt, t_ns, row = per.first_drop
        yield chk.finding(
            f"{per.lost} samples dropped in {len(per.drops)} places; first after t_ns {t_ns} "
            f"(interval {dt * MS:.4g} ms, period {per.period_ns * MS:.4g} ms; "
            f"{per.long_intervals} intervals over 1.5 periods, the others are jitter)",
            value=per.lost,
            budget=0,
            **_loc(s, t_ns=t_ns, where=f"row {row}"),
        )


def _jitter_text(per: _Periods) -> str:
    return (
        f"stamp error against the stream's clock p50 {per.jitter_pct(50):.3g} ms, p99 "
        f"{per.jitter_pct(99):.3g} ms, max {per.jitter_max_ms:.3g} ms (period "
        f"{per.period_ns * MS:.4g} ms)"
    )


@check(
    "T005",
    group="time",
    severity="error",
    title="stamp jitter p99 within budget",
    quantity="p99 of |stamp error| against the stream's fitted clock",
    unit="ms",
    budget="time.jitter_p99_ms",
    hint="stamp at the sensor (header stamps) rather than on arrival, or filter the stamps",
)
def _jitter_p99(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.jitter_p99_ms")
    for s, per in _all_periods(ctx):
        if per.n_jitter == 0:
            continue
        period_ms = per.period_ns * MS
        if per.jitter_max_ms > budget and (p99 := per.jitter_pct(99)) > budget:
            yield chk.finding(_jitter_text(per), value=p99, budget=budget, **_loc(s))
        elif (
            per.jitter_max_ms > _NOTE_JITTER * period_ms
            and (p99 := per.jitter_pct(99)) > _NOTE_JITTER * period_ms
        ):
            yield chk.finding(
                _jitter_text(per) + f": {100 * p99 / period_ms:.3g} % of the period, within "
                "the budget; drops are counted from phase steps, not from long intervals",
                value=p99,
                budget=budget,
                severity="info",
                **_loc(s),
            )


@check(
    "T006",
    group="time",
    severity="error",
    title="largest stamp jitter within budget",
    quantity="max of |stamp error| against the stream's fitted clock",
    unit="ms",
    budget="time.jitter_max_ms",
    hint="a single late stamp breaks ms-level alignment; find the stall at that time",
)
def _jitter_max(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.jitter_max_ms")
    for s, per in _all_periods(ctx):
        if per.n_jitter and per.jitter_max_ms > budget and per.jitter_at is not None:
            t_ns, row = per.jitter_at
            yield chk.finding(
                _jitter_text(per),
                value=per.jitter_max_ms,
                budget=budget,
                **_loc(s, t_ns=t_ns, where=f"row {row}"),
            )


def t_range(ctx: CheckContext, rel: str) -> tuple[int, int] | None:
    """(min, max) ``t_ns`` of a table from its footer statistics; None if absent or empty.

    Full mode falls back to reading the column when the footer has no statistics. Kept per
    table for the next check (T007 and T008 both ask; an unreadable table is asked again).
    """
    # reported=False: a RobogsError reaches the calling check as it did before the cache
    return ctx.cached(("t-range", rel), lambda: _t_range(ctx, rel), reported=False)


def _t_range(ctx: CheckContext, rel: str) -> tuple[int, int] | None:
    md = ctx.footer(rel)
    schema = md.schema.to_arrow_schema()
    names = schema.names
    if "t_ns" not in names or md.num_rows == 0:
        return None
    if names.count("t_ns") != 1 or not pa.types.is_int64(schema.field("t_ns").type):
        raise InputReported(rel)  # S003 reports the column
    j = names.index("t_ns")
    lo: list[int] = []
    hi: list[int] = []
    for g in range(md.num_row_groups):
        rg = md.row_group(g)
        if rg.num_rows == 0:
            continue
        stats = rg.column(j).statistics
        if stats is None or not stats.has_min_max:
            lo = []
            break
        lo.append(int(stats.min))
        hi.append(int(stats.max))
    if lo:
        return min(lo), max(hi)
    if ctx.quick:
        return None
    t = ctx.table(rel, columns=("t_ns",)).column("t_ns").to_numpy(zero_copy_only=False)
    return (int(t.min()), int(t.max())) if t.size else None


def _ranges(ctx: CheckContext) -> Iterator[tuple[object, str, dict, str, tuple[int, int]]]:
    for ep, name, st in ctx.streams():
        kind = st.get("kind")
        rel = st.get("frames") if kind == "camera" else st.get("path")
        if kind in ("segments", "generic") or not isinstance(rel, str):
            continue
        try:
            rng = t_range(ctx, rel)
        except InputReported:
            continue
        if rng is not None:
            yield ep, name, st, rel, rng


def _ends_beyond(
    chk: Check, budget: float, loc: dict[str, object], *ends: tuple[float, int, str]
) -> Iterator[Finding]:
    """One finding per stream end beyond ``budget``: ``ends`` are (ms, t_ns, message template)."""
    for ms, t_ns, text in ends:
        if ms > budget:
            yield chk.finding(text.format(ms), value=ms, budget=budget, t_ns=t_ns, **loc)


@check(
    "T007",
    group="time",
    severity="error",
    title="every stream covers its episode",
    needs_full=False,
    quantity="late start or early end",
    unit="ms",
    budget="time.coverage_ms",
    hint="trim the episode bounds to the span all streams cover, or find the missing samples",
)
def _coverage(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.coverage_ms")
    for ep, name, st, rel, (lo, hi) in _ranges(ctx):
        if st.get("kind") not in PERIODIC_KINDS:
            continue
        yield from _ends_beyond(
            chk,
            budget,
            {"file": rel, "episode": ep.id, "stream": name},
            ((lo - ep.start_ns) * MS, lo, "stream starts {:.4g} ms after the episode start"),
            ((ep.end_ns - hi) * MS, hi, "stream ends {:.4g} ms before the episode end"),
        )


@check(
    "T008",
    group="time",
    severity="error",
    title="stamps lie within the episode bounds",
    needs_full=False,
    quantity="stamp outside [start_ns, end_ns]",
    unit="ms",
    budget="time.sync_ms",
    hint="the stream's clock or offset_ns disagrees with the others; re-derive the offset, "
    "or widen start_ns/end_ns if the bounds are wrong",
)
def _bounds(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.sync_ms")
    for ep, name, _st, rel, (lo, hi) in _ranges(ctx):
        yield from _ends_beyond(
            chk,
            budget,
            {"file": rel, "episode": ep.id, "stream": name},
            ((ep.start_ns - lo) * MS, lo, "first stamp is {:.4g} ms before the episode start"),
            ((hi - ep.end_ns) * MS, hi, "last stamp is {:.4g} ms after the episode end"),
        )


def _frame_index(ctx: CheckContext, rel: str) -> np.ndarray:
    return column(ctx.table(rel, columns=("frame_index",)), "frame_index")


_EXACT_VIDEO_FRAMES = 3000


@check(
    "T009",
    group="time",
    severity="error",
    title="video frames match the frame table",
    quantity="frame count difference",
    unit="frames",
    hint="frame_index i must be frame i of the video, one row per frame; re-export the frame table",
)
def _video(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    from ..images import video_frame_count

    for ep, name, st in ctx.streams(("camera",)):
        rel = st.get("frames")
        if not isinstance(rel, str):
            continue
        loc = {"file": rel, "episode": ep.id, "stream": name}
        try:
            fi = _frame_index(ctx, rel)
        except InputReported:
            continue
        if fi.size and not np.all(np.diff(fi) > 0):
            yield chk.finding("frame_index is not strictly increasing", **loc)
            continue
        vrel = st.get("video")
        if not isinstance(vrel, str):
            continue
        try:
            vpath = ctx.existing(vrel)
        except InputReported:
            continue
        n = video_frame_count(vpath)
        if 0 < n <= _EXACT_VIDEO_FRAMES:
            n = video_frame_count(vpath, exact=True)
        if n != fi.size:
            yield chk.finding(
                f"video has {n} frames, the frame table {fi.size} rows",
                value=n - fi.size,
                budget=0,
                file=vrel,
                episode=ep.id,
                stream=name,
            )
        elif fi.size and (fi[0] != 0 or fi[-1] != n - 1):
            yield chk.finding(
                f"frame_index runs {int(fi[0])}..{int(fi[-1])}, the video has frames 0..{n - 1}",
                **loc,
            )


@check(
    "T010",
    group="time",
    severity="error",
    title="label frames are recorded frames",
    quantity="label rows without a frame",
    unit="rows",
    hint="every label row's frame_index must appear once in the camera's frame table",
)
def _labels(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for ep, name, st in ctx.streams(("camera",)):
        rel, lrel = st.get("frames"), st.get("labels")
        if not isinstance(lrel, str):
            continue
        loc = {"file": lrel, "episode": ep.id, "stream": name}
        try:
            lab = _frame_index(ctx, lrel)
            frames = _frame_index(ctx, rel) if isinstance(rel, str) else None
        except InputReported:
            continue
        uniq, counts = np.unique(lab, return_counts=True)
        if np.any(counts > 1):
            dup = uniq[counts > 1]
            yield chk.finding(
                f"{dup.size} frame indices have more than one label image, e.g. {int(dup[0])}",
                value=int(np.sum(counts[counts > 1] - 1)),
                budget=0,
                frame=int(dup[0]),
                **loc,
            )
        if frames is None:
            yield chk.finding(
                "labels without a frame table (frames)", value=lab.size, budget=0, **loc
            )
            continue
        unknown = np.setdiff1d(uniq, frames)
        if unknown.size:
            yield chk.finding(
                f"{unknown.size} label frame indices are not in the frame table, e.g. {int(unknown[0])}",
                value=unknown.size,
                budget=0,
                frame=int(unknown[0]),
                **loc,
            )


@check(
    "T011",
    group="time",
    severity="error",
    title="2D boxes refer to recorded frames at their stamps",
    quantity="box stamp minus frame stamp",
    unit="ms",
    budget="time.sync_ms",
    hint="boxes2d rows copy the t_ns of their camera frame; re-derive them from the frame table",
)
def _boxes2d(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.sync_ms")
    for ep, name, rel, boxes in stream_tables(ctx, "boxes2d", ("t_ns", "camera", "frame_index")):
        cams = {
            s["camera"]: s
            for s in ep.streams.values()
            if isinstance(s, dict)
            and s.get("kind") == "camera"
            and isinstance(s.get("camera"), str)
        }
        for cam, rows in _split(boxes.column("t_ns").to_numpy(), boxes.column("camera")):
            loc = {"file": rel, "episode": ep.id, "stream": name}
            cst = cams.get(cam)
            if cst is None or not isinstance(cst.get("frames"), str):
                yield chk.finding(
                    f"boxes of camera {cam!r}, which has no frame table in this episode",
                    value=rows.size,
                    budget=0,
                    unit="rows",
                    file=rel,
                    episode=ep.id,
                    stream=name,
                )
                continue
            try:
                ft = ctx.table(cst["frames"], columns=("t_ns", "frame_index"))
            except InputReported:
                continue
            f_idx = ft.column("frame_index").to_numpy()
            f_t = ft.column("t_ns").to_numpy()
            b_idx = boxes.column("frame_index").to_numpy()[rows]
            b_t = boxes.column("t_ns").to_numpy()[rows]
            order = np.argsort(f_idx, kind="stable")
            pos = np.clip(np.searchsorted(f_idx[order], b_idx), 0, max(f_idx.size - 1, 0))
            found = f_idx.size > 0 and f_idx[order][pos] == b_idx
            found = np.asarray(found, bool) if f_idx.size else np.zeros(b_idx.size, bool)
            if not found.all():
                k = int(np.flatnonzero(~found)[0])
                yield chk.finding(
                    f"{int((~found).sum())} boxes of camera {cam!r} name frames not in its frame table",
                    value=int((~found).sum()),
                    budget=0,
                    unit="rows",
                    frame=int(b_idx[k]),
                    **loc,
                )
            if found.any():
                diff_ms = (b_t[found] - f_t[order][pos[found]]) * MS
                k = int(np.argmax(np.abs(diff_ms)))
                worst = float(abs(diff_ms[k]))
                if worst > budget:
                    yield chk.finding(
                        f"box stamps of camera {cam!r} differ from their frame stamps by up to {worst:.4g} ms "
                        f"({int((np.abs(diff_ms) > budget).sum())} rows)",
                        value=worst,
                        budget=budget,
                        frame=int(b_idx[found][k]),
                        t_ns=int(b_t[found][k]),
                        **loc,
                    )


from . import stale as _stale  # noqa: E402,F401  (registers T014)

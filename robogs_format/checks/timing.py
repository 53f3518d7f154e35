"""Time checks (T0xx): stamps, rates, gaps, jitter, coverage and cross-stream consistency.

Periodic-stream statistics follow one definition. With ``p`` the median period
of a series (per stream; per link for ``ee_poses``, per object for
``object_poses``, per frame for ``wrenches``):

* a *gap* is a period longer than ``time.gap_factor * p`` (T003);
* a *dropped sample* is a period in ``(1.5 p, time.gap_factor * p]`` (T004);
* *jitter* is ``|period - p|`` over the remaining periods (T005, T006).

A stream whose ``nominal_rate_hz`` is ``null`` is declared aperiodic and is
left out of T002-T006. Series whose stamps are not increasing are reported by
T001 only.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ..findings import Finding
from .context import ENTITY_COLUMNS, PERIODIC_KINDS, CheckContext, InputReported
from .registry import Check, check

__all__: list[str] = []

_DROP_FACTOR = 1.5
_MAX_GAPS_PER_SERIES = 5
_MS = 1e-6  # ns -> ms


@dataclass(frozen=True)
class _Series:
    """The stamps of one entity of one stream, in table order."""

    episode: str
    stream: str
    kind: str
    rel: str
    entity: str | None
    t_ns: np.ndarray
    rows: np.ndarray  # table row of each stamp
    strict: bool
    periodic: bool
    nominal_hz: float | None


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


def _series(ctx: CheckContext) -> Iterator[_Series]:
    """Every stamped series of the dataset (cached per context)."""
    key = ("timing-series",)
    if key not in ctx._cache:
        ctx._cache[key] = list(_build_series(ctx))
    yield from ctx._cache[key]


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
            cols = ("t_ns",) if ent_col is None or ent_col not in names else ("t_ns", ent_col)
            table = ctx.table(rel, columns=cols)
        except InputReported:
            continue
        t = table.column("t_ns").to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        keys = table.column(ent_col) if len(cols) == 2 else None
        strict = kind not in ("boxes2d",)
        for entity, rows in _split(t, keys):
            yield _Series(
                ep.id, name, str(kind), rel, entity, t[rows], rows, strict, periodic, nominal_hz
            )


def _loc(s: _Series, **extra: object) -> dict[str, object]:
    loc: dict[str, object] = {"file": s.rel, "episode": s.episode, "stream": s.stream}
    if s.entity is not None:
        loc["link" if s.kind == "ee_poses" else "object"] = s.entity
    loc.update(extra)
    return loc


def _increasing(s: _Series) -> bool:
    d = np.diff(s.t_ns)
    return bool(np.all(d > 0)) if s.strict else bool(np.all(d >= 0))


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
        d = np.diff(s.t_ns)
        bad = np.flatnonzero(d <= 0) if s.strict else np.flatnonzero(d < 0)
        if bad.size == 0:
            continue
        i = int(bad[0])
        what = "strictly increasing" if s.strict else "non-decreasing"
        ent = f" ({s.entity})" if s.entity is not None else ""
        yield chk.finding(
            f"stamps{ent} are not {what}: {bad.size} steps, first at row {int(s.rows[i + 1])} "
            f"({int(s.t_ns[i])} -> {int(s.t_ns[i + 1])} ns)",
            value=bad.size,
            budget=0,
            **_loc(s, t_ns=int(s.t_ns[i + 1]), where=f"row {int(s.rows[i + 1])}"),
        )


@dataclass(frozen=True)
class _Periods:
    period_ns: float
    dt: np.ndarray
    gaps: np.ndarray  # indices into dt
    drops: np.ndarray
    jitter_ms: np.ndarray


def _periods(s: _Series, gap_factor: float) -> _Periods | None:
    if not s.periodic or s.t_ns.size < 3 or not _increasing(s):
        return None
    dt = np.diff(s.t_ns).astype(np.float64)
    p = float(np.median(dt))
    if p <= 0:
        return None
    gaps = np.flatnonzero(dt > gap_factor * p)
    drops = np.flatnonzero((dt > _DROP_FACTOR * p) & (dt <= gap_factor * p))
    regular = dt[dt <= _DROP_FACTOR * p]
    return _Periods(p, dt, gaps, drops, np.abs(regular - p) * _MS)


def _all_periods(ctx: CheckContext) -> Iterator[tuple[_Series, _Periods]]:
    gf = ctx.budget("time.gap_factor")
    for s in _series(ctx):
        per = _periods(s, gf)
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
                f"median rate {rate:.4g} Hz, nominal {s.nominal_hz:.4g} Hz",
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
        for n, i in enumerate(per.gaps):
            if n == _MAX_GAPS_PER_SERIES:
                yield chk.finding(f"{per.gaps.size - n} more gaps in this series", **_loc(s))
                break
            yield chk.finding(
                f"gap of {per.dt[i] * _MS:.4g} ms ({per.dt[i] / per.period_ns:.1f} periods of "
                f"{per.period_ns * _MS:.4g} ms) after t_ns {int(s.t_ns[i])}",
                value=per.dt[i] * _MS,
                budget=gf * per.period_ns * _MS,
                **_loc(s, t_ns=int(s.t_ns[i]), where=f"row {int(s.rows[i])}"),
            )


@check(
    "T004",
    group="time",
    severity="warning",
    title="no dropped samples in periodic streams",
    quantity="samples lost in periods of 1.5 to gap_factor periods",
    unit="samples",
    hint="the sensor or recorder dropped samples; check its load and queue sizes",
)
def _drops(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for s, per in _all_periods(ctx):
        if per.drops.size == 0:
            continue
        lost = int(np.sum(np.rint(per.dt[per.drops] / per.period_ns) - 1))
        i = int(per.drops[0])
        yield chk.finding(
            f"{max(lost, per.drops.size)} samples dropped in {per.drops.size} places; first after t_ns "
            f"{int(s.t_ns[i])} (period {per.dt[i] * _MS:.4g} ms, median {per.period_ns * _MS:.4g} ms)",
            value=max(lost, per.drops.size),
            budget=0,
            **_loc(s, t_ns=int(s.t_ns[i]), where=f"row {int(s.rows[i])}"),
        )


def _jitter_text(per: _Periods) -> str:
    j = per.jitter_ms
    return (
        f"jitter p50 {np.percentile(j, 50):.3g} ms, p99 {np.percentile(j, 99):.3g} ms, "
        f"max {j.max():.3g} ms around a {per.period_ns * _MS:.4g} ms period"
    )


@check(
    "T005",
    group="time",
    severity="error",
    title="stamp jitter p99 within budget",
    quantity="p99 of |period - median period|",
    unit="ms",
    budget="time.jitter_p99_ms",
    hint="stamp at the sensor (header stamps) rather than on arrival, or filter the stamps",
)
def _jitter_p99(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.jitter_p99_ms")
    for s, per in _all_periods(ctx):
        if per.jitter_ms.size and (p99 := float(np.percentile(per.jitter_ms, 99))) > budget:
            yield chk.finding(_jitter_text(per), value=p99, budget=budget, **_loc(s))


@check(
    "T006",
    group="time",
    severity="error",
    title="largest stamp jitter within budget",
    quantity="max of |period - median period|",
    unit="ms",
    budget="time.jitter_max_ms",
    hint="a single late stamp breaks ms-level alignment; find the stall at that time",
)
def _jitter_max(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.jitter_max_ms")
    for s, per in _all_periods(ctx):
        if per.jitter_ms.size and (mx := float(per.jitter_ms.max())) > budget:
            regular = np.flatnonzero(per.dt <= _DROP_FACTOR * per.period_ns)
            i = int(regular[np.argmax(per.jitter_ms)])
            yield chk.finding(
                _jitter_text(per),
                value=mx,
                budget=budget,
                **_loc(s, t_ns=int(s.t_ns[i + 1]), where=f"row {int(s.rows[i + 1])}"),
            )


def _ranges(ctx: CheckContext) -> Iterator[tuple[object, str, dict, str, tuple[int, int]]]:
    for ep, name, st in ctx.streams():
        kind = st.get("kind")
        rel = st.get("frames") if kind == "camera" else st.get("path")
        if kind == "segments" or not isinstance(rel, str):
            continue
        try:
            rng = ctx.t_range(rel)
        except InputReported:
            continue
        if rng is not None:
            yield ep, name, st, rel, rng


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
        late, early = (lo - ep.start_ns) * _MS, (ep.end_ns - hi) * _MS
        loc = {"file": rel, "episode": ep.id, "stream": name}
        if late > budget:
            yield chk.finding(
                f"stream starts {late:.4g} ms after the episode start",
                value=late,
                budget=budget,
                t_ns=lo,
                **loc,
            )
        if early > budget:
            yield chk.finding(
                f"stream ends {early:.4g} ms before the episode end",
                value=early,
                budget=budget,
                t_ns=hi,
                **loc,
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
        before, after = (ep.start_ns - lo) * _MS, (hi - ep.end_ns) * _MS
        loc = {"file": rel, "episode": ep.id, "stream": name}
        if before > budget:
            yield chk.finding(
                f"first stamp is {before:.4g} ms before the episode start",
                value=before,
                budget=budget,
                t_ns=lo,
                **loc,
            )
        if after > budget:
            yield chk.finding(
                f"last stamp is {after:.4g} ms after the episode end",
                value=after,
                budget=budget,
                t_ns=hi,
                **loc,
            )


def _frame_index(ctx: CheckContext, rel: str) -> np.ndarray:
    return (
        ctx.table(rel, columns=("frame_index",))
        .column("frame_index")
        .to_numpy(zero_copy_only=False)
    )


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
    for ep, name, st in ctx.streams(("boxes2d",)):
        rel = st.get("path")
        if not isinstance(rel, str):
            continue
        try:
            boxes = ctx.table(rel, columns=("t_ns", "camera", "frame_index"))
        except InputReported:
            continue
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
                diff_ms = (b_t[found] - f_t[order][pos[found]]) * _MS
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

"""Cleaning a log file's rows and cutting them into segments.

Rows with an unparseable stamp or a non-finite mapped value are dropped, duplicated stamps and
stamps going back are dropped (too many going back is an error), positions that look like
degrees read as radians are an error. The kept rows are cut at every change of the segment
column and at forward time gaps; velocities missing from the log are differentiated here.
Every drop is counted with its reason and source lines in a :class:`FileReport`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from robogs.format.errors import InputError

from .column_map import ColumnMap
from .pose import pose_samples
from .reading import RawLog, to_float, to_ns

__all__ = ["FileReport", "LogSegment", "clean_file"]

_MAX_BACK_FRACTION = 0.01


@dataclass
class LogSegment:
    """One trajectory of one file, cleaned and in SI units.

    Attributes:
        source: file name; index: segment number in the file.
        t_ns: [N] int64 stamps; q, qd: [N, J] (all joints, held ones constant); tau:
            [N, len(effort_joints)] or None.
        derived_velocity: velocities were differentiated from positions.
        lines: [N] source line numbers.
        effort_joints: the joints ``tau`` covers (the logged ones, not the held ones).
        ee_t_ns, ee: [M] stamps and [M, 7] end-effector poses (``x y z qw qx qy qz``, world)
            of the rows with a usable pose; None without ``ee_pose`` columns.
    """

    source: str
    index: int
    t_ns: np.ndarray
    q: np.ndarray
    qd: np.ndarray | None
    tau: np.ndarray | None
    derived_velocity: bool
    lines: np.ndarray
    effort_joints: list[str] = field(default_factory=list)
    ee_t_ns: np.ndarray | None = None
    ee: np.ndarray | None = None
    name: str | None = None


@dataclass
class FileReport:
    rows: int = 0
    written: int = 0
    dropped: dict[str, list[int]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    ee_rows: int = 0
    ee_written: int = 0
    ee_dropped: list[int] = field(default_factory=list)

    def drop(self, reason: str, lines: np.ndarray | list[int]) -> None:
        lst = self.dropped.setdefault(reason, [])
        lst.extend(int(x) for x in np.asarray(lines).ravel())


def _check_degrees(
    path: Path,
    cmap: ColumnMap,
    q: np.ndarray,
    lines: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    joint_names: list[str],
    report: FileReport,
) -> None:
    for k, j in enumerate(joint_names):
        lo, hi = lower[k], upper[k]
        if not (np.isfinite(lo) and np.isfinite(hi)) or len(q) == 0:
            continue
        qj = q[:, k]
        span = hi - lo
        outside = (qj < lo - 0.05 * span) | (qj > hi + 0.05 * span)
        if not outside.any():
            continue
        as_rad = qj * math.pi / 180.0
        inside_deg = np.all((as_rad >= lo - 1e-9) & (as_rad <= hi + 1e-9))
        worst = int(np.argmax(np.abs(qj)))
        col = cmap.joints[j].position
        if inside_deg and cmap.joints[j].units.get("position", "rad") == "rad":
            raise InputError(
                f"positions of joint {j!r} reach {qj[worst]:.4g} rad, far outside its URDF limits "
                f"[{lo:.4g}, {hi:.4g}] rad but inside them if read as degrees",
                path=path,
                where=f"line {lines[worst]}, column {col!r}",
                hint="the column is probably in degrees: pass --map with 'unit: deg' for it",
            )
        report.notes.append(
            f"joint {j!r} (column {col!r}) leaves its URDF limits on {int(outside.sum())} rows "
            f"(first at line {int(lines[np.argmax(outside)])})"
        )


def clean_file(
    path: Path,
    raw: RawLog,
    cmap: ColumnMap,
    joint_names: list[str],
    lower: np.ndarray,
    upper: np.ndarray,
    gap_s: float | None,
) -> tuple[list[LogSegment], FileReport]:
    """Clean one file's rows and cut them into segments: at every change of the
    ``segment_column`` value (time may restart there) and at forward time gaps."""
    report = FileReport(rows=len(raw.lines) + sum(len(v) for v in raw.dropped.values()))
    for reason, lns in raw.dropped.items():
        report.drop(reason, lns)
    missing = [c for c in cmap.columns() if c not in raw.data]
    if missing:
        raise InputError(
            f"column {missing[0]!r} named by the {cmap.layout} mapping is missing"
            + (f" (and {len(missing) - 1} more: {missing[1:4]})" if len(missing) > 1 else ""),
            path=path,
            where="header",
            hint=f"the file has columns {raw.columns[:12]}{' ...' if len(raw.columns) > 12 else ''}",
        )
    lines = raw.lines
    t_ns, t_bad = to_ns(raw.data[cmap.time_column], cmap.time_unit)
    t_ns = t_ns + int(cmap.epoch_ns)
    keep = ~t_bad
    if t_bad.any():
        report.drop(f"unparseable or missing stamp in column {cmap.time_column!r}", lines[t_bad])

    def numeric(col: str, scale: float) -> np.ndarray:
        nonlocal keep
        vals, bad = to_float(raw.data[col])
        nan = ~np.isfinite(vals) & ~bad
        if bool((bad | nan).all()) and len(vals):
            raise InputError(
                f"column {col!r} has no numeric value",
                path=path,
                where=f"column {col!r}",
                hint="check the mapping and the delimiter",
            )
        for mask, reason in (
            (bad & keep, f"unparseable value in column {col!r}"),
            (nan & keep, f"NaN or empty value in column {col!r}"),
        ):
            if mask.any():
                report.drop(reason, lines[mask])
        keep = keep & ~bad & ~nan
        return vals * scale

    logged = [j for j in joint_names if j not in cmap.hold]
    n_rows = len(lines)

    def per_joint(kind: str) -> np.ndarray:
        cols = []
        for j in joint_names:
            jc = cmap.joints.get(j)
            if jc is None:  # held joint
                v = cmap.hold[j] if kind == "position" else 0.0
                cols.append(np.full(n_rows, v))
            else:
                cols.append(numeric(getattr(jc, kind), getattr(jc, f"{kind}_scale")))
        return np.stack(cols, axis=1)

    q = per_joint("position")
    has_v = all(cmap.joints[j].velocity for j in logged)
    has_e = all(cmap.joints[j].effort for j in logged)
    qd = per_joint("velocity") if has_v else None
    tau = (
        np.stack(
            [numeric(cmap.joints[j].effort, cmap.joints[j].effort_scale) for j in logged],
            axis=1,
        )
        if has_e
        else None
    )
    ee = ee_ok = None
    if cmap.ee_pose is not None:  # a bad pose cell drops the pose only, not the joint row
        vals = np.stack([to_float(raw.data[c])[0] for c in cmap.ee_pose.columns], axis=1)
        ee, ee_ok = pose_samples(vals, cmap.ee_pose, lines, path)
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        raise InputError(
            "no usable row", path=path, hint="every row was dropped; see the provenance reasons"
        )
    group = _group_ids(raw, cmap.segment_column)
    idx = _monotonic(t_ns, idx, group, lines, path, cmap.time_column, report)
    t_k = t_ns[idx]
    g_k = group[idx]
    cols = [k for k, j in enumerate(joint_names) if j in cmap.joints]
    _check_degrees(
        path, cmap, q[idx][:, cols], lines[idx], lower[cols], upper[cols], logged, report
    )
    bounds, gap_ns, n_gaps = _cuts(t_k, g_k, gap_s)
    from robogs.format.differentiate import savgol_derivative  # scipy: loaded when used

    segments: list[LogSegment] = []
    for s in range(len(bounds) - 1):
        sel = idx[bounds[s] : bounds[s + 1]]
        if len(sel) < 5:
            report.drop("segment shorter than 5 samples", lines[sel])
            continue
        qs = q[sel]
        qds = qd[sel] if qd is not None else savgol_derivative(t_ns[sel], qs, order=1)
        ee_sel = None
        if ee is not None and ee_ok is not None:
            ee_sel = sel[ee_ok[sel]]
            report.ee_rows += len(sel)
            report.ee_written += len(ee_sel)
            report.ee_dropped.extend(int(x) for x in lines[sel][~ee_ok[sel]])
        segments.append(
            LogSegment(
                path.name,
                len(segments),
                t_ns[sel],
                qs,
                qds,
                tau[sel] if tau is not None else None,
                qd is None,
                lines[sel],
                logged if tau is not None else [],
                t_ns[ee_sel] if ee_sel is not None else None,
                ee[ee_sel] if ee_sel is not None and ee is not None else None,
                _group_name(raw, cmap.segment_column, sel[0]),
            )
        )
        report.written += len(sel)
    if n_gaps:
        report.notes.append(
            f"{n_gaps} time gap(s) over {gap_ns / 1e9:g} s split the file into {len(bounds) - 1} segments"
        )
    if cmap.segment_column is not None:
        report.notes.append(
            f"column {cmap.segment_column!r} names {len(np.unique(g_k))} trajectories; each "
            "becomes its own episode(s), with its name as the segment"
        )
    return segments, report


def _monotonic(
    t_ns: np.ndarray,
    idx: np.ndarray,
    group: np.ndarray,
    lines: np.ndarray,
    path: Path,
    time_column: str,
    report: FileReport,
) -> np.ndarray:
    """The rows ``idx`` less duplicated stamps and stamps going back (the kept order is the
    file order), within each named trajectory ``group``; more than 1 % going back is an error."""
    t_k = t_ns[idx]
    g_k = group[idx]
    prev_max = np.full(len(t_k), np.iinfo(np.int64).min)
    for g in np.unique(g_k):
        sel = np.flatnonzero(g_k == g)
        run_max = np.maximum.accumulate(t_k[sel])
        prev_max[sel[1:]] = run_max[:-1]
    dup = t_k == prev_max
    back = t_k < prev_max
    if back.sum() > max(_MAX_BACK_FRACTION * len(t_k), 2):
        first = int(np.argmax(back))
        raise InputError(
            f"{int(back.sum())} of {len(t_k)} stamps go back in time (not monotonic)",
            path=path,
            where=f"line {lines[idx[first]]}, column {time_column!r}",
            hint="sort the log by time, or check the time column and its unit",
        )
    if dup.any():
        report.drop("duplicate stamp", lines[idx[dup]])
    if back.any():
        report.drop("stamp earlier than the previous sample", lines[idx[back]])
    return idx[~dup & ~back]


def _cuts(t_k: np.ndarray, g_k: np.ndarray, gap_s: float | None) -> tuple[np.ndarray, int, int]:
    """Segment bounds of increasing stamps ``t_k`` (ns): at every change of the trajectory id
    ``g_k`` and at forward steps over ``gap_s`` (None: max(1 s, 50 median steps)).

    Returns:
        ``(bounds [S + 1], gap_ns, number of time gaps)``.
    """
    steps = np.diff(t_k)
    med = float(np.median(steps)) if len(steps) else 0.0
    gap_ns = int((gap_s if gap_s is not None else max(1.0, 50 * med * 1e-9)) * 1e9)
    named = np.diff(g_k) != 0
    cuts = np.flatnonzero((steps > gap_ns) | named) + 1
    return np.concatenate([[0], cuts, [len(t_k)]]), gap_ns, int((steps > gap_ns).sum())


def _group_ids(raw: RawLog, column: str | None) -> np.ndarray:
    """[N] int: the run number of each row's segment value (0 everywhere without a column)."""
    n = len(raw.lines)
    if column is None:
        return np.zeros(n, dtype=np.int64)
    vals = np.char.strip(np.asarray(raw.data[column]).astype(str))
    change = np.concatenate([[False], vals[1:] != vals[:-1]]) if n else np.zeros(0, bool)
    return np.cumsum(change).astype(np.int64)


def _group_name(raw: RawLog, column: str | None, row: int) -> str | None:
    """The segment value of a row (None without a segment column)."""
    if column is None:
        return None
    v = str(raw.data[column][row]).strip()
    if v.endswith(".0") and v[:-2].lstrip("-").isdigit():  # 3.0 from a float column
        v = v[:-2]
    return v or "unnamed"

"""Held (stale) samples (T014): values that repeat while the stamps advance and the signal moves.

A sample *repeats* when every value column equals the previous sample's exactly. A block of
equal values (its first, *fresh*, sample and the repeats after it) is *held* when the signal
moved into it and moves out of it: for some column ``c``, with ``v`` the value before the
block, ``f`` the block's value and ``w`` the first value after it,

* ``w_c - f_c`` has the sign of ``f_c - v_c`` (the motion continues in the same direction), and
* the mean speed across the block, ``|w_c - f_c| / (t_w - t_f)``, is at least
  :data:`CATCH_UP` times the speed of the step into it, ``|f_c - v_c| / (t_f - t_v)``.

A publisher that re-sends its last value while the robot moves lets the signal run ahead, so
the value after the block catches up at about the speed before it. A robot at rest gives
exact repeats too (quantised encoders), but a rest ends at a small fraction of the speed it
started with (one step over the whole rest), and sensor noise flickers back and forth, so
neither counts. Blocks at the ends of a series (no value before or after) are not counted.

Only the value columns of measured streams are compared: joint positions (``joint_states``),
poses (``ee_poses`` per link, ``object_poses`` per object) and wrenches (per frame).
Commanded ``actions`` may legitimately hold a value and are left out.

The scan is streamed batch by batch; an open block is carried over as three rows.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ..findings import Finding
from ._common import MS
from .context import ENTITY_COLUMNS, CheckContext, InputReported
from .registry import Check, check
from .streaming import batches

__all__ = ["CATCH_UP", "HeldScan", "held_blocks", "held_mask", "value_columns"]

#: a block is held when the signal leaves it at >= this fraction of the speed it entered with
CATCH_UP = 0.6

_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")
_WRENCH = ("fx", "fy", "fz", "tx", "ty", "tz")


def value_columns(kind: str, names: list[str]) -> tuple[str, ...]:
    """The value columns compared for ``kind`` among a table's column ``names`` (empty: none)."""
    if kind == "joint_states":
        return tuple(n for n in names if n.startswith("position."))
    if kind in ("ee_poses", "object_poses"):
        return _POSE if set(_POSE) <= set(names) else ()
    if kind == "wrenches":
        return _WRENCH if set(_WRENCH) <= set(names) else ()
    return ()


def held_blocks(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blocks of equal values of one series and whether each is held.

    Args:
        t: [N] int64 stamps, ns, increasing.
        v: [N, C] values.

    Returns:
        ``(first, last, held)``: [B] index of each block's fresh sample, [B] index of its last
        repeat, [B] bool held flag, for every block with at least one repeat. Blocks touching
        either end of the series are returned with ``held`` False.
    """
    n = t.size
    if n < 2:
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0, bool)
    rep = np.all(v[1:] == v[:-1], axis=1) & (np.diff(t) > 0)  # rep[k]: sample k+1 repeats k
    edges = np.diff(np.concatenate(([0], rep.astype(np.int8), [0])))
    first = np.flatnonzero(edges == 1)  # fresh sample of each block
    last = np.flatnonzero(edges == -1)  # last repeat of each block
    held = np.zeros(first.size, bool)
    # the value before a block was measured at the fresh sample of its own block
    prev_last = np.concatenate([[-2], last[:-1]])
    prev = np.where(prev_last == first - 1, np.concatenate([[0], first[:-1]]), first - 1)
    inner = (first >= 1) & (last <= n - 2)
    if inner.any():
        f, e, b = first[inner], last[inner], prev[inner]
        before = v[f] - v[f - 1]  # [b, C]
        after = v[e + 1] - v[e]
        dt_in = (t[f] - t[b]).astype(np.float64)[:, None]
        dt_out = (t[e + 1] - t[f]).astype(np.float64)[:, None]
        with np.errstate(invalid="ignore"):  # non-finite values (I009) compare False
            same_way = before * after > 0
            fast = np.abs(after) / dt_out >= CATCH_UP * np.abs(before) / dt_in
        held[inner] = np.any(same_way & fast, axis=1)
    return first, last, held


def held_mask(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    """[N] bool: samples that repeat a held value (see :func:`held_blocks`)."""
    first, last, held = held_blocks(t, v)
    mask = np.zeros(t.size, bool)
    for f, e in zip(first[held], last[held], strict=True):
        mask[f + 1 : e + 1] = True
    return mask


@dataclass
class HeldScan:
    """Held-sample statistics of one series, fed batch by batch in table order.

    Attributes:
        n: samples scanned.
        held: held repeats.
        longest: most consecutive held repeats.
        longest_age_ns: how long the longest held value stood (its last repeat minus its
            fresh sample), ns.
        longest_at: (stamp, row) of the fresh sample of the longest held block.
    """

    n: int = 0
    held: int = 0
    longest: int = 0
    longest_age_ns: int = 0
    longest_at: tuple[int, int] = (0, 0)
    _t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    _v: np.ndarray | None = None
    _rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    _fresh: int = -1  # index, in the carried rows, of the open block's fresh sample
    _skipped: int = 0  # repeats of the open block left out of the carried rows

    def absorb(self, t: np.ndarray, v: np.ndarray, rows: np.ndarray) -> None:
        """Scan the next samples: [B] int64 stamps, [B, C] values, [B] table rows."""
        if t.size == 0:
            return
        self.n += t.size
        if self._v is not None:
            t = np.concatenate([self._t, t])
            v = np.concatenate([self._v, v])
            rows = np.concatenate([self._rows, rows])
        first, last, held = held_blocks(t, v)
        extra = np.where(first == self._fresh, self._skipped, 0)
        closed = last < t.size - 1  # a block reaching the end may still grow
        sel = held & closed
        for f, e, k in zip(first[sel], last[sel], extra[sel], strict=True):
            self._count(int(e - f + k), int(t[e] - t[f]), int(t[f]), int(rows[f]))
        open_block = bool(first.size) and not closed[-1]
        f = int(first[-1]) if open_block else t.size - 1
        # carry: the fresh sample of the block before f, the sample before f, f, the last row
        before = f - 1
        k = np.searchsorted(last, before)
        fresh_before = int(first[k]) if k < last.size and last[k] == before else before
        keep = np.unique([i for i in (fresh_before, before, f, t.size - 1) if i >= 0])
        if open_block:
            self._fresh = int(np.searchsorted(keep, f))
            self._skipped = int(extra[-1]) + (t.size - 1 - f) - 1
        else:
            self._fresh, self._skipped = -1, 0
        self._t, self._v, self._rows = t[keep], v[keep], rows[keep]

    def _count(self, repeats: int, age_ns: int, t_f: int, row_f: int) -> None:
        self.held += repeats
        if repeats > self.longest:
            self.longest, self.longest_age_ns, self.longest_at = repeats, age_ns, (t_f, row_f)

    @property
    def share(self) -> float:
        """Held repeats over samples."""
        return self.held / self.n if self.n else 0.0


def _keys(col: pa.Array) -> np.ndarray:
    return pc.fill_null(pc.cast(col, pa.string()), "<null>").to_numpy(zero_copy_only=False)


def _scan(ctx: CheckContext, rel: str, kind: str) -> dict[str | None, HeldScan]:
    names = ctx.footer(rel).schema.to_arrow_schema().names
    cols = value_columns(kind, names)
    ent = ENTITY_COLUMNS.get(kind)
    if not cols or "t_ns" not in names or (ent is not None and ent not in names):
        return {}
    read = ("t_ns", *cols) if ent is None else ("t_ns", ent, *cols)
    scans: dict[str | None, HeldScan] = {}
    offset = 0
    for b in batches(ctx, rel, read):
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        first_val = 1 if ent is None else 2
        v = np.stack(
            [b.column(i).to_numpy(zero_copy_only=False) for i in range(first_val, b.num_columns)],
            axis=1,
        ).astype(np.float64, copy=False)
        rows = np.arange(offset, offset + t.size)
        offset += t.size
        if ent is None:
            scans.setdefault(None, HeldScan()).absorb(t, v, rows)
            continue
        keys = _keys(b.column(1))
        for key in dict.fromkeys(keys.tolist()):
            sel = keys == key
            scans.setdefault(str(key), HeldScan()).absorb(t[sel], v[sel], rows[sel])
    return scans


def _ordered(ctx: CheckContext, rel: str) -> bool:
    """Whether the table's stamps never decrease (T001 reports the others)."""
    last = None
    for b in batches(ctx, rel, ("t_ns",)):
        t = b.column(0).to_numpy(zero_copy_only=False)
        if t.size == 0:
            continue
        if (last is not None and t[0] < last) or np.any(np.diff(t) < 0):
            return False
        last = t[-1]
    return True


def _held_scans(ctx: CheckContext) -> Iterator[tuple[object, str, str, str, str | None, HeldScan]]:
    kinds = ("joint_states", "ee_poses", "object_poses", "wrenches")
    for ep, name, st in ctx.streams(kinds):
        rel = st.get("path")
        if not isinstance(rel, str):
            continue
        kind = str(st.get("kind"))
        try:
            if not _ordered(ctx, rel):
                continue
            scans = _scan(ctx, rel, kind)
        except InputReported:
            continue
        for entity, scan in scans.items():
            yield ep, name, rel, kind, entity, scan


@check(
    "T014",
    group="time",
    severity="warning",
    title="no held (stale) samples while the signal moves",
    quantity="share of samples that repeat a held value",
    unit="ratio",
    budget="time.held_share",
    hint="the publisher re-sent its last value (a slower source resampled, or a stalled driver); "
    "drop the repeats or record the source at its own rate and stamps",
)
def _held(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.held_share")
    sync = ctx.budget("time.sync_ms")
    for ep, name, rel, kind, entity, scan in _held_scans(ctx):
        if scan.n == 0 or scan.share <= budget:
            continue
        age_ms = scan.longest_age_ns * MS
        severity = "error" if age_ms > sync else "warning"
        t_f, row = scan.longest_at
        ent = "" if entity is None else f" ({entity})"
        loc: dict[str, object] = {"file": rel, "episode": ep.id, "stream": name}
        if entity is not None:
            loc["link" if kind == "ee_poses" else "object"] = entity
        yield chk.finding(
            f"{scan.held} of {scan.n} samples{ent} ({100 * scan.share:.3g} %) repeat a held value "
            f"while the signal moves; longest run {scan.longest} samples, a value held for "
            f"{age_ms:.4g} ms ({'over' if severity == 'error' else 'within'} time.sync_ms "
            f"{sync:g} ms)",
            value=scan.share,
            budget=budget,
            severity=severity,
            t_ns=t_f,
            where=f"row {row}",
            **loc,
        )

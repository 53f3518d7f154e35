"""Cut long episodes into whole trajectories for the physics loop.

A recording of several pushes with hand resets between them is one episode on disk; the physics
loop needs one trajectory per push (to fit, and to hold trajectories out). :func:`find_cuts`
finds the boundaries in the measured object poses alone (never in the model):

* **gap** - the object stream stops for longer than ``max(gap_s, 5 median steps)``
  (tracking lost while a hand resets the object);
* **teleport** - one step moves the object further than its velocity allows: more than
  ``teleport_m`` and more than 5x both neighbouring steps (or turns it by more than
  ``teleport_rad`` and 5x its neighbours), i.e. a hand reset seen by the tracker;
* **rest** - rest-motion-rest segmentation: two motions of the object separated by at least
  ``min_rest_s`` of rest are cut at the middle of the rest.

A cut at a gap or teleport lies half-way between the two samples; the end-effector stream is
cut at the same instants, so each trajectory keeps the pusher's motion up to its boundaries.

``--split auto|none|at=T1,T2,...`` (seconds from the episode start) chooses the cut on the
physics commands: :func:`split_option` sets it for every :func:`~robogs.physics.recording.
load_recording` inside its ``with`` block and collects the cuts made, for the table
:func:`cut_table` prints.
"""

from __future__ import annotations

import argparse
import contextlib
import contextvars
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robogs.format.errors import InputError

__all__ = [
    "Cut",
    "Piece",
    "SplitLog",
    "parse_split",
    "find_cuts",
    "split_trajectory",
    "split_recording_trajectory",
    "split_option",
    "current_split",
    "add_split_argument",
    "cut_table",
]


@dataclass(frozen=True)
class Cut:
    """One boundary: cut at ``t_ns`` (int64 ns, object-stream clock) for ``why``."""

    t_ns: int
    why: str  # "gap", "teleport", "rest", "at"
    detail: str = ""


@dataclass(frozen=True)
class Piece:
    """One trajectory cut from an episode: ``[start_s, end_s]`` s from the episode start."""

    trajectory: str
    episode: str
    start_s: float
    end_s: float
    why_start: str
    why_end: str


@dataclass
class SplitLog:
    """The split mode in force, every piece cut and recording loaded while it was in force,
    and ``notes`` other modules keep for the same command (e.g. :mod:`~robogs.physics.sanity`)."""

    mode: str = "auto"
    at_s: tuple[float, ...] = ()
    pieces: list[Piece] = field(default_factory=list)
    recordings: list[Any] = field(default_factory=list)
    notes: dict[str, Any] = field(default_factory=dict)


_CURRENT: contextvars.ContextVar[SplitLog | None] = contextvars.ContextVar(
    "robogs_physics_split", default=None
)


def parse_split(text: str) -> tuple[str, tuple[float, ...]]:
    """``auto`` | ``none`` | ``at=T1,T2,...`` (s from the episode start) -> (mode, times)."""
    s = str(text).strip()
    if s in ("auto", "none"):
        return s, ()
    if s.startswith("at="):
        try:
            ts = tuple(sorted(float(v) for v in s[3:].split(",") if v.strip()))
        except ValueError:
            ts = ()
        if ts and all(np.isfinite(ts)) and ts[0] > 0:
            return "at", ts
    raise InputError(
        f"bad --split value {text!r}",
        hint="use auto, none, or at=T1,T2,... (positive seconds from the episode start)",
    )


def current_split() -> SplitLog | None:
    """The :class:`SplitLog` of the innermost :func:`split_option` block (None outside)."""
    return _CURRENT.get()


@contextlib.contextmanager
def split_option(text: str = "auto") -> Iterator[SplitLog]:
    """Use split mode ``text`` for every dataset loaded inside the block; yields the log."""
    mode, at = parse_split(text)
    log = SplitLog(mode, at)
    token = _CURRENT.set(log)
    try:
        yield log
    finally:
        _CURRENT.reset(token)


def add_split_argument(p: argparse.ArgumentParser) -> None:
    """The ``--split`` option of the physics commands."""
    p.add_argument(
        "--split",
        default="auto",
        metavar="auto|none|at=T1,...",
        help="cut each episode into trajectories: auto (stream gaps, object teleports, "
        "rest-motion-rest; default), none (one trajectory per episode), or at=T1,T2,... "
        "(seconds from the episode start)",
    )


def _noise_sigma(pos: np.ndarray) -> float:
    """Position noise [m] from the MAD of second differences (robust to motion and jumps)."""
    if len(pos) < 4:
        return 0.0
    d2 = np.diff(pos, n=2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return float(np.max(1.4826 * mad / np.sqrt(6.0)))


def _yaw(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = (quat[:, i] for i in range(4))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _motions(t: np.ndarray, pos: np.ndarray, min_motion_m: float) -> list[tuple[int, int]]:
    """Index runs [a, b) where the object moves: smoothed planar speed (7-point line fit) above
    ``max(0.02 m/s, 5 sigma_v)``, lasting 5 samples or moving more than ``min_motion_m``."""
    from robogs.physics.phases import local_velocity, runs

    if len(t) < 8:
        return []
    sig = _noise_sigma(pos)
    dt_med = float(np.median(np.diff(t)))
    v = local_velocity(t, pos[:, :2])
    sig_v = sig / (dt_med * np.sqrt(28.0))  # slope std of a 7-point fit
    moving = np.hypot(v[:, 0], v[:, 1]) > max(0.02, 5.0 * sig_v)
    return [
        (p, q)
        for p, q in runs(moving)
        if q - p >= 5 or np.linalg.norm(pos[q - 1, :2] - pos[p, :2]) > max(min_motion_m, 5 * sig)
    ]


def find_cuts(
    t_ns: np.ndarray,
    pos: np.ndarray,
    quat: np.ndarray | None = None,
    *,
    gap_s: float = 0.25,
    teleport_m: float = 0.02,
    teleport_rad: float = 0.35,
    min_rest_s: float = 0.5,
    min_motion_m: float = 0.005,
) -> list[Cut]:
    """Boundaries of the trajectories in one episode's object poses (see the module doc).

    Args:
        t_ns: stamps [N] int64 ns, increasing. pos: T_world_object translation [N, 3] m.
        quat: T_world_object rotation [N, 4] (w, x, y, z), or None (no yaw teleports).
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    pos = np.asarray(pos, dtype=float)
    n = len(t_ns)
    if n < 4:
        return []
    dt = np.diff(t_ns) * 1e-9
    dt_med = float(np.median(dt))
    cuts: dict[int, Cut] = {}  # keyed by the index of the first sample after the cut
    for i in np.flatnonzero(dt > max(gap_s, 5.0 * dt_med)):
        mid = int(t_ns[i] + (t_ns[i + 1] - t_ns[i]) // 2)
        cuts[int(i) + 1] = Cut(mid, "gap", f"no object pose for {dt[i]:.2f} s")
    step = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    jumps = [(step, teleport_m, "m")]
    if quat is not None:
        yaw = np.abs(np.angle(np.exp(1j * np.diff(_yaw(np.asarray(quat, float))))))
        jumps.append((yaw, teleport_rad, "rad"))
    for d, floor, unit in jumps:
        prev = np.concatenate([[0.0], d[:-1]])
        nxt = np.concatenate([d[1:], [0.0]])
        for i in np.flatnonzero((d > floor) & (d > 5.0 * np.maximum(prev, nxt))):
            if int(i) + 1 not in cuts:
                mid = int(t_ns[i] + (t_ns[i + 1] - t_ns[i]) // 2)
                what = f"{1e3 * d[i]:.0f} mm" if unit == "m" else f"{np.degrees(d[i]):.0f} deg"
                cuts[int(i) + 1] = Cut(mid, "teleport", f"jump of {what} in one step")
    # rest-motion-rest inside each piece between the cuts above
    bounds = [0, *sorted(cuts), n]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        t = (t_ns[a:b] - t_ns[a]) * 1e-9
        motions = _motions(t, pos[a:b], min_motion_m)
        for (_, q), (p2, _) in zip(motions[:-1], motions[1:], strict=True):
            if t[p2] - t[q - 1] >= min_rest_s:
                k = a + (q - 1 + p2 + 1) // 2
                tm = int(t_ns[a + q - 1] + (t_ns[a + p2] - t_ns[a + q - 1]) // 2)
                cuts.setdefault(k, Cut(tm, "rest", f"object at rest for {t[p2] - t[q - 1]:.2f} s"))
    return [cuts[k] for k in sorted(cuts)]


def split_trajectory(tr: Any, cuts: list[Cut], pad_s: float | None = 0.6) -> list[Any]:
    """Cut trajectory ``tr`` (a :class:`~robogs.physics.recording.Trajectory`) at ``cuts``.

    Object and end-effector samples are cut at the same instants. On a side that was cut, a
    piece keeps at most ``pad_s`` of rest beyond its object's motion (None: all of it), so a
    long wait between pushes is not simulated. A piece with fewer than 4 object samples or 2
    end-effector samples is dropped (too short to compare). Names: ``<episode>#<k>`` (k from 0)
    when there is more than one piece.
    """
    from dataclasses import replace

    edges = [int(c.t_ns) for c in cuts]
    lo = [np.iinfo(np.int64).min, *edges]
    hi = [*edges, np.iinfo(np.int64).max]
    out = []
    for k, (a, b) in enumerate(zip(lo, hi, strict=True)):
        mo = (tr.t_ns >= a) & (tr.t_ns < b)
        if pad_s is not None and mo.sum() >= 8:
            t = tr.t_ns[mo]
            mv = _motions((t - t[0]) * 1e-9, tr.object_pos[mo], 0.005)
            pad = int(pad_s * 1e9)
            if mv and k > 0:
                a = max(a, int(t[mv[0][0]]) - pad)
            if mv and k < len(edges):
                b = min(b, int(t[mv[-1][1] - 1]) + pad + 1)
            mo = (tr.t_ns >= a) & (tr.t_ns < b)
        me = (tr.ee_t_ns >= a) & (tr.ee_t_ns < b)
        if mo.sum() < 4 or me.sum() < 2:
            continue
        wt, wf = getattr(tr, "wrench_t_ns", None), getattr(tr, "wrench_force", None)
        extra = {}
        if wt is not None and wf is not None:
            mw = (wt >= a) & (wt < b)
            extra = {"wrench_t_ns": wt[mw], "wrench_force": wf[mw]}
        if getattr(tr, "pusher_dofs", None) is not None:  # the robot pusher's, at ee_t_ns
            extra["pusher_dofs"] = tr.pusher_dofs[me]
        out.append(
            replace(
                tr,
                name=tr.name if not cuts else f"{tr.name}#{k}",
                t_ns=tr.t_ns[mo],
                object_pos=tr.object_pos[mo],
                object_quat=tr.object_quat[mo],
                ee_t_ns=tr.ee_t_ns[me],
                ee_pos=tr.ee_pos[me],
                ee_quat=tr.ee_quat[me],
                grasp=tr.grasp[me],
                **extra,
            )
        )
    return out


def split_recording_trajectory(
    tr: Any, mode: str = "auto", at_s: tuple[float, ...] = (), t_start_ns: int | None = None
) -> tuple[list[Any], list[Piece]]:
    """Split one episode's trajectory by ``mode`` (``auto``, ``none``, ``at``); return the
    trajectories and their :class:`Piece` rows (times from ``t_start_ns``, default the first
    stamp of either stream)."""
    t0 = int(t_start_ns if t_start_ns is not None else min(tr.t_ns[0], tr.ee_t_ns[0]))
    if mode == "none":
        cuts: list[Cut] = []
    elif mode == "at":
        cuts = [Cut(t0 + int(round(s * 1e9)), "at", "given with --split at=") for s in at_s]
    else:
        cuts = find_cuts(tr.t_ns, tr.object_pos, tr.object_quat)
    pieces = split_trajectory(tr, cuts)
    rows = []
    by_t = {c.t_ns: c for c in cuts}
    edges = sorted(by_t)
    for p in pieces:
        a, b = int(p.t_ns[0]), int(p.t_ns[-1])
        before = [e for e in edges if e <= a]
        after = [e for e in edges if e > b]
        rows.append(
            Piece(
                trajectory=p.name,
                episode=tr.name,
                start_s=(a - t0) * 1e-9,
                end_s=(b - t0) * 1e-9,
                why_start=by_t[before[-1]].why if before else "episode start",
                why_end=by_t[after[0]].why if after else "episode end",
            )
        )
    return pieces, rows


def cut_table(pieces: list[Piece]) -> str:
    """Plain-text table: trajectory, start/end s (from the episode start), why cut."""
    if not pieces:
        return ""
    w = max(10, *(len(p.trajectory) for p in pieces))
    lines = [f"{'trajectory':<{w}s}  {'start s':>8s}  {'end s':>8s}  cut at start / end"]
    for p in pieces:
        lines.append(
            f"{p.trajectory:<{w}s}  {p.start_s:8.2f}  {p.end_s:8.2f}  {p.why_start} / {p.why_end}"
        )
    return "\n".join(lines)

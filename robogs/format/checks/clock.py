"""A periodic stream's clock, robust to jitter: dropped samples from phase steps, stamp errors
from a local fit.

With stamps ``t_j = t_0 + n_j P + e_j`` (``n_j`` the slot of sample ``j``, ``e_j`` the stamp
error), a long interval is either a dropped sample (``n`` skips a slot) or jitter (``e_j`` large,
``e_{j+1}`` not). Thresholding intervals at ``1.5 P`` cannot tell them apart once the jitter is a
sizeable fraction of the period: with an interval rms of 25 % of ``P`` about 2 % of regular
intervals exceed ``1.5 P``. A drop, though, shifts the phase ``rho_j = t_j - j P`` of *every
later sample* by ``P``, while jitter moves one stamp. So each candidate interval (longer than
``1.5 P``; candidates closer than ``h`` samples form one cluster) counts
``round((median(rho after) - median(rho before)) / P)`` lost samples, the medians taken over
the ``h`` samples on each side. A cluster whose longest interval exceeds ``gap_factor``
periods and that lost more than ``gap_factor - 1`` samples is a gap; one that lost none is a
late stamp, whatever its length. This is the step detection of a running median, which keeps
edges and ignores outliers (Tukey 1977; Pratt, *Digital Image Processing*, median filters).

The nominal period is then the total time over the total slots, ``P = sum(d) / (intervals +
lost)`` over the intervals that are not gaps (gaps split the series into segments), which telescopes the jitter away. The stamp error
of a sample is its phase minus the median phase of the ``2h + 1`` samples around it (same
segment between gaps), so slow clock drift is not counted as jitter.

Functions here work on arrays of stamps; :mod:`.timing` feeds them in overlapping chunks.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = [
    "DROP_FACTOR",
    "HALF_WINDOW",
    "CONTEXT",
    "Drop",
    "chunks_with_context",
    "find_drops",
    "stamp_errors",
]

#: intervals longer than this many periods are drop candidates
DROP_FACTOR = 1.5
#: samples on each side of a phase step or a stamp (h)
HALF_WINDOW = 10
#: samples of context carried around each chunk (a cluster spans at most 2h samples)
CONTEXT = 4 * HALF_WINDOW


Drop = tuple[int, int]  # (global index of the sample after the longest interval, samples lost)


def chunks_with_context(
    chunks: Iterable[tuple[np.ndarray, ...]], context: int = CONTEXT
) -> Iterator[tuple[int, tuple[np.ndarray, ...], int, int]]:
    """Re-cut chunks of parallel arrays (stamps, rows...) so that each comes with ``context``
    samples around it.

    Yields:
        ``(g0, arrays, lo, hi)``: ``arrays`` hold the samples of global indices ``g0 ..
        g0 + len``; ``[lo:hi]`` is the core. Every sample is in exactly one core, cores come in
        order, and each core has ``context`` samples on both sides unless the series ends.
    """
    buf: tuple[np.ndarray, ...] | None = None
    start = 0  # global index of buf[0]
    done = 0  # global index of the first sample not yet in a core
    for c in chunks:
        if c[0].size == 0:
            continue
        buf = (
            c if buf is None else tuple(np.concatenate([a, b]) for a, b in zip(buf, c, strict=True))
        )
        emit = start + buf[0].size - context
        if emit > done:
            yield start, buf, done - start, emit - start
            done = emit
            cut = max(0, done - context - start)
            buf, start = tuple(a[cut:] for a in buf), start + cut
    if buf is not None and start + buf[0].size > done:
        yield start, buf, done - start, buf[0].size


def find_drops(
    t: np.ndarray, start: int, hi: int, p0: float, gap_factor: float, h: int = HALF_WINDOW
) -> tuple[list[tuple[int, int, bool]], int]:
    """Lost samples at the long intervals whose cluster starts in ``t[start:hi]``.

    Args:
        t: [n] int64 stamps of a chunk (strictly increasing), with context around the core.
        start, hi: where clusters may start (the core, less what earlier chunks took).
        p0: a first estimate of the period (ns), e.g. the median interval.
        gap_factor: a cluster whose longest interval exceeds ``gap_factor * p0`` and that lost
            more than ``gap_factor - 1`` samples is a gap; one that lost none is jitter.
        h: samples on each side of a cluster whose median phases are compared.

    Returns:
        ``([(i, lost, gap)], end)``: per cluster that lost samples, the chunk index of the
        sample after its longest interval, the samples lost and whether it is a gap; ``end``
        is the chunk index after the last cluster examined (a cluster that starts in the core
        may reach into the context after it).
    """
    d = np.diff(t).astype(np.float64)  # d[k-1]: interval before sample k
    cand = np.flatnonzero(d > DROP_FACTOR * p0) + 1  # sample after each long interval
    cand = cand[cand >= max(start, 1)]
    out: list[tuple[int, int, bool]] = []
    end = start
    i = 0
    while i < cand.size and cand[i] < hi:
        a = b = int(cand[i])
        j = i + 1
        while j < cand.size and cand[j] - b <= h and cand[j] - a <= 2 * h:
            b = int(cand[j])
            j += 1
        before = np.arange(max(a - h, 0), a)
        after = np.arange(b, min(b + h, t.size))
        if before.size and after.size:
            ref = t[a - 1]
            rho_b = (t[before] - ref).astype(np.float64) - (before - (a - 1)) * p0
            rho_a = (t[after] - ref).astype(np.float64) - (after - (a - 1)) * p0
            lost = int(np.rint((np.median(rho_a) - np.median(rho_b)) / p0))
        else:  # no samples on one side: fall back to the interval lengths
            lost = int(np.sum(np.rint(d[cand[i:j] - 1] / p0) - 1))
        if lost > 0:
            k = int(cand[i:j][int(np.argmax(d[cand[i:j] - 1]))])
            gap = lost + 1 > gap_factor and d[k - 1] > gap_factor * p0
            out.append((k, lost, bool(gap)))
        end = b + 1
        i = j
    return out, end


def stamp_errors(
    t: np.ndarray,
    slots: np.ndarray,
    lo: int,
    hi: int,
    period: float,
    breaks: np.ndarray,
    h: int = HALF_WINDOW,
) -> np.ndarray:
    """[hi - lo] stamp errors (ns) of the core samples: phase minus the local median phase.

    Args:
        t: [n] int64 stamps of a chunk.
        slots: [n] int64 slot of each sample (its index plus the samples lost before it).
        lo, hi: the core.
        period: the nominal period, ns.
        breaks: [n] bool, True where a sample starts a new segment (after a gap).
        h: half window, samples.
    """
    rho = (t - t[lo]).astype(np.float64) - (slots - slots[lo]).astype(np.float64) * period
    seg = np.cumsum(breaks)
    pad = np.full(h, np.nan)
    rp = np.concatenate([pad, rho, pad])
    sp = np.concatenate([np.full(h, -1), seg, np.full(h, -1)])
    win = sliding_window_view(rp, 2 * h + 1)[lo:hi]  # windows centred on core samples
    wseg = sliding_window_view(sp, 2 * h + 1)[lo:hi]
    same = wseg == seg[lo:hi, None]
    full = same.all(axis=1)
    med = np.empty(hi - lo)
    if full.any():
        med[full] = np.median(win[full], axis=1)
    if (~full).any():
        part = np.where(same[~full], win[~full], np.nan)
        med[~full] = np.nanmedian(part, axis=1)
    return rho[lo:hi] - med

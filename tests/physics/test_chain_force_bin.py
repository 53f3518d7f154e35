"""The force bin of a chain of contacts, from the data (issue 16).

With other tracked objects (one box pushed into another) the pusher force is compared over bins
of one period of the ring the measured force shows during contact
(:func:`robogs.physics.prepare.chain_force_bin`, :func:`~robogs.physics.prepare.ring_period`:
the first zero crossing of the autocorrelation of its increments is a quarter period), three
periods per bin clamped to [20, 250] ms, else :data:`~robogs.physics.prepare.CHAIN_FORCE_BIN_S`
with the reason. Oracles:
damped sinusoids of known frequency with noise and force steps, built here (independent of the
generator), must give their period within 10 %; noise and steps alone, no ring; and the two-box
generator's force (a rigid chain: it does not ring) falls back, while the same recording with a
25 Hz ring added to its sensor gets 120 ms bins.
"""

from __future__ import annotations

import logging
import re

import numpy as np
import pytest

from robogs.physics.prepare import (
    CHAIN_FORCE_BIN_S,
    RING_BIN_PERIODS,
    RING_BIN_RANGE_S,
    chain_force_bin,
    prepare,
    ring_period,
)
from robogs.synth.scenarios.two_objects import make_two_objects

H = 0.004  # 250 Hz, the two-box generator's sensor rate
NOISE = 0.03  # N per sample


def _pushes(
    freq: float,
    rng: np.random.Generator,
    amp: float = 0.4,
    periods: float = 2.0,
    dur: float = 0.4,
    h: float = H,
) -> list[np.ndarray]:
    """Three contacts of ``dur`` s: 1.5 N, a 1.3 N step at 30 ms (an impact) that starts a ring
    of ``freq`` Hz, amplitude ``amp`` N, decaying by e over ``periods`` periods, random phase,
    white noise ``NOISE``, sampled every ``h`` s."""
    out = []
    for _ in range(3):
        t = np.arange(0.0, dur, h)
        s = np.clip(t - 0.03, 0.0, None)
        on = t >= 0.03
        ring = amp * np.exp(-s * freq / periods) * np.sin(2 * np.pi * freq * s + rng.uniform(0, 6))
        out.append(1.5 + 1.3 * on + ring * on + rng.normal(0.0, NOISE, len(t)))
    return out


@pytest.mark.parametrize("freq", [12.0, 25.0, 40.0])
@pytest.mark.parametrize("periods", [2.0, 4.0])
def test_ring_period_of_damped_sinusoids(freq, periods):
    """The period of a damped ring within 10 % (measured within 3 % over 10 draws)."""
    rng = np.random.default_rng(int(freq * 10 + periods))
    period, why = ring_period(_pushes(freq, rng, periods=periods), H, NOISE)
    print(f"{freq} Hz, decay {periods} periods: {period}, {why}")
    assert period == pytest.approx(1.0 / freq, rel=0.10)
    assert "ring of" in why
    bin_s, why = chain_force_bin(_pushes(freq, rng, periods=periods), H, NOISE)
    want = min(RING_BIN_PERIODS / freq, RING_BIN_RANGE_S[1])
    assert bin_s == pytest.approx(want, rel=0.10) and "ring periods per bin" in why


def test_no_ring_falls_back_with_its_reason(caplog):
    """Noise and steps alone (no ring), and too few samples: the constant, the reason logged."""
    rng = np.random.default_rng(3)
    for segs in (_pushes(25.0, rng, amp=0.0), [np.zeros(10)]):
        with caplog.at_level(logging.INFO, logger="robogs.physics.prepare"):
            bin_s, why = chain_force_bin(segs, H, NOISE)
        assert bin_s == CHAIN_FORCE_BIN_S and "CHAIN_FORCE_BIN_S" in why
        assert any(why.split(": ", 1)[1] in r.getMessage() for r in caplog.records)
        assert ring_period(segs, H, NOISE)[0] is None


def test_bin_is_clamped():
    """A 200 Hz ring at 1 kHz (3 periods: 15 ms) bins at 20 ms, a 3 Hz one (1.5 s contacts) at
    250 ms; the clamp is said.
    (The increments whiten the force: a 3 Hz ring of 0.4 N moves 0.03 N per sample, under the
    noise's 0.042 N, and is not found; of 1 N it is, 315-335 ms in three draws.)"""
    lo, hi = RING_BIN_RANGE_S
    rng = np.random.default_rng(5)
    period, _ = ring_period(_pushes(200.0, rng, periods=4.0, h=1e-3), 1e-3, NOISE)
    assert period == pytest.approx(0.005, rel=0.15)  # 5.5 ms: 5.5 samples a period
    bin_s, why = chain_force_bin(_pushes(200.0, rng, periods=4.0, h=1e-3), 1e-3, NOISE)
    assert bin_s == lo and "clamped" in why
    bin_s, why = chain_force_bin(_pushes(3.0, rng, amp=1.0, periods=4.0, dur=1.5), H, NOISE)
    assert bin_s == hi and "clamped" in why


def test_two_box_recording_bins():
    """The generator's rigid chain does not ring: 100 ms bins and why; the same recording with
    a 25 Hz ring (0.3 N, decaying over 2 periods) added to its force sensor from the moment the
    pusher drives both boxes: bins of three periods, 120 ms."""
    rec = make_two_objects(seed=0, noise=True)
    note = prepare(rec).wrench_note
    assert "bins of 100 ms" in note and "CHAIN_FORCE_BIN_S" in note and "no ring" in note
    for tr in rec.trajectories:
        f = tr.wrench_force[:, :2] - np.median(tr.wrench_force[:50, :2], axis=0)
        k = int(np.argmax(np.linalg.norm(f, axis=1) > 2.2))  # both boxes pushed: 2.77 N
        s = (tr.wrench_t_ns[k:] - tr.wrench_t_ns[k]) * 1e-9
        ring = 0.3 * np.exp(-s * 25.0 / 2.0) * np.sin(2 * np.pi * 25.0 * s)
        u = f[k] / np.linalg.norm(f[k])
        tr.wrench_force = tr.wrench_force.copy()
        tr.wrench_force[k:, :2] += ring[:, None] * u
    note = prepare(rec).wrench_note
    print(note)
    ms = float(re.search(r"bins of (\d+) ms", note).group(1))
    assert ms == pytest.approx(120.0, rel=0.10) and "3 ring periods per bin: ring of" in note

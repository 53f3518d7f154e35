"""The tricube local-polynomial smoother of the drive, against closed forms and a brute force."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from robogs.physics.smoothing import local_polynomial


def _stamps(n: int = 400, rate: float = 500.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.arange(n) / rate + rng.uniform(-2e-4, 2e-4, n)  # jittered 500 Hz


def test_exact_for_quartics_value_and_slope() -> None:
    t = _stamps()
    c = np.array([0.1, -0.4, 2.0, -3.0, 1.5])
    x = np.polynomial.polynomial.polyval(t, c)[:, None]
    dx = np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyder(c))
    got = local_polynomial(t, x, 0.08)
    slope = local_polynomial(t, x, 0.06, deriv=1)
    assert np.max(np.abs(got[:, 0] - x[:, 0])) < 1e-10
    assert np.max(np.abs(slope[:, 0] - dx)) < 1e-8


def test_matches_brute_force_weighted_polyfit() -> None:
    t = _stamps(200)
    rng = np.random.default_rng(1)
    x = np.column_stack([np.sin(9 * t), np.cos(5 * t)]) + rng.normal(0, 1e-3, (200, 2))
    window, half = 0.05, 0.025
    got = local_polynomial(t, x, window, degree=3)
    got_v = local_polynomial(t, x, window, degree=3, deriv=1)
    for i in (0, 3, 57, 100, 199):
        sel = np.abs(t - t[i]) < half
        u = np.abs(t[sel] - t[i]) / half
        w = (1 - u**3) ** 3
        for d in range(2):
            # np.polyfit weights multiply the residuals: pass sqrt of the tricube weights
            p = np.polyfit(t[sel] - t[i], x[sel, d], 3, w=np.sqrt(w))
            assert abs(np.polyval(p, 0.0) - got[i, d]) < 1e-9
            assert abs(p[-2] - got_v[i, d]) < 1e-6


def test_passes_less_high_frequency_noise_than_a_savgol_window() -> None:
    """The motivation: white encoder noise above 60 Hz survives a quadratic Savitzky-Golay
    filter over 40 ms far more than the degree-4 tricube fit over 80 ms (side lobes)."""
    rng = np.random.default_rng(2)
    t = np.arange(20000) / 500.0
    noise = rng.normal(0.0, 1.0, (len(t), 1))
    f = np.fft.rfftfreq(len(t), 1 / 500.0)
    hi = f > 60.0

    def hf_power(y: np.ndarray) -> float:
        return float(np.sum(np.abs(np.fft.rfft(y[:, 0])) ** 2 * hi))

    ours = hf_power(local_polynomial(t, noise, 0.08))
    sg = hf_power(savgol_filter(noise, 21, 2, axis=0))
    assert ours < 0.1 * sg


def test_short_window_returns_input() -> None:
    t = _stamps(50)
    x = np.random.default_rng(3).normal(size=(50, 3))
    assert np.array_equal(local_polynomial(t, x, 0.002), x)

"""The Savitzky-Golay differentiator on uniform and non-uniform int64-ns stamps."""

from __future__ import annotations

import numpy as np
import pytest

from robogs.format.differentiate import savgol_derivative
from robogs.format.errors import InputError


def _cubic(t):
    y = 0.3 + 1.2 * t - 0.7 * t**2 + 0.25 * t**3
    return y, 1.2 - 1.4 * t + 0.75 * t**2, -1.4 + 1.5 * t


@pytest.mark.parametrize("uniform", [True, False])
def test_exact_on_cubics(uniform):
    rng = np.random.default_rng(0)
    step = 8_000_000
    t_ns = np.cumsum(
        np.full(400, step) if uniform else rng.integers(step // 2, 2 * step, 400)
    ).astype(np.int64)
    t = (t_ns - t_ns[0]) * 1e-9
    y, dy, ddy = _cubic(t)
    two = np.stack([y, 2 * y], axis=1)
    np.testing.assert_allclose(savgol_derivative(t_ns, y, order=1), dy, atol=1e-8)
    np.testing.assert_allclose(savgol_derivative(t_ns, y, order=2), ddy, atol=1e-6)
    np.testing.assert_allclose(savgol_derivative(t_ns, two, order=1)[:, 1], 2 * dy, atol=1e-8)


def test_uniform_and_local_fit_agree_on_noisy_sines():
    t_ns = (np.arange(1000) * 2_000_000).astype(np.int64)
    t = t_ns * 1e-9
    y = np.sin(3 * t) + np.random.default_rng(1).normal(0, 1e-4, t.shape)
    fast = savgol_derivative(t_ns, y, order=1)
    jittered = t_ns.copy()
    jittered[500] += 100_000  # 5 % of a step: the local polynomial path
    slow = savgol_derivative(jittered, y, order=1)
    np.testing.assert_allclose(fast[:450], slow[:450], atol=1e-9)
    np.testing.assert_allclose(fast[50:-50], 3 * np.cos(3 * t[50:-50]), atol=0.02)


def test_rejects_bad_input():
    with pytest.raises(InputError, match="too few"):
        savgol_derivative(np.arange(3, dtype=np.int64), np.zeros(3))
    with pytest.raises(InputError, match="strictly increasing"):
        savgol_derivative(np.array([0, 1, 1, 2, 3, 4], dtype=np.int64), np.zeros(6))

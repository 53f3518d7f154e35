"""The linearisation check on an effect that is flat up to a threshold in its parameter (issue
17, h40): a closed-form oracle for the restitution misses of design A.

The model (numpy, no engine): per trajectory ``t`` and sample ``x``, ``pred = beta x + l_t +
f(a)``, ``f(a) = S (a v_t x - x^2 / 2)`` where positive (its corner smoothed over ``w``), unit
noise: a ballistic arc whose height grows as ``a^2`` and whose length grows as ``a``, like a
rebound's with restitution ``a`` (zero and flat at ``a = 0``; a sample is reached only once ``a``
passes ``x / (2 v_t)``). Its change from ``a = 0`` is not along its tangent at the fit, so the
data's own ratio of gain to linear gain is 2.5-5.5 whatever the noise; the check should not
count that against it (it is the effect's own path, not capacity to fit noise).

``test_factor_near_one_on_an_effect_flat_up_to_a_threshold`` runs the diagnosis's check (h38:
one draw, the fitted change shrunk in data space, ``gate.null_draw_factor``) and is a strict
xfail: its factor scatters 1.6-3.5 between noise seeds, as design A's restitution does
(1.08-10.5). Three other checks passed it or traded it against false positives and were not
adopted (antithetic draws h40/h46, their choice by roughness h49, by a z cut h109;
bench/RESULTS.md, issue 17).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from robogs.physics import gate as G

T_N, K_N = 9, 40
_R = np.random.default_rng(0)
X = np.sort(_R.uniform(0.0, 1.0, (T_N, K_N)), axis=1)
XC = X - X.mean(axis=1, keepdims=True)
VT = np.linspace(0.5, 1.5, T_N)[:, None]  # each trajectory's launch speed
VALID = np.ones((T_N, K_N), bool)
ARC_S, ARC_W = 10.0, 0.02
GRID = np.linspace(0.0, 1.0, 401)
THR = 10.0
"""The toy's null threshold [sigma^2] (about a one-parameter family-wise tail)."""


def _arc(a: float) -> np.ndarray:
    u = (a * VT * X - X**2 / 2.0) / ARC_W
    return ARC_S * ARC_W * np.logaddexp(0.0, u)


def _profile(r: np.ndarray) -> np.ndarray:
    """Residual after fitting beta and every trajectory's offset (linear least squares)."""
    rc = r - r.mean(axis=1, keepdims=True)
    return rc - np.sum(rc * XC) / np.sum(XC * XC) * XC


def _fit(offset: np.ndarray, obs: np.ndarray):
    """chi^2 of the base and base + arc fits of ``r(theta) + offset`` (r = pred - obs; ``a`` by
    a dense grid refined by a bounded scalar search), the fitted ``a``, the base residual."""
    r_b = _profile(offset - obs)
    c_b = float(np.sum(r_b**2))

    def cost(a: float) -> float:
        return float(np.sum(_profile(_arc(a) + offset - obs) ** 2))

    c = np.array([cost(a) for a in GRID])
    j = int(np.argmin(c))
    h = GRID[1] - GRID[0]
    lo, hi = max(GRID[j] - h, GRID[0]), min(GRID[j] + h, GRID[-1])
    r = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    a = float(r.x) if r.fun < c[j] else float(GRID[j])
    return c_b, min(cost(a), c_b), a, r_b


def _linear(a: float) -> G.LinearCandidate:
    """The model linearised at ``a`` (1 % forward-difference column, as the engines')."""
    col = (_arc(a + 0.01) - _arc(a)) / 0.01
    return G.LinearCandidate("e", np.stack([X, col], -1), np.ones((T_N, K_N, 1)), 1)


def _case(seed: int, amp: float = 0.35) -> tuple[float, G.LinearisationCheck]:
    """(the data's own ratio, the diagnosis's check) for the arc planted at ``amp``."""
    obs = _arc(amp) + 0.3 * X + np.random.default_rng(seed).standard_normal(X.shape)
    c_b, c_c, a_hat, r_b = _fit(np.zeros_like(obs), obs)
    r_c = _profile(_arc(a_hat) - obs)
    data = G.linear_ratio(c_b - c_c, G.linear_gain(_linear(a_hat), r_b, VALID), 1)

    def fit(off: np.ndarray):
        cb, cc, a, rb = _fit(off, obs)
        return cb, cc, _linear(a), rb

    lam = G.draw_scale(c_b - c_c, THR)
    signs = G.check_signs(T_N, f"arc {seed}")
    return data, G.null_draw_factor(r_b, r_c, VALID, fit, signs, lam, data)


def test_the_arc_is_curved_along_its_path():
    """The oracle's premise: planted at ``a = 0.35`` its fit gains more than the threshold of 10
    sigma^2 (so the check shrinks the change, ``lambda`` 0.53-0.75) and 2.5x or more of what
    its linear model at the fit reproduces, on every noise seed (measured 2.7-5.5)."""
    for seed in range(6):
        data, chk = _case(seed)
        assert data >= 2.5, (seed, data)
        assert chk.scale < 1.0  # the gain exceeds the threshold: the change is shrunk


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="issue 17 (h40): the check still holds an effect's own curvature (h38's draw, its "
    "change shrunk in data space where the model cannot follow)",
)
def test_factor_near_one_on_an_effect_flat_up_to_a_threshold():
    """The check the diagnosis runs should leave the arc's null unscaled (factor <= 1.10 on
    every seed): it is the effect's path, not capacity to fit noise. h38's draw: 1.6-3.5,
    >= 2 on 4 of 6 seeds (h46's antithetic check, not adopted, gave 1.00-1.09)."""
    factors = [_case(seed)[1].factor for seed in range(6)]
    assert max(factors) <= 1.10, factors

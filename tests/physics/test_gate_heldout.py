"""The held-out fold steps behind the gate's statistic (robogs.physics.heldout), on toy models.

Oracles: (1) the bounded Gauss-Newton step of a linear model is the bounded least-squares
minimum found by brute force on a grid, and it beats clipping the unbounded step; (2) where the
linearised step raises the training chi^2 of a nonlinear model, the step is halved until it does
not, and a linear model is never halved; (3) parameters on a bound are named.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from robogs.physics.diagnose import _bound_report
from robogs.physics.fit import FitOutcome
from robogs.physics.heldout import gn_step, heldout_rollouts


def _space(lower, upper, names=("mu", "dmu")):
    slots = [SimpleNamespace(param=SimpleNamespace(name=n), owner="x") for n in names]
    return SimpleNamespace(
        lower=np.asarray(lower, float), upper=np.asarray(upper, float), slots=slots
    )


def _outcome(theta, resid, jac):
    t_n, k = resid.shape
    return FitOutcome(
        theta=np.asarray(theta, float),
        local=np.zeros((t_n, 3)),
        cost=float(np.sum(resid**2)),
        n=resid.size,
        resid=resid,
        jac=jac,
        jac_local=np.zeros((t_n, k, 3)),
    )


def test_bounded_step_is_the_bounded_least_squares_minimum():
    """Two nearly collinear columns (a friction and a Stribeck amplitude): the unbounded step
    drives the amplitude below 0, and clipping it leaves the friction with its compensation."""
    rng = np.random.default_rng(0)
    t_n, k = 4, 50
    s = np.linspace(0, 1, k)
    jac = np.stack([np.tile(s, (t_n, 1)), np.tile(s + 0.05 * s**2, (t_n, 1))], axis=-1)
    theta = np.array([0.30, 0.05])
    resid = rng.normal(0, 0.05, (t_n, k)) + 0.4 * jac[..., 1]  # wants dmu ~ -0.35
    space = _space([0.0, 0.0], [2.0, 3.0])
    out = _outcome(theta, resid, jac)
    train = np.array([True, True, True, False])
    th, hit = gn_step(out, space, [0, 1], train)
    assert hit[1] == "lower" and th[1] == 0.0

    def cost(t):
        d = t - theta
        return float(np.sum((resid[train] + jac[train] @ d) ** 2))

    g0, g1 = np.meshgrid(np.linspace(0.0, 1.0, 2001), np.linspace(0.0, 0.2, 401), indexing="ij")
    grid = [cost(np.array([a, b])) for a, b in zip(g0.ravel(), g1.ravel(), strict=True)]
    assert cost(th) <= min(grid) + 1e-6
    j = jac[train].reshape(-1, 2)
    free = theta - np.linalg.lstsq(j, resid[train].reshape(-1), rcond=None)[0]
    clipped = np.clip(free, space.lower, space.upper)
    assert cost(clipped) > 2.0 * cost(th)


class _Engine:
    """``evaluate`` of a toy model: residual = data - f(theta) per trajectory."""

    def __init__(self, data, f):
        self.data, self.f = data, f

    def evaluate(self, space, thetas, locals_):
        return np.stack([self.data - self.f(t) for t in thetas])


def test_failed_fold_steps_are_halved_and_linear_steps_are_not():
    t_n, k = 5, 40
    x = np.linspace(0.0, 1.0, k)
    rng = np.random.default_rng(1)
    folds = [np.arange(t_n) % 5 == f for f in range(5)]
    space = _space([0.0], [10.0], names=("b",))

    def fd_jac(f, th):
        h = 1e-6
        return ((f(th + h) - f(th)) / h)[..., None]

    # linear model: the Gauss-Newton step is exact, never halved
    lin = lambda th: np.tile(th[0] * x, (t_n, 1))  # noqa: E731
    data = lin(np.array([2.0])) + rng.normal(0, 0.1, (t_n, k))
    th = np.array([2.0])
    out = _outcome(th, data - lin(th), -fd_jac(lin, th))
    eng = _Engine(data, lin)
    held, hits, halved = heldout_rollouts(eng, space, [out], [[0]], folds)
    assert halved == [0]
    # nonlinear model b^2 x linearised at b = 0.2 for data at b = 2: the step to b = 10 (0.2 +
    # 3.96 / 0.4, on the bound) overshoots and raises the training chi^2; halving brings it down
    nl = lambda th: np.tile(th[0] ** 2 * x, (t_n, 1))  # noqa: E731
    data = nl(np.array([2.0])) + rng.normal(0, 0.01, (t_n, k))
    th = np.array([0.2])
    out = _outcome(th, data - nl(th), -fd_jac(nl, th))
    eng = _Engine(data, nl)
    full_step = [gn_step(out, space, [0], ~f)[0] for f in folds]
    raised = [
        np.sum((data - nl(t))[~f] ** 2) > np.sum(out.resid[~f] ** 2)
        for t, f in zip(full_step, folds, strict=True)
    ]
    assert all(raised)  # the oracle case: every full step fails
    held, hits, halved = heldout_rollouts(eng, space, [out], [[0]], folds)
    assert halved == [5]
    for i, f in enumerate(folds):
        assert np.sum(held[i][~f] ** 2) <= np.sum(out.resid[~f] ** 2)


def test_parameters_on_a_bound_are_named():
    space = _space([0.0, 0.01], [3.0, 1.0], names=("dmu", "v_s"))
    t_n, k = 3, 10
    out = _outcome([0.0, 0.5], np.zeros((t_n, k)), np.zeros((t_n, k, 2)))
    rep = _bound_report(space, out, [0, 1], [0, 1], [["lower", ""], ["", "upper"], ["", ""]])
    assert rep == {"dmu": "lower (full fit); lower in 1 of 3 folds", "v_s": "upper in 1 of 3 folds"}
    assert pytest.approx(0.0) == out.theta[0]

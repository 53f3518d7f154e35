"""A nested model with its extra parameters at their zero values is the base model: fitted by
:func:`robogs.physics.fit.fit_nested` it is never worse than the base, and its gain over the
base is its parameters', never the optimiser's (the converted null bag once reported ``mass``
with dm = 0.001 and a held-out fall of 1111 sigma^2: the base fit had stopped at its
iteration cap, the mass fit had gone on).

Oracle: the exact optima of both models by ``scipy.optimize.least_squares`` (trust region
reflective, tolerances 1e-12), an implementation independent of ours.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.optimize import least_squares

from robogs.physics.effects import Effect, Param
from robogs.physics.fit import Problem, fit_nested, fit_problems, nested_gap
from robogs.physics.space import ParamSpace

T, K = 4, 40
X = np.linspace(0.0, 1.0, K)
H = np.sin(7.0 * X)  # what the candidate parameter adds (absent from the data: a null)
SIGMA = 0.05


def _data(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    b = rng.normal(0.0, 0.3, T)
    return np.exp(1.2 * X)[None, :] + b[:, None] + rng.normal(0.0, SIGMA, (T, K))


def _space() -> ParamSpace:
    base = [Param("a", "-", -3.0, 3.0, 0.0, 1.0)]
    cand = Effect(name="wiggle", family="test", params=(Param("c", "-", -1.0, 1.0, 0.0, 0.1),))
    return ParamSpace(base, [cand])


def _fn(y: np.ndarray):
    yt = torch.as_tensor(y)
    x, h = torch.as_tensor(X), torch.as_tensor(H)

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        a, c = theta[:, 0:1, None], theta[:, 1:2, None]  # [M, 1, 1]
        pred = torch.exp(a * x) + local[:, :, 0:1] + c * h  # [M, T, K]
        return (pred - yt) / SIGMA

    return fn


def _exact(y: np.ndarray, with_c: bool) -> float:
    """Exact minimum chi^2 (scipy), parameters (a, [c], b_1..b_T)."""

    def res(p: np.ndarray) -> np.ndarray:
        a, c = p[0], (p[1] if with_c else 0.0)
        b = p[2:] if with_c else p[1:]
        return ((np.exp(a * X)[None] + b[:, None] + c * H - y) / SIGMA).ravel()

    p0 = np.zeros(T + (2 if with_c else 1))
    return float(2 * least_squares(res, p0, xtol=1e-12, ftol=1e-12, gtol=1e-12).cost)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_nested_never_worse_and_its_gain_is_its_own(seed: int) -> None:
    y = _data(seed)
    space, fn = _space(), _fn(y)
    # an iteration cap that stops the base fit short of its optimum (from a = -2.5, far off)
    theta0 = space.zero.copy()
    theta0[0] = -2.5

    def fit(probs):
        return fit_problems(fn, space, probs, n_traj=T, n_local=1, max_iter=4,
                            local_h=(1e-4,), ftol=1e-12, atol=1e-9)  # fmt: skip

    def evaluate(th: np.ndarray, lo: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return fn(torch.as_tensor(th), torch.as_tensor(lo)).numpy()

    cand = [([1], [space.zero])]
    exact_gain = _exact(y, False) - _exact(y, True)
    assert 0.0 <= exact_gain < 10.0  # a null: one parameter fitted to noise

    # without re-optimising the base (rounds=0) the candidate's gain is mostly the optimiser's:
    # this is the bug the test must catch
    b0, (c0,) = fit_nested(fit, evaluate, space, Problem([0], theta0=theta0), cand, rounds=0)
    assert b0.cost - _exact(y, False) > 100.0  # the capped base stopped short
    assert b0.cost - c0.cost > exact_gain + 50.0
    assert nested_gap(evaluate, space, b0, [c0], [[1]])[0] > 50.0

    b, (c,) = fit_nested(fit, evaluate, space, Problem([0], theta0=theta0), cand, rounds=6)
    # the invariant: the nested model is never worse than the base
    assert c.cost <= b.cost
    # and no longer beats it at the base model's parameters
    assert nested_gap(evaluate, space, b, [c], [[1]])[0] <= 1.0
    # its gain is the exact one (within the fit's tolerance), both at their exact optima
    assert b.cost == pytest.approx(_exact(y, False), abs=1.0)
    assert c.cost == pytest.approx(_exact(y, True), abs=1.0)
    assert b.cost - c.cost == pytest.approx(exact_gain, abs=1.0)


def test_damping_trials_reach_the_exact_optimum_in_fewer_rollouts() -> None:
    """fit_problems(damping=(0.1, 1, 10, 100)): several damping values tried in one rollout
    reach the same exact optimum (scipy) as plain LM, with no more rollouts."""
    from robogs.physics import fit as fit_mod

    y = _data(0)
    space, fn = _space(), _fn(y)
    theta0 = space.zero.copy()
    theta0[0] = -2.5
    calls = []

    def counted(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        calls.append(theta.shape[0])
        return fn(theta, local)

    runs = {}
    for damping in [(1.0,), (0.1, 1.0, 10.0, 100.0)]:
        calls.clear()
        (out,) = fit_mod.fit_problems(counted, space, [Problem([0], theta0=theta0)], n_traj=T,
                                      n_local=1, max_iter=200, local_h=(1e-4,), ftol=1e-12,
                                      atol=1e-9, damping=damping)  # fmt: skip
        assert out.cost == pytest.approx(_exact(y, False), abs=1e-3)
        runs[damping] = len(calls)
    assert runs[(0.1, 1.0, 10.0, 100.0)] <= runs[(1.0,)]

"""After a rejected step the fitter does not roll out a more damped one whose predicted gain is
under its stop tolerance (:func:`robogs.physics.fit.fit_problems`).

The objective is a staircase, as MuJoCo's contact events on whole 1 ms steps make a slide's end
pose: the forward difference (1 % of the scale) straddles a stair's edge, so the Jacobian
promises a gain ``P`` that no step shorter than the distance to that edge can realise. Every
trial is rejected, the damping rises tenfold each time, and the fit must stop as soon as the
linear model's prediction for the next trial falls under ``max(ftol chi^2, atol)``.

Oracle: the closed form of that prediction. With one parameter, Jacobian ``J`` and Marquardt
damping ``lam``, the step is ``-g / (A (1 + lam))`` (``A = J'J``, ``g = J'r``) and its predicted
gain ``P (2 / (1 + lam) - 1 / (1 + lam)^2)`` with ``P = g^2 / A``; the damping of trial ``k`` is
``1e-3 * 10^k``. Before this rule the fit stopped only past a damping of 1e6: ten rejected
rollouts whatever ``P`` (design B null seed 1 on MuJoCo, bench/RESULTS.md "rejected steps").
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.physics.effects import Param
from robogs.physics.fit import Problem, fit_problems
from robogs.physics.space import ParamSpace

K = 10  # samples
SIGMA = 1e-3  # m
STAIR = 0.02  # stair width [parameter units]; the FD step is 1 % of the scale 1: 0.01
C0 = 0.015  # start, 5e-3 below a stair's edge: the FD point 0.025 lies past it
LAM0, ATOL, FTOL = 1e-3, 0.05, 1e-5


def _fn(y0: float, calls: list[int]):
    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        calls.append(int(theta.shape[0]))
        s = STAIR * torch.floor(theta[:, 0] / STAIR)  # [M]
        return ((s[:, None] - y0) / SIGMA)[:, None, :].expand(-1, 1, K).clone()

    return fn


def _expected_trials(y0: float) -> int:
    """Trials rolled out: the first always, then each whose predicted gain reaches the bound."""
    r = -y0 / SIGMA
    jac = (STAIR / 0.01) / SIGMA  # forward difference across the edge
    g, a = K * jac * r, K * jac * jac
    p = g * g / a
    tol = max(FTOL * K * r * r, ATOL)
    n = 1
    for k in range(1, 20):
        q = 1.0 + LAM0 * 10.0**k
        if p * (2.0 / q - 1.0 / q**2) < tol:
            break
        n += 1
    return n


@pytest.mark.parametrize("y0", [1e-3, 4e-3])
def test_rejected_steps_stop_when_the_predicted_gain_is_under_the_tolerance(y0):
    space = ParamSpace([Param("c", "-", -1.0, 1.0, 0.0, 1.0)], [])
    calls: list[int] = []
    theta0 = np.array([C0])
    (out,) = fit_problems(
        _fn(y0, calls),
        space,
        [Problem(free=[0], theta0=theta0, fit_local=False, local0=np.zeros((1, 0)))],
        n_traj=1,
        n_local=0,
        local_h=(),
        atol=ATOL,
        ftol=FTOL,
    )
    # every trial stays on the start's stair: nothing is gained, the start is returned
    assert out.theta[0] == C0
    assert out.cost == pytest.approx(K * (y0 / SIGMA) ** 2, rel=1e-12)
    n = _expected_trials(y0)
    # y0 = 1e-3: P = 10 sigma^2, trials at damping 1e-3 ... 1e2 (6); y0 = 4e-3: P = 160, 7
    assert n == {1e-3: 6, 4e-3: 7}[y0]
    assert len(calls) == 1 + n  # the start's evaluation, then one rollout per trial
    assert n < 10  # the rule it replaces rolled out ten trials (damping 1e-3 ... 1e6)

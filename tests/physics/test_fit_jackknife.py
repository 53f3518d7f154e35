"""Fitter intervals: the leave-one-trajectory-out jackknife (CR3) against brute-force refits."""

from __future__ import annotations

import numpy as np
import torch

from robogs.physics.effects import Param
from robogs.physics.fit import Problem, fit_problems
from robogs.physics.space import ParamSpace


def _clustered_line(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """y = 1.5 x + intercept per cluster + noise; cluster 0 has a wide x range (it carries most
    of the slope information) and a slope error of its own, which the noise model cannot see."""
    rng = np.random.default_rng(seed)
    n_t, n_k = 8, 30
    x = rng.uniform(-0.2, 0.2, (n_t, n_k))
    x[0] = np.linspace(-3.0, 3.0, n_k)
    y = 1.5 * x + rng.normal(0.0, 1.0, (n_t, 1)) + rng.normal(0.0, 0.1, (n_t, n_k))
    y[0] += 0.05 * x[0]
    return x, y


def _fit(x: np.ndarray, y: np.ndarray, jackknife: bool):
    space = ParamSpace([Param("slope", "-", -10.0, 10.0, 0.0, 1.0)], [])
    xt, yt = torch.as_tensor(x), torch.as_tensor(y)

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        pred = theta[:, :1, None] * xt[None] + local[..., :1]
        return (yt[None] - pred) / 0.1

    return fit_problems(
        fn,
        space,
        [Problem(free=[0])],
        n_traj=x.shape[0],
        n_local=1,
        local_h=(1e-3,),
        cluster_jackknife=jackknife,
    )[0]


def _slope(x: np.ndarray, y: np.ndarray) -> float:
    """Least-squares slope with one intercept per cluster (within-cluster demeaning)."""
    xd = x - x.mean(axis=1, keepdims=True)
    yd = y - y.mean(axis=1, keepdims=True)
    return float(np.sum(xd * yd) / np.sum(xd * xd))


def test_jackknife_matches_leave_one_cluster_out_refits():
    x, y = _clustered_line()
    out = _fit(x, y, jackknife=True)
    assert abs(out.theta[0] - _slope(x, y)) < 1e-6
    # oracle: refit without each cluster, exactly, and take the jackknife variance
    loo = np.array([_slope(np.delete(x, t, 0), np.delete(y, t, 0)) for t in range(len(x))])
    g = len(loo)
    sd_jack = np.sqrt((g - 1) / g * np.sum((loo - loo.mean()) ** 2))
    assert np.isfinite(out.std[0]) and out.ok[0]
    assert abs(out.std[0] / sd_jack - 1.0) < 1e-3
    # without it the interval is the sandwich's or the model's, much narrower here
    plain = _fit(x, y, jackknife=False)
    assert plain.std[0] < 0.6 * sd_jack
    assert abs(plain.theta[0] - out.theta[0]) < 1e-9


def test_jackknife_never_narrows_the_interval():
    # homogeneous clusters: every estimate is close, and the reported one is the largest
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, (10, 25))
    y = 0.7 * x + rng.normal(0.0, 1.0, (10, 1)) + rng.normal(0.0, 0.1, (10, 25))
    with_jk = _fit(x, y, jackknife=True)
    without = _fit(x, y, jackknife=False)
    assert with_jk.std[0] >= without.std[0]
    assert with_jk.std[0] < 2.0 * without.std[0]

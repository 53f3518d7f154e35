"""The closed-form toy of the linearisation-check tests in ``test_gate_linearisation.py``
(numpy, no engine).

Per trajectory t and sample i: ``pred = beta x + l_t + S sin(a z)`` (+ jumps), ``beta`` the base
parameter, ``l_t`` a nuisance offset, ``a`` the effect's parameter (zero: no effect); unit noise.
The rough variant adds a jump of 1 sigma in norm every 0.4 % of ``a`` (h38's rough residual).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

T_N, K_N, S_AMP = 9, 40, 4.0


@dataclass(frozen=True)
class RoughToy:
    """The toy's design: sample positions ``x`` [T, K], phases ``z`` [T, K], jump positions
    ``tau`` and directions ``jumps`` [J, T, K] (unit norm each)."""

    x: np.ndarray
    z: np.ndarray
    tau: np.ndarray
    jumps: np.ndarray

    @property
    def xc(self) -> np.ndarray:
        return self.x - self.x.mean(axis=1, keepdims=True)

    def effect(self, a: float, rough: bool) -> np.ndarray:
        """The effect's prediction at parameter ``a`` (with the jumps between 0 and ``a``)."""
        out = S_AMP * np.sin(a * self.z)
        if rough:
            on = (a > self.tau).astype(float) - (0.0 > self.tau).astype(float)
            out = out + np.einsum("j,jtk->tk", on, self.jumps)
        return out

    def profile(self, r: np.ndarray) -> np.ndarray:
        """Residual after fitting beta and every trajectory's offset (linear least squares)."""
        rc = r - r.mean(axis=1, keepdims=True)
        xc = self.xc
        return rc - np.sum(rc * xc) / np.sum(xc * xc) * xc


def make_toy(seed: int) -> RoughToy:
    """The toy drawn from ``default_rng(seed)`` (x, z, then the jumps, in that order)."""
    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(0.0, 1.0, (T_N, K_N)), axis=1)
    z = rng.uniform(0.0, 2.0, (T_N, K_N))
    tau = np.arange(-0.3, 0.3001, 0.004)
    jumps = rng.standard_normal((len(tau), T_N, K_N))
    jumps /= np.linalg.norm(jumps, axis=(1, 2), keepdims=True)
    return RoughToy(x, z, tau, jumps)

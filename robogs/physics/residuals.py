"""Weighted residuals of the rigid model against the measured object poses."""

from __future__ import annotations

import torch

from robogs.physics.fit import ResidualFn
from robogs.physics.model import SimResult, simulate
from robogs.physics.prepare import Prepared
from robogs.physics.space import ParamSpace

__all__ = ["CHANNELS", "raw_residuals", "weighted_residuals", "residual_fn"]

CHANNELS = ("x", "y", "z", "yaw")


def raw_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor:
    """Measured minus predicted, [M, T, N, 4]: x, y, z [m] and yaw [rad] (wrapped); 0 padding."""
    dpos = prep.meas_pos.unsqueeze(0) - sim.pos
    dy = prep.meas_yaw.unsqueeze(0) - sim.yaw
    dy = torch.atan2(torch.sin(dy), torch.cos(dy))
    r = torch.cat([dpos, dy.unsqueeze(-1)], dim=-1)
    return r * prep.mask.unsqueeze(0).unsqueeze(-1)


def weighted_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor:
    """Residuals divided by their per-sample deviation, flattened to [M, T, N * 4]."""
    sig = torch.cat([prep.sig_pos, prep.sig_yaw.unsqueeze(-1)], dim=-1)
    r = raw_residuals(sim, prep) / sig.unsqueeze(0)
    return r.reshape(r.shape[0], r.shape[1], -1)


def residual_fn(prep: Prepared, space: ParamSpace) -> ResidualFn:
    """``fn(theta [M, Q], local [M, T, 3]) -> [M, T, N * 4]`` for the fitter."""

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        sim = simulate(theta, space, prep.drive, prep.scene, init_offset=local)
        return weighted_residuals(sim, prep)

    return fn

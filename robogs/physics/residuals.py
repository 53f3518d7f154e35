"""Weighted residuals of the rigid model against the measured object poses and pusher force.

Layout per trajectory: the pose block, 4 per object sample (x, y, z [m], yaw [rad]), then,
when the recording carries the pusher's force sensor, the force block, 4 per force bin
(fx, fy, fz [N], world axes, and a 0 so that both blocks share the width 4; the mean of the
bin's samples, :data:`robogs.physics.prepare.FORCE_BIN_S`). Each residual is
divided by its own noise floor (pose: :mod:`robogs.physics.noise`; force: the sensor's,
from the samples out of contact, :func:`robogs.physics.prepare.wrench_data`), so forces enter
the objective in N against the sensor noise, and mass, which poses alone cannot tell, becomes
identifiable.
"""

from __future__ import annotations

import torch

from robogs.physics.fit import ResidualFn
from robogs.physics.model import SimResult, simulate
from robogs.physics.prepare import Prepared
from robogs.physics.space import ParamSpace

__all__ = ["CHANNELS", "raw_residuals", "force_residuals", "weighted_residuals", "residual_fn"]

CHANNELS = ("x", "y", "z", "yaw")


def raw_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor:
    """Measured minus predicted, [M, T, N, 4]: x, y, z [m] and yaw [rad] (wrapped); 0 padding."""
    dpos = prep.meas_pos.unsqueeze(0) - sim.pos
    dy = prep.meas_yaw.unsqueeze(0) - sim.yaw
    dy = torch.atan2(torch.sin(dy), torch.cos(dy))
    r = torch.cat([dpos, dy.unsqueeze(-1)], dim=-1)
    return r * prep.mask.unsqueeze(0).unsqueeze(-1)


def force_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor | None:
    """Measured minus predicted pusher force [M, T, W, 4] (N; last column 0), or None."""
    w = prep.wrench
    if w is None or sim.force is None:
        return None
    r = (w.meas.unsqueeze(0) - sim.force) * w.mask.unsqueeze(0).unsqueeze(-1)
    return torch.nn.functional.pad(r, (0, 1))


def weighted_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor:
    """Residuals divided by their per-sample deviation, flattened to [M, T, (N + W) * 4]."""
    sig = torch.cat([prep.sig_pos, prep.sig_yaw.unsqueeze(-1)], dim=-1)
    r = raw_residuals(sim, prep) / sig.unsqueeze(0)
    r = r.reshape(r.shape[0], r.shape[1], -1)
    rf = force_residuals(sim, prep)
    if rf is None:
        return r
    w = prep.wrench
    sf = torch.nn.functional.pad(w.sigma, (0, 1), value=1.0) / w.count.sqrt().unsqueeze(-1)
    rf = rf / sf.unsqueeze(0)
    return torch.cat([r, rf.reshape(rf.shape[0], rf.shape[1], -1)], dim=-1)


def residual_fn(prep: Prepared, space: ParamSpace) -> ResidualFn:
    """``fn(theta [M, Q], local [M, T, 3]) -> [M, T, N * 4]`` for the fitter."""

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        sim = simulate(theta, space, prep.drive, prep.scene, init_offset=local)
        return weighted_residuals(sim, prep)

    return fn

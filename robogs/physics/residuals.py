"""Weighted residuals of the rigid model against the measured object poses and pusher force.

Layout per trajectory: the pose block, 4 per object sample (x, y, z [m], yaw [rad]), then one
such block per other tracked object (:attr:`robogs.physics.prepare.Prepared.tracked`, in that
order, each whitened by its own noise estimate; only an engine that predicts them,
:class:`SceneSimResult`, can be compared with such a recording), then,
when the recording carries the pusher's force sensor, the force block, 4 per force bin
(fx, fy, fz [N], world axes, and a 0 so that both blocks share the width 4; the mean of the
bin's samples, :data:`robogs.physics.prepare.FORCE_BIN_S`). Each residual is
divided by its own noise floor (pose: :mod:`robogs.physics.noise`; force: the sensor's,
from the samples out of contact, :func:`robogs.physics.prepare.wrench_data`), so forces enter
the objective in N against the sensor noise, and mass, which poses alone cannot tell, becomes
identifiable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.physics.fit import ResidualFn
from robogs.physics.model import SimResult, simulate
from robogs.physics.prepare import Prepared, TrackedObject
from robogs.physics.space import ParamSpace

__all__ = [
    "CHANNELS",
    "SceneSimResult",
    "raw_residuals",
    "force_residuals",
    "tracked_residuals",
    "tracked_rms",
    "tracked_streams",
    "weighted_residuals",
    "residual_fn",
]

CHANNELS = ("x", "y", "z", "yaw")


@dataclass
class SceneSimResult(SimResult):
    """A :class:`~robogs.physics.model.SimResult` with the other tracked objects' predictions:
    ``others[name] = (pos [M, T, K, 3] m, yaw [M, T, K] rad)`` at that object's stamps."""

    others: dict[str, tuple[torch.Tensor, torch.Tensor]] = field(default_factory=dict)


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


def tracked_residuals(sim: SimResult, obj: TrackedObject) -> torch.Tensor:
    """Measured minus predicted poses of another tracked object, [M, T, K, 4] (0 padding).

    Raises:
        InputError: the engine predicted only the free object (the planar model).
    """
    others = getattr(sim, "others", None) or {}
    if obj.name not in others:
        raise InputError(
            f"the recording tracks object {obj.name!r} too, and this engine predicts only the "
            "pushed object",
            where="--engine",
            hint="use --engine mujoco (or auto): it simulates every object of the scene",
        )
    pos, yaw = others[obj.name]
    dy = obj.meas_yaw.unsqueeze(0) - yaw
    dy = torch.atan2(torch.sin(dy), torch.cos(dy))
    r = torch.cat([obj.meas_pos.unsqueeze(0) - pos, dy.unsqueeze(-1)], dim=-1)
    return r * obj.mask.unsqueeze(0).unsqueeze(-1)


def weighted_residuals(sim: SimResult, prep: Prepared) -> torch.Tensor:
    """Residuals divided by their per-sample deviation, flattened to [M, T, (N + K... + W) * 4]
    (the free object's poses, each tracked object's poses, the pusher force)."""
    sig = torch.cat([prep.sig_pos, prep.sig_yaw.unsqueeze(-1)], dim=-1)
    r = raw_residuals(sim, prep) / sig.unsqueeze(0)
    r = r.reshape(r.shape[0], r.shape[1], -1)
    blocks = [r]
    for obj in prep.tracked:
        so = torch.cat([obj.sig_pos, obj.sig_yaw.unsqueeze(-1)], dim=-1)
        ro = tracked_residuals(sim, obj) / so.unsqueeze(0)
        blocks.append(ro.reshape(ro.shape[0], ro.shape[1], -1))
    r = torch.cat(blocks, dim=-1) if len(blocks) > 1 else r
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


def _tracked_raw(prep: Prepared, weighted: np.ndarray) -> list[tuple[TrackedObject, np.ndarray]]:
    """Each tracked object with its raw residuals [..., T, K, 4] (m, rad) out of weighted ones."""
    out = []
    col = int(prep.mask.shape[1]) * 4
    w = np.asarray(weighted)
    for obj in prep.tracked:
        sig = torch.cat([obj.sig_pos, obj.sig_yaw.unsqueeze(-1)], dim=-1).numpy()
        out.append(
            (obj, w[..., col : col + obj.width].reshape(*w.shape[:-1], *sig.shape[1:]) * sig)
        )
        col += obj.width
    return out


def tracked_rms(prep: Prepared, weighted: np.ndarray) -> dict[str, dict[str, Any]]:
    """Per other tracked object, from weighted residuals [T, C] (:func:`weighted_residuals`):
    ``rms_mm`` (3-D position RMS over its valid samples), ``rms_deg`` (yaw), ``noise_floor_mm``
    (the RMS its own per-sample deviations give: what the true model would leave) and
    ``per_trajectory_mm`` [T]."""
    out: dict[str, dict[str, Any]] = {}
    for obj, raw in _tracked_raw(prep, weighted):
        m = obj.mask.numpy()
        d2 = np.sum(raw[..., :3] ** 2, axis=-1)
        per = [
            float(np.sqrt(d2[i][m[i]].mean()) * 1e3) if m[i].any() else 0.0 for i in range(len(m))
        ]
        floor = np.sum(obj.sig_pos.numpy() ** 2, axis=-1)[m]
        out[obj.name] = {
            "rms_mm": float(np.sqrt(d2[m].mean()) * 1e3),
            "rms_deg": float(np.degrees(np.sqrt(np.mean(raw[..., 3][m] ** 2)))),
            "noise_floor_mm": float(np.sqrt(floor.mean()) * 1e3),
            "per_trajectory_mm": per,
        }
    return out


def tracked_streams(prep: Prepared, weighted: np.ndarray) -> list[Any]:
    """``object_poses/<name>`` rows (:class:`~robogs.physics.compare.StreamResidual`, mm and
    deg; no per-phase split) of every other tracked object in every trajectory."""
    from robogs.physics.compare import StreamResidual

    rows = []
    for obj, raw in _tracked_raw(prep, weighted):
        m = obj.mask.numpy()
        for i, tr in enumerate(prep.rec.trajectories):
            e = raw[i][m[i]]
            d = np.linalg.norm(e[:, :3], axis=-1) * 1e3
            rows.append(
                StreamResidual(
                    stream=f"object_poses/{obj.name}",
                    trajectory=tr.name,
                    rms_mm=float(np.sqrt(np.mean(d**2))) if d.size else 0.0,
                    max_mm=float(d.max()) if d.size else 0.0,
                    rms_deg=float(np.degrees(np.sqrt(np.mean(e[:, 3] ** 2)))) if d.size else 0.0,
                    per_phase_mm={},
                )
            )
    return rows

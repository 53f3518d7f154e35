"""Replaying an exported scene in plain MuJoCo: the pusher driven by its servos (test helper)."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np


def drive_pusher(
    model,
    data,
    qb: int,
    p: np.ndarray,
    yaw: np.ndarray,
    dt: float,
    knot_steps: float | None = None,
    dofs: np.ndarray | None = None,
    servos: Sequence[Sequence[str]] = (),
) -> np.ndarray:
    """Drive the pusher along ``p`` [N, 3] m / ``yaw`` [N] rad (position + velocity controls,
    step ``dt`` s) and return the box's slide positions [N, 3] m (qpos from index ``qb``). The
    servos get the path the engine gives them (``mujoco_engine.servo_targets``: smoothed over
    the spacing ``knot_steps`` [steps] of the samples ``p`` was interpolated from: the median
    stamp spacing over ``dt``, or ``mujoco_engine.sample_steps(drive)[t]`` for an engine's
    drive; None reads it from the path, which works only for stamps on the steps).

    A robot pusher's other DOFs (``dofs`` [N, J] rad or m on the same grid, the columns of
    ``servos``: (joint, position servo, velocity servo) names, ``pusher_servos`` of
    ``robot_trajectory.npz``) go through ``mujoco_engine.servo_dof_targets`` at the same
    spacing and drive their servos likewise; their joints start at the first targets' values
    and velocities, as the engine starts them."""
    from robogs.physics.engines.mujoco_engine import servo_dof_targets, servo_targets

    raw = np.asarray(p, dtype=float)
    sp, sy = servo_targets(raw[None], yaw[None], knot_steps)
    p, yaw = sp[0], sy[0]
    d, pos_ids, vel_ids = None, [], []
    if dofs is not None and len(servos):
        d = servo_dof_targets(raw[None], np.asarray(dofs, dtype=float)[None], knot_steps)[0]
        pos_ids = [model.actuator(s[1]).id for s in servos]
        vel_ids = [model.actuator(s[2]).id for s in servos]
        raw_d = np.asarray(dofs, dtype=float)
        for i, s in enumerate(servos):
            j = model.joint(s[0])
            data.qpos[j.qposadr[0]] = raw_d[0, i]
            data.qvel[j.dofadr[0]] = (raw_d[1, i] - raw_d[0, i]) / dt
    pos = np.empty((len(p), 3))
    pos[0] = data.qpos[qb : qb + 3]
    for k in range(len(p) - 1):
        data.ctrl[:4] = (*p[k], yaw[k])
        data.ctrl[4:7] = (p[k + 1] - p[k]) / dt
        data.ctrl[7] = (yaw[k + 1] - yaw[k]) / dt
        if d is not None:
            data.ctrl[pos_ids] = d[k]
            data.ctrl[vel_ids] = (d[k + 1] - d[k]) / dt
        mujoco.mj_step(model, data)
        pos[k + 1] = data.qpos[qb : qb + 3]
    return pos

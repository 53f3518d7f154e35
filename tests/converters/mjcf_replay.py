"""Replaying an exported scene in plain MuJoCo: the pusher driven by its servos (test helper)."""

from __future__ import annotations

import mujoco
import numpy as np


def drive_pusher(
    model, data, qb: int, p: np.ndarray, yaw: np.ndarray, dt: float, knot_steps: float | None = None
) -> np.ndarray:
    """Drive the pusher along ``p`` [N, 3] m / ``yaw`` [N] rad (position + velocity controls,
    step ``dt`` s) and return the box's slide positions [N, 3] m (qpos from index ``qb``). The
    servos get the path the engine gives them (``mujoco_engine.servo_targets``: smoothed over
    the spacing ``knot_steps`` [steps] of the samples ``p`` was interpolated from: the median
    stamp spacing over ``dt``, or ``mujoco_engine.sample_steps(drive)[t]`` for an engine's
    drive; None reads it from the path, which works only for stamps on the steps)."""
    from robogs.physics.engines.mujoco_engine import servo_targets

    sp, sy = servo_targets(p[None], yaw[None], knot_steps)
    p, yaw = sp[0], sy[0]
    pos = np.empty((len(p), 3))
    pos[0] = data.qpos[qb : qb + 3]
    for k in range(len(p) - 1):
        data.ctrl[:4] = (*p[k], yaw[k])
        data.ctrl[4:7] = (p[k + 1] - p[k]) / dt
        data.ctrl[7] = (yaw[k + 1] - yaw[k]) / dt
        mujoco.mj_step(model, data)
        pos[k + 1] = data.qpos[qb : qb + 3]
    return pos

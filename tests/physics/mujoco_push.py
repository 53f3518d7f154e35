"""Straight pushes along +x for the MuJoCo engine tests: the pusher's speed profiles, the drive,
and which contacts touch the pusher while :meth:`MujocoEngine.step_states` steps a scene. SI
units, world frame (z up)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from robogs.physics.engines.base import make_drive
from robogs.physics.model import Drive


def ramp_up(v: float, n: int) -> np.ndarray:
    """Speeds [m/s] of ``n`` steps that take the pusher from rest to ``v`` along a half cosine
    (the last one is ``v``)."""
    return v * 0.5 * (1 - np.cos(np.pi * np.arange(1, n + 1) / n))


def brake(v: float, dt: float, decel: float = 12.0) -> np.ndarray:
    """Speeds [m/s] of the steps that stop a pusher at ``v`` with ``decel`` [m/s^2] (linear,
    the last one 0)."""
    n = int(math.ceil(v / decel / dt))
    return np.linspace(v, 0.0, n + 1)[1:]


def push_x(
    vel: np.ndarray,
    start_x: float,
    z: float,
    dt: float,
    box_x: np.ndarray | None = None,
    every_step: bool = False,
) -> Drive:
    """The pusher from ``(start_x, 0, z)`` along +x at ``vel[k]`` [m/s] on step k (S = len(vel)
    + 1 poses), heading 0; one trajectory per object start ``(box_x[t], 0, z)`` [m] (default
    one at the origin), yaw 0. Poses are wanted at the end only, or at every step."""
    box_x = np.zeros(1) if box_x is None else np.asarray(box_x, dtype=float)
    x = start_x + np.concatenate([[0.0], np.cumsum(vel) * dt])
    n, t = len(x), len(box_x)
    path = np.repeat(np.stack([x, np.zeros(n), np.full(n, z)], -1)[None], t, 0)
    init = np.stack([box_x, np.zeros(t), np.full(t, z)], -1)
    stamps = (
        np.repeat((np.arange(n) * dt)[None], t, 0) if every_step else np.full((t, 1), (n - 1) * dt)
    )
    return make_drive(dt, path, np.zeros((t, n)), stamps, init, np.zeros(t))


def pusher_contacts(model: mujoco.MjModel, data: mujoco.MjData) -> list[int]:
    """Indices into ``data.contact`` of the contacts that touch the pusher's geoms (``pusher``
    and, on a capsule, ``pusher_end``), in contact order."""
    ids = {mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in ("pusher", "pusher_end")}
    ids.discard(-1)
    c = data.contact
    return [i for i in range(data.ncon) if int(c.geom1[i]) in ids or int(c.geom2[i]) in ids]

"""The engine interface: what every simulator behind the physics loop provides.

An engine is built from a scene (a physics.json document and, optionally, object meshes) and
rolls out M parameter sets x T trajectories of a measured pusher drive, returning the object
poses at the measurement stamps. It says up front whether it can represent a scene at all
(:meth:`Engine.can_represent`), so ``auto`` can pick one.

Conventions: world frame z up, metres, seconds from each trajectory's start; quaternions
(w, x, y, z); an object pose is ``T_world_object`` of its ``object_poses`` frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
import torch

from robogs.physics.model import Drive

__all__ = ["Engine", "ObjectState", "Predicted", "make_drive", "yaw_quat", "quat_yaw"]


@dataclass
class ObjectState:
    """Initial state of one object over T trajectories.

    Attributes:
        pos: [T, 3] m, object-frame origin in the world.
        quat: [T, 4] (w, x, y, z), T_world_object rotation.
        vel: [T, 3] m/s, velocity of the object-frame origin (world).
        omega: [T, 3] rad/s, angular velocity (world).
    """

    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray | None = None
    omega: np.ndarray | None = None


@dataclass
class Predicted:
    """Object poses at the drive's stamps, per object name.

    Attributes:
        pos: name -> [M, T, N, 3] m, world.
        quat: name -> [M, T, N, 4] (w, x, y, z).
        notes: what the engine substituted or could not map (one line each).
    """

    pos: dict[str, np.ndarray]
    quat: dict[str, np.ndarray]
    notes: list[str]

    def yaw(self, name: str) -> np.ndarray:
        """[M, T, N] heading of the object's x axis about world z [rad], unwrapped over N."""
        return np.unwrap(quat_yaw(self.quat[name]), axis=-1)


@runtime_checkable
class Engine(Protocol):
    """A rigid-scene simulator.

    Built as ``cls(physics, *, object_name=None, meshes=None, dt=1e-3, threads=1)``.
    """

    name: ClassVar[str]

    @classmethod
    def can_represent(
        cls, physics: Mapping[str, Any], meshes: Mapping[str, Any] | None = None
    ) -> tuple[bool, str]:
        """Whether the engine can simulate this scene, and if not, why (one line)."""
        ...

    def rollout(
        self,
        drive: Drive,
        initial: Mapping[str, ObjectState] | None = None,
        params: Mapping[str, Sequence[float]] | None = None,
    ) -> Predicted:
        """Roll out every parameter set over every trajectory of ``drive``.

        Args:
            drive: the measured pusher on the simulation grid and the measurement stamps.
            initial: object name -> initial state (default: the drive's measured initial pose
                of the modelled object, at rest; other objects at their scene pose).
            params: physics.json dotted keys -> M values (default: one set, the document's).
        """
        ...


def yaw_quat(yaw: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of rotations by ``yaw`` [rad] about z; shape [..., 4]."""
    yaw = np.asarray(yaw, dtype=float)
    z = np.zeros_like(yaw)
    return np.stack([np.cos(yaw / 2), z, z, np.sin(yaw / 2)], axis=-1)


def quat_yaw(q: np.ndarray) -> np.ndarray:
    """Heading [rad] of the rotated x axis about world z, of (w, x, y, z) quaternions [..., 4]."""
    w, x, y, z = (q[..., i] for i in range(4))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def make_drive(
    dt: float,
    pusher: np.ndarray,
    pusher_yaw: np.ndarray,
    obs_t: np.ndarray,
    init_pos: np.ndarray,
    init_yaw: np.ndarray,
    sample_dt: float | np.ndarray | None = None,
    pusher_dofs: np.ndarray | None = None,
) -> Drive:
    """A :class:`~robogs.physics.model.Drive` from arrays (no grasp, object at rest).

    Args:
        dt: grid step [s].
        pusher: [T, S, 3] pusher-centre positions on the grid [m], world.
        pusher_yaw: [T, S] pusher yaw [rad].
        obs_t: [T, N] stamps [s] from the trajectory start at which poses are wanted.
        init_pos: [T, 3] initial object position [m]; init_yaw: [T] [rad].
        sample_dt: the sample interval [s] of the stamped stream ``pusher`` was linearly
            interpolated from (one for all trajectories or [T]; e.g. the median spacing of
            the encoder stamps); None when unknown or the path is given per step
            (``Drive.sample_dt``).
        pusher_dofs: [T, S, J] the robot pusher's other servo DOFs on the grid (rad or m,
            ``Drive.pusher_dofs``); None: none.
    """
    pusher = np.asarray(pusher, dtype=float)
    pusher_yaw = np.asarray(pusher_yaw, dtype=float)
    vel = np.zeros_like(pusher)
    vel[:, :-1] = np.diff(pusher, axis=1) / dt
    rate = np.zeros_like(pusher_yaw)
    rate[:, :-1] = np.diff(pusher_yaw, axis=1) / dt
    f = torch.float64
    obs_t = np.asarray(obs_t, dtype=float)
    return Drive(
        dt=dt,
        pusher=torch.as_tensor(pusher, dtype=f),
        pusher_vel=torch.as_tensor(vel, dtype=f),
        ee_yaw=torch.as_tensor(pusher_yaw, dtype=f),
        ee_yaw_rate=torch.as_tensor(rate, dtype=f),
        grasp=torch.zeros(pusher.shape[:2], dtype=torch.bool),
        init_pos=torch.as_tensor(np.asarray(init_pos, dtype=float), dtype=f),
        init_yaw=torch.as_tensor(np.asarray(init_yaw, dtype=float), dtype=f),
        obs_t=torch.as_tensor(obs_t, dtype=f),
        obs_mask=torch.ones(obs_t.shape, dtype=torch.bool),
        sample_dt=None
        if sample_dt is None
        else torch.as_tensor(
            np.broadcast_to(np.asarray(sample_dt, dtype=float), pusher.shape[:1]).copy(), dtype=f
        ),
        pusher_dofs=None
        if pusher_dofs is None
        else torch.as_tensor(np.asarray(pusher_dofs, dtype=float), dtype=f),
    )

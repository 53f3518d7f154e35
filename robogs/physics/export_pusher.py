"""The robot pusher of a dataset as ``robogs export mjcf`` writes it (h80, issue 16).

With ``objects.pusher.geometry = "robot"`` the pusher the engine fits with is measured from
the recording (:func:`robogs.physics.recording.load_recording`: the links' poses in the pusher
frame, the end effector's tilt and the joints below the pusher link that move, as servo DOFs;
:mod:`robogs.physics.engines.mujoco_robot`). ``robogs.convert`` may not import the physics, so
the exporter takes that measurement as its ``robot_pusher`` option
(:class:`robogs.format.mjcf_pusher.PusherPaths`) and writes it with the engine's own writer
(:func:`robogs.format.mjcf_pusher.robot_pusher_scene`). This function makes the option: the
same ``load_recording`` call ``compare`` and ``fit`` make, one trajectory per episode, with
the servo DOFs' first recorded values as the keyframe's start (:attr:`RobotPusher.start`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from robogs.format.mjcf_pusher import PusherPaths, pusher_geometry

__all__ = ["robot_pusher_paths"]


def robot_pusher_paths(dataset: Any) -> PusherPaths | None:
    """The robot pusher of ``dataset`` (a :class:`robogs.format.dataset.Dataset` or folder) and,
    per episode at its end-effector stamps, the pusher point [N, 3] m, its yaw [N] rad
    (unwrapped, :func:`robogs.physics.recording.yaw_of`) and the servo DOFs [N, J]
    (``Trajectory.pusher_dofs``); None with the primitive pusher.

    The pusher's :attr:`~robogs.format.mjcf_pusher.RobotPusher.start` is set to the DOFs at
    the first end-effector stamp of the scene's episode (the dataset's first, whose first
    ``joint_states`` row and object poses the exported keyframe holds;
    :func:`robogs.convert.export.urdf_scene.scene_state`), else of the first episode with a
    trajectory: the exported scene starts its fingers and tilt where the recording does.

    Raises:
        FormatError, InputError: as :func:`robogs.physics.recording.load_recording` (no URDF,
            a link that strays with nothing left to model, ...).
    """
    from robogs.format.dataset import Dataset
    from robogs.physics.recording import load_recording, yaw_of

    ds = dataset if isinstance(dataset, Dataset) else Dataset.open(dataset)
    if pusher_geometry(ds.physics()) != "robot":
        return None
    rec = load_recording(ds, split="none")
    rp = rec.robot_pusher
    n_dof = len(rp.dofs)
    paths = PusherPaths(rp, [], [], [], [], [])
    for tr in rec.trajectories:
        n = len(tr.ee_t_ns)
        dofs = tr.pusher_dofs if tr.pusher_dofs is not None else np.zeros((n, n_dof))
        paths.episodes.append(str(tr.name))
        paths.t_ns.append(np.asarray(tr.ee_t_ns, dtype=np.int64))
        paths.point.append(np.asarray(tr.ee_pos, dtype=float))
        paths.yaw.append(np.unwrap(yaw_of(np.asarray(tr.ee_quat, dtype=float))))
        paths.dofs.append(np.asarray(dofs, dtype=float).reshape(n, n_dof))
    if n_dof and paths.episodes:
        first = ds.episodes[0].id if ds.episodes else None
        k = paths.episodes.index(first) if first in paths.episodes else 0
        paths.pusher = replace(rp, start=[float(v) for v in paths.dofs[k][0]])
    return paths

"""Joints without effort data held at a constant position: frozen into fixed joints.

A log may leave out some joints (a gripper's fingers on a Franka arm log, a rail). The
tabular import then writes them as constant ``position.<j>`` columns with no ``effort.<j>``
(see :mod:`robogs.convert.ingest.tabular`, ``hold``). For the torque model such a joint has
``qd = qdd = 0`` and no measured torque, so it is exactly a fixed joint at that position: the
model is built from the URDF with these joints (and the mimic joints that follow them)
replaced by fixed joints whose origin includes the held motion.
"""

from __future__ import annotations

import copy

import numpy as np
import pyarrow.parquet as pq
import yourdfpy

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError

__all__ = ["held_joints", "freeze_joints"]


def held_joints(ds: Dataset, joint_names: tuple[str, ...] | list[str]) -> dict[str, float]:
    """Joints with a position column but no effort column, constant over every episode that
    has efforts for the other joints.

    Returns:
        joint -> held position (rad or m); empty when every joint has efforts.

    Raises:
        InputError: such a joint moves, or is held at different positions in different episodes.
    """
    held: dict[str, float] = {}
    where: dict[str, str] = {}
    for ep in ds.episodes:
        if not ep.has("joint_states"):
            continue
        names = pq.ParquetFile(ep.table_path("joint_states")).schema_arrow.names
        with_effort = [j for j in joint_names if f"effort.{j}" in names]
        if not with_effort:
            continue
        lacking = [j for j in joint_names if j not in with_effort and f"position.{j}" in names]
        if not lacking:
            continue
        table = ep.table("joint_states", columns=[f"position.{j}" for j in lacking])
        for j in lacking:
            q = table.column(f"position.{j}").to_numpy()
            q = q[np.isfinite(q)]
            if len(q) == 0:
                continue
            if np.ptp(q) > 0:
                raise InputError(
                    f"joint {j!r} moves but has no effort column",
                    path=ds.root,
                    where=f"episodes/{ep.id}/joint_states",
                    hint="log its effort too, or leave the episode out of the torque model",
                )
            v = float(q[0])
            if j in held and held[j] != v:
                raise InputError(
                    f"joint {j!r} is held at {held[j]:g} in {where[j]} but at {v:g} in {ep.id}",
                    path=ds.root,
                    where=f"episodes/{ep.id}/joint_states",
                    hint="split the dataset by gripper state",
                )
            held[j], where[j] = v, ep.id
    return held


def _motion(joint: yourdfpy.Joint, value: float) -> np.ndarray:
    """[4, 4] motion of a revolute/continuous/prismatic joint at ``value`` (rad or m)."""
    axis = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)
    axis = axis / np.linalg.norm(axis)
    t = np.eye(4)
    if joint.type == "prismatic":
        t[:3, 3] = axis * value
        return t
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    t[:3, :3] = np.eye(3) + np.sin(value) * k + (1 - np.cos(value)) * (k @ k)  # Rodrigues
    return t


def freeze_joints(urdf: yourdfpy.URDF, held: dict[str, float]) -> yourdfpy.URDF:
    """A copy of ``urdf`` with the ``held`` joints and their mimics as fixed joints.

    Args:
        urdf: the robot.
        held: joint -> position (rad or m).

    Returns:
        A new URDF (no scene graph, no meshes); ``urdf`` is not changed.
    """
    if not held:
        return urdf
    robot = copy.deepcopy(urdf.robot)
    for j in robot.joints:
        if j.name in held:
            value = held[j.name]
        elif j.mimic is not None and j.mimic.joint in held:
            mult = 1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier)
            off = 0.0 if j.mimic.offset is None else float(j.mimic.offset)
            value = mult * held[j.mimic.joint] + off
        else:
            continue
        origin = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float)
        j.origin = origin @ _motion(j, value)
        j.type, j.mimic = "fixed", None
    return yourdfpy.URDF(robot=robot, build_scene_graph=False, load_meshes=False)

"""The scene of a URDF export: where the robot, the objects and the table are at one time.

The scene time is the start of the dataset's first episode. Each object's pose
``T_world_object`` is, in this order of preference:

1. its first sample in that episode's ``object_poses`` stream (``source: "object_poses"``,
   with the sample's ``t_ns``);
2. the manifest's ``assets.<name>.pose`` (``source: "manifest"``);
3. the splats' rest pose ``assets.<name>.splats.rest.object_poses`` (``source: "splat_rest"``);
4. the identity (``source: "identity"``: the asset mesh is already in world coordinates).

The world frame is the robot's root link (robogs' world has its origin at the robot base), so
the robot sits at the identity. The joint positions at the scene time are the first
``joint_states`` row. Poses are ``[x, y, z, qw, qx, qy, qz]`` (m; unit quaternion, w first).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from robogs.format import Dataset

__all__ = ["ScenePose", "SceneState", "pose_matrix", "scene_state"]

_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")


@dataclass(frozen=True)
class ScenePose:
    """``T_world_object`` of one object at the scene time.

    Attributes:
        pose: [x, y, z, qw, qx, qy, qz], metres and a unit quaternion.
        source: ``object_poses`` | ``manifest`` | ``splat_rest`` | ``identity``.
        t_ns: stamp of the ``object_poses`` sample, None for the other sources.
    """

    pose: list[float]
    source: str
    t_ns: int | None = None

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"pose": self.pose, "source": self.source}
        if self.t_ns is not None:
            out["t_ns"] = self.t_ns
        return out


@dataclass(frozen=True)
class SceneState:
    """The scene at its time.

    Attributes:
        episode: episode id the poses come from (None: the dataset has no episode).
        t_ns: the scene time (the episode start), None without an episode.
        joint_positions: rad or m per joint, at ``joint_positions_t_ns`` (empty if none).
        joint_positions_t_ns: stamp of the ``joint_states`` row used.
        objects: object name -> pose.
    """

    episode: str | None
    t_ns: int | None
    joint_positions: dict[str, float]
    joint_positions_t_ns: int | None
    objects: dict[str, ScenePose]


def pose_matrix(pose: list[float]) -> np.ndarray:
    """[4, 4] transform of ``[x, y, z, qw, qx, qy, qz]`` (the quaternion is normalised)."""
    x, y, z, w, qx, qy, qz = (float(v) for v in pose)
    n = np.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    w, qx, qy, qz = w / n, qx / n, qy / n, qz / n
    T = np.eye(4)
    T[:3, :3] = [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * w), 2 * (qx * qz + qy * w)],
        [2 * (qx * qy + qz * w), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * w)],
        [2 * (qx * qz - qy * w), 2 * (qy * qz + qx * w), 1 - 2 * (qx * qx + qy * qy)],
    ]
    T[:3, 3] = (x, y, z)
    return T


def _first_rows(tab: pa.Table, key: str) -> dict[str, dict[str, Any]]:
    """The earliest row of each ``key`` value."""
    tab = tab.sort_by("t_ns")
    cols = {c: tab.column(c).to_pylist() for c in ("t_ns", key, *_POSE)}
    out: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(cols[key]):
        if name not in out:
            out[name] = {c: v[i] for c, v in cols.items()}
    return out


def scene_state(ds: Dataset, objects: list[str]) -> SceneState:
    """Poses of ``objects`` and the joint positions at the start of the first episode."""
    ep = ds.episodes[0] if ds.episodes else None
    first: dict[str, dict[str, Any]] = {}
    q: dict[str, float] = {}
    q_t = None
    if ep is not None and ep.has("object_poses"):
        first = _first_rows(ep.table("object_poses"), "object")
    if ep is not None and ep.has("joint_states"):
        js = ep.table("joint_states").sort_by("t_ns").slice(0, 1)
        if js.num_rows:
            q_t = int(js.column("t_ns")[0].as_py())
            q = {
                c[len("position.") :]: float(js.column(c)[0].as_py())
                for c in js.column_names
                if c.startswith("position.")
            }
    poses: dict[str, ScenePose] = {}
    for name in objects:
        asset = ds.assets.get(name) or {}
        rest = ((asset.get("splats") or {}).get("rest") or {}).get("object_poses") or {}
        if name in first:
            row = first[name]
            poses[name] = ScenePose(
                [float(row[c]) for c in _POSE], "object_poses", int(row["t_ns"])
            )
        elif asset.get("pose") is not None:
            poses[name] = ScenePose([float(v) for v in asset["pose"]], "manifest")
        elif rest.get(name) is not None:
            poses[name] = ScenePose([float(v) for v in rest[name]], "splat_rest")
        else:
            poses[name] = ScenePose([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], "identity")
    return SceneState(
        episode=None if ep is None else ep.id,
        t_ns=None if ep is None else int(ep.start_ns),
        joint_positions=q,
        joint_positions_t_ns=q_t,
        objects=poses,
    )

"""Static transform tree from ``/tf_static`` (tf2_msgs/TFMessage).

Each ``TransformStamped`` gives ``T_parent_child`` (``header.frame_id`` = parent,
``child_frame_id`` = child; ROS quaternions are ``(x, y, z, w)``). :meth:`StaticTfTree.lookup`
composes the chain between two frames, walking edges in either direction.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from robogs.format.frames import matrix_to_quat_np, quat_to_matrix_np

__all__ = [
    "StaticTfTree",
    "frame_path",
    "pose_to_matrix",
    "matrix_to_pose",
    "quat_to_matrix_np",
    "matrix_to_quat_np",
]


def pose_to_matrix(t: np.ndarray, q_wxyz: np.ndarray) -> np.ndarray:
    """[4, 4] transform from a translation [3] (m) and a quaternion [4] (w, x, y, z).

    Raises:
        ValueError: the quaternion is zero or not finite.
    """
    n = float(np.linalg.norm(np.asarray(q_wxyz, dtype=np.float64)))
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError("zero or non-finite quaternion")
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix_np(q_wxyz)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def matrix_to_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation [3] and quaternion [4] (w, x, y, z; w >= 0) of a [4, 4] rigid transform."""
    return np.asarray(T[:3, 3], dtype=np.float64).copy(), matrix_to_quat_np(T[:3, :3])


def _transform_of(ts: Any) -> tuple[str, str, np.ndarray]:
    tr = ts.transform
    t = np.array([tr.translation.x, tr.translation.y, tr.translation.z], dtype=np.float64)
    q = np.array([tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z], dtype=np.float64)
    return (
        str(ts.header.frame_id).lstrip("/"),
        str(ts.child_frame_id).lstrip("/"),
        pose_to_matrix(t, q),
    )


def frame_path(adj: dict[str, set[str]], target: str, source: str) -> list[str] | None:
    """Frames on the shortest path ``target ... source`` through an undirected frame graph.

    Leading ``/`` is ignored; ``None`` when the two frames are not connected.
    """
    target, source = target.lstrip("/"), source.lstrip("/")
    if target == source:
        return [target]
    if target not in adj or source not in adj:
        return None
    prev: dict[str, str | None] = {target: None}
    queue = deque([target])
    while queue:
        f = queue.popleft()
        if f == source:
            break
        for g in sorted(adj[f]):
            if g not in prev:
                prev[g] = f
                queue.append(g)
    if source not in prev:
        return None
    path = [source]
    while prev[path[-1]] is not None:
        path.append(prev[path[-1]])  # type: ignore[arg-type]
    path.reverse()
    return path


class StaticTfTree:
    """Frames and the static transforms between them."""

    def __init__(self) -> None:
        self._edges: dict[tuple[str, str], np.ndarray] = {}
        self._adj: dict[str, set[str]] = {}

    @property
    def frames(self) -> set[str]:
        return set(self._adj)

    def add(self, parent: str, child: str, T_parent_child: np.ndarray) -> None:
        """Add (or replace) one edge."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        self._edges[(parent, child)] = np.asarray(T_parent_child, dtype=np.float64)
        self._adj.setdefault(parent, set()).add(child)
        self._adj.setdefault(child, set()).add(parent)

    def add_message(self, msg: Any) -> int:
        """Add every transform of a ``TFMessage``; returns how many."""
        n = 0
        for ts in msg.transforms:
            parent, child, T = _transform_of(ts)
            self.add(parent, child, T)
            n += 1
        return n

    def lookup(self, target: str, source: str) -> np.ndarray | None:
        """``T_target_source`` composed along the tree, or ``None`` when not connected."""
        path = frame_path(self._adj, target, source)
        if path is None:
            return None
        T = np.eye(4)
        for a, b in zip(path[:-1], path[1:], strict=True):
            if (a, b) in self._edges:
                T = T @ self._edges[(a, b)]
            else:
                T = T @ np.linalg.inv(self._edges[(b, a)])
        return T

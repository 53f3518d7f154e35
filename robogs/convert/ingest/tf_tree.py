"""Static transform tree from ``/tf_static`` (tf2_msgs/TFMessage).

Each ``TransformStamped`` gives ``T_parent_child`` (``header.frame_id`` = parent,
``child_frame_id`` = child; ROS quaternions are ``(x, y, z, w)``). :meth:`StaticTfTree.lookup`
composes the chain between two frames, walking edges in either direction.
"""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

__all__ = [
    "StaticTfTree",
    "frame_path",
    "pose_to_matrix",
    "matrix_to_pose",
    "quat_to_matrix_np",
    "matrix_to_quat_np",
]


def quat_to_matrix_np(q_wxyz: np.ndarray) -> np.ndarray:
    """[3, 3] rotation of a quaternion (w, x, y, z), normalised first.

    A numpy twin of :func:`robogs.format.frames.quat_to_matrix`, so that ingest does not load
    torch (the tests check that both agree).
    """
    q = np.asarray(q_wxyz, dtype=np.float64)
    n = float(np.linalg.norm(q))
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError("zero or non-finite quaternion")
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quat_np(R: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z), ``w >= 0``, of a [3, 3] rotation (Shepperd 1978: largest pivot).

    A numpy twin of :func:`robogs.format.frames.matrix_to_quat`.
    """
    R = np.asarray(R, dtype=np.float64)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    pivots = (1 + tr, 1 + 2 * R[0, 0] - tr, 1 + 2 * R[1, 1] - tr, 1 + 2 * R[2, 2] - tr)
    k = int(np.argmax(pivots))
    if k == 0:
        q = np.array([1 + tr, R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    elif k == 1:
        q = np.array(
            [R[2, 1] - R[1, 2], 1 + 2 * R[0, 0] - tr, R[0, 1] + R[1, 0], R[0, 2] + R[2, 0]]
        )
    elif k == 2:
        q = np.array(
            [R[0, 2] - R[2, 0], R[0, 1] + R[1, 0], 1 + 2 * R[1, 1] - tr, R[1, 2] + R[2, 1]]
        )
    else:
        q = np.array(
            [R[1, 0] - R[0, 1], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1], 1 + 2 * R[2, 2] - tr]
        )
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def pose_to_matrix(t: np.ndarray, q_wxyz: np.ndarray) -> np.ndarray:
    """[4, 4] transform from a translation [3] (m) and a quaternion [4] (w, x, y, z)."""
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

"""Named frames (spec 1.1.0, FORMAT.md §5.2): frames fixed to a robot link, kept from the source.

``manifest.robot.frames`` maps a frame name to ``{parent, T_parent_frame, source}``: ``parent``
is a URDF link or another named frame, ``T_parent_frame`` the 4x4 rigid transform mapping
coordinates in the frame to its parent (metres), ``source`` where it came from (``/tf_static``).
A converter keeps the static TF frames that hang from robot links this way (e.g. ``tool0 ->
pusher_tip``), so the physics loop can use them as pusher points and wrench frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from robogs.format.errors import FormatError

__all__ = ["NamedFrame", "read_named_frames", "frame_in_link", "add_named_frames", "ROT_TOL"]

ROT_TOL = 1e-6
"""Largest |R^T R - I| entry and |det R - 1| accepted for a named frame's rotation."""


@dataclass(frozen=True)
class NamedFrame:
    """One named frame: its ``parent`` and ``T_parent_frame`` [4, 4] (m), and its ``source``."""

    name: str
    parent: str
    T_parent_frame: np.ndarray
    source: str = ""


def _check(name: str, entry: Any, path: Any) -> NamedFrame:
    where = f"robot/frames/{name}"
    if not isinstance(entry, dict) or not isinstance(entry.get("parent"), str):
        raise FormatError("a named frame needs a parent", path=path, where=where)
    try:
        T = np.asarray(entry.get("T_parent_frame"), dtype=float)
    except (TypeError, ValueError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise FormatError("T_parent_frame must be a finite 4x4 matrix", path=path, where=where)
    R = T[:3, :3]
    off = max(float(np.abs(R.T @ R - np.eye(3)).max()), abs(float(np.linalg.det(R)) - 1.0))
    if off > ROT_TOL or not np.allclose(T[3], [0, 0, 0, 1], atol=ROT_TOL):
        raise FormatError(
            f"T_parent_frame is not a rigid transform (rotation off by {off:.1e})",
            path=path,
            where=where,
            hint="write a proper rotation and the last row 0 0 0 1",
        )
    if entry["parent"] == name:
        raise FormatError("a named frame cannot be its own parent", path=path, where=where)
    return NamedFrame(name, entry["parent"], T, str(entry.get("source", "")))


def read_named_frames(manifest: dict[str, Any], path: Any = None) -> dict[str, NamedFrame]:
    """The checked named frames of a manifest (empty for datasets without them)."""
    frames = (manifest.get("robot") or {}).get("frames") or {}
    return {name: _check(name, e, path) for name, e in sorted(frames.items())}


def frame_in_link(
    frames: dict[str, NamedFrame], name: str, links: set[str] | None = None
) -> tuple[str, np.ndarray]:
    """The robot link a named frame is fixed to and ``T_link_frame`` [4, 4], composed through
    named parents. A name that is a link itself gives (name, I).

    Raises:
        FormatError: a cycle, or a chain that ends neither at a known link nor at a named frame.
    """
    T = np.eye(4)
    seen: list[str] = []
    cur = name
    while cur in frames and (links is None or cur not in links):
        if cur in seen:
            raise FormatError(
                f"named frames form a cycle: {' -> '.join([*seen, cur])}",
                where=f"robot/frames/{name}",
            )
        seen.append(cur)
        f = frames[cur]
        T = f.T_parent_frame @ T
        cur = f.parent
    if links is not None and cur not in links:
        raise FormatError(
            f"named frame {name!r} hangs from {cur!r}, which is not a robot link",
            where=f"robot/frames/{name}",
            hint="a named frame's parent must be a URDF link or another named frame",
        )
    return cur, T


def add_named_frames(manifest: dict[str, Any], frames: dict[str, NamedFrame]) -> None:
    """Store ``frames`` in ``manifest['robot']['frames']`` (a robot entry without its ``urdf``
    yet is valid only until the writer attaches the URDF)."""
    robot = dict(manifest.get("robot") or {})
    out = dict(robot.get("frames") or {})
    for name, f in sorted(frames.items()):
        entry: dict[str, Any] = {
            "parent": f.parent,
            "T_parent_frame": np.asarray(f.T_parent_frame, dtype=float).tolist(),
        }
        if f.source:
            entry["source"] = f.source
        out[name] = entry
    robot["frames"] = out
    manifest["robot"] = robot

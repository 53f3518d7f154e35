"""Tracked objects and link paths of a dataset, sampled at the object-pose stamps.

An :class:`ObjectTrack` is one object's poses in one episode with windowed velocities and its
rest / moving masks; :func:`link_paths` gives every candidate link's pose at those stamps, by
forward kinematics of the measured joints (``robogs.format.kinematics.Chain``, joint values
interpolated linearly to the stamps and read by name, in any column order) or from the episode's
``ee_poses`` where that link is recorded.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ObjectTrack", "object_tracks", "link_paths", "WINDOW_S"]

WINDOW_S = 0.15
"""Time base of the windowed velocities [s]."""


@dataclass
class ObjectTrack:
    """One object in one episode (world frame, SI).

    Attributes:
        episode, name: episode id and object name.
        t_ns: [N] stamps; pos: [N, 3] m; R: [N, 3, 3] T_world_object rotation.
        vel: [N, 3] windowed velocity (m/s) over :data:`WINDOW_S`.
        sigma: position noise [m] (robust, from second differences).
        rest, moving: [N] masks (speed below / above noise-derived thresholds).
    """

    episode: str
    name: str
    t_ns: np.ndarray
    pos: np.ndarray
    R: np.ndarray
    vel: np.ndarray
    sigma: float
    rest: np.ndarray
    moving: np.ndarray

    @property
    def t(self) -> np.ndarray:
        """Seconds from the first stamp."""
        return (self.t_ns - self.t_ns[0]) * 1e-9


def windowed_velocity(t: np.ndarray, x: np.ndarray, window: float = WINDOW_S) -> np.ndarray:
    """(x(t + w/2) - x(t - w/2)) / w by linear interpolation, clamped at the ends [..., 3]."""
    lo = np.clip(t - 0.5 * window, t[0], t[-1])
    hi = np.clip(t + 0.5 * window, t[0], t[-1])
    span = np.maximum(hi - lo, 1e-9)
    out = np.empty_like(x)
    for a in range(x.shape[1]):
        out[:, a] = (np.interp(hi, t, x[:, a]) - np.interp(lo, t, x[:, a])) / span
    return out


def _noise(pos: np.ndarray) -> float:
    """Robust white-noise sigma [m]: Var(x[i+1] - 2 x[i] + x[i-1]) = 6 sigma^2."""
    if len(pos) < 5:
        return 0.0
    d2 = pos[2:] - 2 * pos[1:-1] + pos[:-2]
    mad = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return float(np.median(mad) / np.sqrt(6.0))


def object_tracks(ds: Any) -> list[ObjectTrack]:
    """Every (episode, object) of the dataset's ``object_poses`` streams with >= 5 samples."""
    from robogs.format.frames import quat_to_matrix

    out: list[ObjectTrack] = []
    for ep in ds.episodes:
        if not ep.has("object_poses"):
            continue
        tab = ep.table("object_poses")
        names = tab.column("object").to_numpy(zero_copy_only=False)
        t_all = tab.column("t_ns").to_numpy().astype(np.int64)
        cols = {
            c: tab.column(c).to_numpy().astype(float)
            for c in ("x", "y", "z", "qw", "qx", "qy", "qz")
        }
        for name in sorted(set(names.tolist())):
            sel = names == name
            t_ns = t_all[sel]
            if len(t_ns) < 5:
                continue
            order = np.argsort(t_ns, kind="stable")
            t_ns = t_ns[order]
            pos = np.stack([cols[c][sel][order] for c in ("x", "y", "z")], axis=1)
            q = np.stack([cols[c][sel][order] for c in ("qw", "qx", "qy", "qz")], axis=1)
            good = np.isfinite(pos).all(axis=1) & np.isfinite(q).all(axis=1)
            t_ns, pos, q = t_ns[good], pos[good], q[good]
            q = q / np.linalg.norm(q, axis=1, keepdims=True)
            t = (t_ns - t_ns[0]) * 1e-9
            vel = windowed_velocity(t, pos)
            sigma = _noise(pos)
            v_noise = np.sqrt(2.0) * sigma / WINDOW_S
            speed = np.linalg.norm(vel, axis=1)
            out.append(
                ObjectTrack(
                    ep.id,
                    str(name),
                    t_ns,
                    pos,
                    np.asarray(quat_to_matrix(q)),
                    vel,
                    sigma,
                    rest=speed < max(0.004, 3.0 * v_noise),
                    moving=speed > max(0.008, 5.0 * v_noise),
                )
            )
    return out


def _interp_rows(t: np.ndarray, tq: np.ndarray, x: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, tq, x[:, j]) for j in range(x.shape[1])], axis=1)


def link_paths(
    ds: Any, ep_id: str, t_ns: np.ndarray, chain: Any | None, links: list[str]
) -> dict[str, tuple[np.ndarray, np.ndarray, str]]:
    """Pose of each link in ``links`` at stamps ``t_ns`` of episode ``ep_id``.

    Returns:
        link -> (positions [N, 3] m, rotations [N, 3, 3], how: ``ee_poses`` or ``FK``); a link
        with neither a recorded pose nor the joints to compute it is left out.
    """

    from robogs.format.frames import quat_to_matrix

    ep = ds.episode(ep_id)
    out: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
    if ep.has("ee_poses"):
        tab = ep.table("ee_poses")
        names = tab.column("link").to_numpy(zero_copy_only=False)
        te_all = tab.column("t_ns").to_numpy().astype(np.int64)
        for link in links:
            sel = names == link
            if sel.sum() < 2:
                continue
            te = te_all[sel]
            p = np.stack([tab.column(c).to_numpy()[sel].astype(float) for c in "xyz"], 1)
            q = np.stack(
                [tab.column(c).to_numpy()[sel].astype(float) for c in ("qw", "qx", "qy", "qz")], 1
            )
            i = np.clip(np.searchsorted(te, t_ns), 0, len(te) - 1)  # nearest-after rotation
            R = np.asarray(quat_to_matrix(q[i] / np.linalg.norm(q[i], axis=1, keepdims=True)))
            out[link] = (_interp_rows(t_ns, te, p), R, "ee_poses")
    rest = [lk for lk in links if lk not in out]
    if not rest or chain is None or not ep.has("joint_states"):
        return out
    from robogs.physics.recording import link_frames

    _, T = link_frames(ds, ep, chain, t_query=t_ns)  # [N, L, 4, 4] in the base frame
    for link in rest:
        if link in chain.link_names:
            Tl = T[:, chain.link_index(link)]
            out[link] = (Tl[:, :3, 3].copy(), Tl[:, :3, :3].copy(), "FK")
    return out

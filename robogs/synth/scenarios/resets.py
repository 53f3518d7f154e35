"""One long episode of several pushes with hand resets between them, as a user records it.

:func:`join_pushes` lays independent push trajectories (e.g. the ones
:func:`~robogs.synth.scenarios.make_scenario` simulates) end to end on one clock. Between two
pushes the end effector lifts by ``lift_m``, moves over and comes down behind the next start,
while the object is reset in one of three ways:

* ``gap`` - the tracker loses the object for ``gap_s`` (a hand covers it) and sees it again at
  the next push's start;
* ``teleport`` - the object rests ``rest_s`` where the push left it, then is at the next start
  from one sample to the next (a hand reset faster than the tracker's rate);
* ``rest`` - no reset: the next push is turned and moved rigidly (about z) so that it starts
  where the previous one ended, after ``rest_s`` of rest.

Rest samples carry Gaussian noise of ``sigma_m`` (and are stamped at the push's median rate).
Nothing here reads the physics model or the physics loop's cutting code; the truth (the object
sample stamps of every push) is returned for the tests.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

__all__ = ["JoinedSession", "join_pushes", "write_session"]


@dataclass
class JoinedSession:
    """The joined episode (a trajectory-like object) and, per push, its object-sample stamps
    in the joined episode [int64 ns]; ``joins[k]`` is how push k+1 follows push k."""

    trajectory: Any
    pushes: list[Any]
    push_t_ns: list[np.ndarray]
    joins: list[str]


def _yaw_quat(yaw: float) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = (a[..., i] for i in range(4))
    bw, bx, by, bz = (b[..., i] for i in range(4))
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def _yaw(q: np.ndarray) -> float:
    w, x, y, z = q
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _moved(tr: Any, to_pos: np.ndarray, to_yaw: float) -> Any:
    """``tr`` turned about z and shifted so that its first object pose is (to_pos, to_yaw)."""
    dyaw = to_yaw - _yaw(tr.object_quat[0])
    c, s = np.cos(dyaw), np.sin(dyaw)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    p0 = tr.object_pos[0].copy()
    shift = np.array([to_pos[0], to_pos[1], p0[2]])
    q = _yaw_quat(dyaw)
    return replace(
        tr,
        object_pos=(tr.object_pos - p0) @ R.T + shift,
        object_quat=_qmul(q, tr.object_quat),
        ee_pos=(tr.ee_pos - p0) @ R.T + shift,
        ee_quat=_qmul(q, tr.ee_quat),
    )


def _shift(tr: Any, dt_ns: int) -> Any:
    return replace(tr, t_ns=tr.t_ns + dt_ns, ee_t_ns=tr.ee_t_ns + dt_ns)


def join_pushes(
    pushes: list[Any],
    joins: list[str],
    *,
    gap_s: float = 2.0,
    rest_s: float = 1.0,
    lift_m: float = 0.12,
    sigma_m: float = 1e-3,
    seed: int = 0,
) -> JoinedSession:
    """Join ``pushes`` (objects with ``t_ns, object_pos, object_quat, ee_t_ns, ee_pos,
    ee_quat, grasp``) into one episode; ``joins[k]`` in {gap, teleport, rest} follows push k."""
    if len(joins) != len(pushes) - 1 or not set(joins) <= {"gap", "teleport", "rest"}:
        raise ValueError("joins: one of gap, teleport, rest between each two pushes")
    rng = np.random.default_rng(seed)
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("t", "p", "q", "et", "ep", "eq", "g")}
    placed: list[Any] = []
    stamps: list[np.ndarray] = []
    t_end = 0
    for k, tr in enumerate(pushes):
        if k > 0 and joins[k - 1] == "rest":
            prev = placed[-1]
            tr = _moved(tr, prev.object_pos[-1], _yaw(prev.object_quat[-1]))
        t_first = int(min(tr.t_ns[0], tr.ee_t_ns[0]))
        if k == 0:
            tr = _shift(tr, -t_first)
        else:
            prev, how = placed[-1], joins[k - 1]
            dt_obj = int(np.median(np.diff(prev.t_ns)))
            pause_s = gap_s if how == "gap" else rest_s
            start = t_end + int(pause_s * 1e9)
            tr = _shift(tr, start - t_first)
            if how != "gap":  # the object rests where the push left it, seen by the tracker
                tt = np.arange(int(prev.t_ns[-1]) + dt_obj, int(tr.t_ns[0]) - dt_obj // 2, dt_obj)
                rest = prev.object_pos[-1] + sigma_m * rng.standard_normal((len(tt), 3))
                cols["t"].append(tt)
                cols["p"].append(rest)
                cols["q"].append(np.repeat(prev.object_quat[-1][None], len(tt), 0))
            # the end effector lifts, moves over and comes down behind the next start
            dt_ee = int(np.median(np.diff(prev.ee_t_ns)))
            te = np.arange(int(prev.ee_t_ns[-1]) + dt_ee, int(tr.ee_t_ns[0]), dt_ee)
            u = (te - te[0]) / max(1, te[-1] - te[0])
            a, b = prev.ee_pos[-1], tr.ee_pos[0]
            path = a + np.clip(3 * u - 1, 0, 1)[:, None] * (b - a)
            path[:, 2] += lift_m * np.clip(np.minimum(3 * u, 3 - 3 * u), 0, 1)
            cols["et"].append(te)
            cols["ep"].append(path)
            cols["eq"].append(np.repeat(prev.ee_quat[-1][None], len(te), 0))
            cols["g"].append(np.zeros(len(te), bool))
        placed.append(tr)
        stamps.append(np.asarray(tr.t_ns, np.int64))
        for key, arr in zip(
            ("t", "p", "q", "et", "ep", "eq", "g"),
            (tr.t_ns, tr.object_pos, tr.object_quat, tr.ee_t_ns, tr.ee_pos, tr.ee_quat, tr.grasp),
            strict=True,
        ):
            cols[key].append(np.asarray(arr))
        t_end = int(max(tr.t_ns[-1], tr.ee_t_ns[-1]))
    order = np.argsort(np.concatenate(cols["t"]), kind="stable")
    eorder = np.argsort(np.concatenate(cols["et"]), kind="stable")
    joined = replace(
        pushes[0],
        name="session",
        t_ns=np.concatenate(cols["t"])[order].astype(np.int64),
        object_pos=np.concatenate(cols["p"])[order],
        object_quat=np.concatenate(cols["q"])[order],
        ee_t_ns=np.concatenate(cols["et"])[eorder].astype(np.int64),
        ee_pos=np.concatenate(cols["ep"])[eorder],
        ee_quat=np.concatenate(cols["eq"])[eorder],
        grasp=np.concatenate(cols["g"])[eorder],
    )
    return JoinedSession(joined, placed, stamps, list(joins))


def write_session(recording: Any, trajectories: list[Any], out_path: Any) -> Any:
    """Write ``trajectories`` (one episode each) with ``recording``'s physics and object name
    through :func:`~robogs.synth.scenarios.write.write_scenario`; return the ``Dataset``."""
    from robogs.synth.scenarios.write import write_scenario

    return write_scenario(replace(recording, trajectories=list(trajectories), meta={}), out_path)

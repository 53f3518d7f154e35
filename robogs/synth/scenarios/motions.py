"""End-effector motions of the scenarios: pushes, off-centre pushes, release-and-slide,
grasp-lift-place.

Every motion is a list of samples on a fine grid (``dt`` s) of the EE (pusher-sphere centre)
position, its yaw and the grasp flag, plus the initial box pose. Velocity profiles are
trapezoids (pushes, slides) or minimum-jerk moves (pick and place), integrated numerically.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.synth.scenarios.sim import TruthBox

__all__ = ["Motion", "push", "offset_push", "release_slide", "grasp_place"]


@dataclass
class Motion:
    """One EE motion: positions [K, 3] m, yaw [K] rad, grasp [K] bool, box start pose."""

    kind: str
    name: str
    pos: np.ndarray
    yaw: np.ndarray
    grasp: np.ndarray
    box_xy: np.ndarray
    box_yaw: float


def _trapezoid(
    dt: float, hold: float, v: float, a_up: float, dist: float, a_dn: float, tail: float
) -> np.ndarray:
    """Travelled distance [K] for hold / accelerate / cruise to ``dist`` / brake / hold."""
    vel = [np.zeros(int(round(hold / dt)))]
    n_up = max(1, int(round(v / a_up / dt)))
    vel.append(np.linspace(0.0, v, n_up, endpoint=False) + 0.5 * v / n_up)
    d_up = float(np.sum(vel[-1]) * dt)
    n_dn = max(1, int(round(v / a_dn / dt)))
    ramp_dn = np.linspace(v, 0.0, n_dn, endpoint=False) - 0.5 * v / n_dn
    d_dn = float(np.sum(ramp_dn) * dt)
    n_cr = max(0, int(round((dist - d_up - d_dn) / (v * dt))))
    vel.append(np.full(n_cr, v))
    vel.append(ramp_dn)
    vel.append(np.zeros(int(round(tail / dt))))
    v_all = np.concatenate(vel)
    # jerk limit: a 30 ms moving average turns the trapezoid into an S-curve (real arms)
    n_box = max(1, int(round(0.03 / dt)))
    v_all = np.convolve(np.concatenate([v_all, np.zeros(n_box)]), np.ones(n_box) / n_box)[
        : len(v_all) + n_box
    ]
    return np.concatenate([[0.0], np.cumsum(v_all) * dt])


def _min_jerk(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, max(n, 2))
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    return a[None] + (b - a)[None] * s[:, None]


def push(
    box: TruthBox,
    dt: float,
    heading: float,
    speed: float,
    offset: float,
    name: str,
    contact: float = 0.045,
) -> Motion:
    """Push along ``heading`` [rad] at ``speed`` [m/s], ``offset`` [m] off the centre line.

    The box's x axis faces the push. The pusher brakes at 12 m/s^2 after ``contact`` m of
    contact, faster than friction stops the box, so the box leaves it and slides. The contact
    lasts long enough (45 mm) for the box to settle against the pusher after the first hit, so
    the release speed is the pusher's.
    """
    hx, hz = 0.5 * box.size[0], 0.5 * box.size[2]
    d = np.array([np.cos(heading), np.sin(heading)])
    perp = np.array([-d[1], d[0]])
    gap0 = 0.03
    box_xy = np.array([0.5, 0.0])
    start = box_xy - d * (hx + box.pusher_radius + gap0) + perp * offset
    tail = 0.5 + speed / (box.mu_d * box.gravity)
    s = _trapezoid(dt, 0.3, speed, 8.0, gap0 + contact, 12.0, tail)
    xy = start[None] + s[:, None] * d[None]
    pos = np.column_stack([xy, np.full(len(s), box.table_z + hz)])
    return Motion(
        "push", name, pos, np.full(len(s), heading), np.zeros(len(s), bool), box_xy, heading
    )


def offset_push(
    box: TruthBox,
    dt: float,
    heading: float,
    speed: float,
    face: str,
    side: float,
    name: str,
    contact: float = 0.02,
) -> Motion:
    """Push one box face far off its centre line, so that only one end of the capsule touches
    it (a point push): the box turns, at a rate set by the lever arm about its centre of mass.

    Args:
        face: ``"x"`` pushes the face normal to the box x axis, ``"y"`` the face normal to y.
        side: +1 or -1, the side of the centre line the touching capsule end is on.
        contact: pushed distance [m] before the pusher brakes.
    """
    hz = 0.5 * box.size[2]
    depth, width = (box.size[0], box.size[1]) if face == "x" else (box.size[1], box.size[0])
    half_len = 0.5 * box.pusher_length
    # touching end at half the face half-width off centre; the other end clears the corner
    lateral = side * (0.5 * (0.5 * width) + half_len)
    d = np.array([np.cos(heading), np.sin(heading)])
    perp = np.array([-d[1], d[0]])
    gap0 = 0.02
    box_xy = np.array([0.5, 0.0])
    start = box_xy - d * (0.5 * depth + box.pusher_radius + gap0) + perp * lateral
    tail = 0.5 + speed / (box.mu_d * box.gravity)
    s = _trapezoid(dt, 0.3, speed, 6.0, gap0 + contact, 10.0, tail)
    xy = start[None] + s[:, None] * d[None]
    pos = np.column_stack([xy, np.full(len(s), box.table_z + hz)])
    box_yaw = heading if face == "x" else heading - 0.5 * np.pi
    return Motion(
        "offset_push", name, pos, np.full(len(s), heading), np.zeros(len(s), bool), box_xy, box_yaw
    )


def release_slide(box: TruthBox, dt: float, heading: float, speed: float, name: str) -> Motion:
    """Lift the box 4 mm, carry it along ``heading`` and release it at ``speed``: it drops onto
    the table (a small impact) and slides."""
    hz = 0.5 * box.size[2]
    d = np.array([np.cos(heading), np.sin(heading)])
    box_xy = np.array([0.45, 0.05])
    lift = 0.004
    # accelerate at 4 m/s^2, cruise 5 cm (released 2 cm into it), brake at 3 m/s^2
    s = _trapezoid(dt, 0.3, speed, 4.0, speed**2 / 8.0 + 0.05 + speed**2 / 6.0, 3.0, 0.55)
    n_rel = int(np.argmax(s >= speed**2 / 8.0 + 0.02))  # inside the cruise
    grasp = np.zeros(len(s), bool)
    grasp[:n_rel] = True
    xy = box_xy[None] + s[:, None] * d[None]
    t_all = np.arange(len(s)) * dt
    z = (
        box.table_z
        + 2 * hz
        + box.pusher_radius
        + 0.002
        + lift * np.clip((t_all - 0.1) / 0.1, 0.0, 1.0)
    )
    t_after = np.arange(len(s) - n_rel) * dt - 0.04  # the gripper opens, then retracts
    z[n_rel:] += np.clip(0.5 * t_after, 0.0, 0.05)
    pos = np.column_stack([xy, z])
    return Motion("release_slide", name, pos, np.full(len(s), heading), grasp, box_xy, heading)


def grasp_place(box: TruthBox, dt: float, heading: float, drop: float, name: str) -> Motion:
    """Descend, grasp, lift 4 cm, carry 8 cm along ``heading``, release ``drop`` m above the
    table (an impact), retreat upwards."""
    hz = 0.5 * box.size[2]
    box_xy = np.array([0.55, -0.05])
    top = box.table_z + 2 * hz + box.pusher_radius + 0.002
    d = np.array([np.cos(heading), np.sin(heading), 0.0])
    p0 = np.array([box_xy[0], box_xy[1], top + 0.06])
    pg = np.array([box_xy[0], box_xy[1], top])
    pl = pg + np.array([0, 0, 0.04])
    pm = pl + 0.08 * d
    pr = pm - np.array([0, 0, 0.04 - drop])
    pu = pr + np.array([0, 0, 0.05])
    n = lambda t: int(round(t / dt))  # noqa: E731
    parts = [
        np.repeat(p0[None], n(0.2), 0),
        _min_jerk(p0, pg, n(0.25)),
        np.repeat(pg[None], n(0.05), 0),
        _min_jerk(pg, pl, n(0.2)),
        _min_jerk(pl, pm, n(0.3)),
        _min_jerk(pm, pr, n(0.15)),
        np.repeat(pr[None], n(0.05), 0),
        _min_jerk(pr, pu, n(0.2)),
        np.repeat(pu[None], n(0.45), 0),
    ]
    pos = np.concatenate(parts)
    lens = np.cumsum([len(p) for p in parts])
    grasp = np.zeros(len(pos), bool)
    grasp[lens[1] : lens[6]] = True
    return Motion("grasp_place", name, pos, np.full(len(pos), heading), grasp, box_xy, heading)

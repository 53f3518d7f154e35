"""Two boxes in one scene: a pusher drives box A face-on into box B along a line.

An independent numpy generator (no ``robogs.physics``, no MuJoCo) of a one-dimensional chain:
a kinematic pusher (sphere of radius ``r``), box A, box B, aligned on the pushing line, both on
the table with Coulomb friction (``mu_a``, ``mu_b``; the boxes' faces touch flat, so the
motion stays on the line and nothing turns). Per fine step (0.1 ms), sequential impulses:

1. table friction slows each sliding box by ``mu g dt`` (never past rest);
2. the pusher is kinematic (infinite mass): a pusher touching A and faster sets A to its speed;
3. box-box contact: a closing A meets B with restitution ``e`` (default 0, perfectly plastic).
   A driven by the pusher is an infinite mass (B leaves at ``v_a + e (v_a - v_b)``), a free
   A shares momentum with B; the pusher's impulse is what A and, through a driven A, B took;

then positions advance and any overlap is removed by moving the box ahead. The pusher's
motion: rest out of contact, approach A, accelerate (cosine ramp, :data:`RAMP_S`) to the push
speed, hold it, then brake at :data:`BRAKE` (faster than table friction stops the boxes), so the
boxes slide on alone: A stops after ``v^2 / (2 mu_a g)``, B, with ``mu_b < mu_a``, separates
and slides ``v^2 / (2 mu_b g)``. Box A starts a gap ``gap`` [m] behind B, so the pusher drives A
into B at the push speed (an impact).

The sensor reads the force the boxes exert on the pusher (world axes, offset, noise), as in
:mod:`robogs.synth.scenarios.force_push`: ``(mu_a m_a + mu_b m_b) g`` while pushing both.

Measurement: both boxes' poses at 30 Hz (one camera clock), tool at 500 Hz, wrench at 250 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.synth.scenarios.force_push import ForcePushTrajectory
from robogs.synth.scenarios.generate import ScenarioRecording, _quat_yaw

__all__ = [
    "PUSHES",
    "ChainTruth",
    "TwoBoxTruth",
    "TwoObjectTrajectory",
    "make_two_objects",
    "push_chain",
    "write_two_objects",
]

G = 9.81
FINE_DT = 1e-4
BRAKE = 10.0
"""Deceleration of the pusher at the end of a push [m/s^2] (friction brakes a box at mu g)."""
RAMP_S = 0.1
"""Speed ramp of the pusher at the start of a push [s]."""


@dataclass(frozen=True)
class TwoBoxTruth:
    """True scene: edges [m] and masses [kg] of boxes A and B, their table friction, the
    restitution of the box-box contact, the initial gap A-B [m], the pusher sphere (radius,
    centre height above the table [m]), table height [m], sensor offset [N] and noise."""

    size_a: tuple[float, float, float] = (0.06, 0.06, 0.05)
    size_b: tuple[float, float, float] = (0.08, 0.06, 0.05)
    mass_a: float = 0.35
    mass_b: float = 0.5
    mu_a: float = 0.45
    mu_b: float = 0.25
    restitution: float = 0.0
    gap: float = 0.01
    pusher_radius: float = 0.01
    pusher_height: float = 0.02
    table_z: float = 0.0
    sensor_offset: tuple[float, float, float] = (0.2, -0.1, -1.5)
    sigma_pos: float = 5e-4
    sigma_rot: float = float(np.radians(0.3))
    sigma_ee: float = 6e-5
    sigma_force: float = 0.03


@dataclass
class ChainTruth:
    """Fine-step truth of one push along the line: times [K] s, pusher centre, box A and box B
    centre coordinates along the line [K] m (from the pusher's start), box speeds [K] m/s, and
    the force the boxes exert on the pusher along the line [K] N (<= 0)."""

    t: np.ndarray
    pusher: np.ndarray
    a: np.ndarray
    b: np.ndarray
    v_a: np.ndarray
    v_b: np.ndarray
    force: np.ndarray


def push_chain(truth: TwoBoxTruth, speed: float, dist: float, *, dt: float = FINE_DT) -> ChainTruth:
    """Simulate one push: the pusher (centre at 0, 2 cm behind A's face) rests 0.3 s, moves
    ``dist`` [m] at up to ``speed`` [m/s] along +s (ramp :data:`RAMP_S`, then brakes at
    :data:`BRAKE`), and everything rests 0.5 s after the last box stops."""
    ha, hb = 0.5 * truth.size_a[0], 0.5 * truth.size_b[0]
    r, e = truth.pusher_radius, truth.restitution
    ma, mb = truth.mass_a, truth.mass_b
    sa = 0.02 + r + ha  # A's centre: its back face 2 cm ahead of the pusher's surface
    sb = sa + ha + truth.gap + hb
    va = vb = 0.0
    sp = vp = 0.0
    t_rest = 0.3
    braking = False
    ts, ps, as_, bs, vas, vbs, fs = [], [], [], [], [], [], []
    stop_at = None
    k = 0
    while True:
        t = k * dt
        # pusher kinematics: rest, ramp, cruise to dist, brake
        if t >= t_rest and not braking:
            vp = speed * min(1.0, 0.5 - 0.5 * np.cos(np.pi * min((t - t_rest) / RAMP_S, 1.0)))
            if sp + vp * vp / (2 * BRAKE) >= dist:
                braking = True
        if braking:
            vp = max(vp - BRAKE * dt, 0.0)
        # 1. table friction
        va = max(va - truth.mu_a * G * dt, 0.0)
        vb = max(vb - truth.mu_b * G * dt, 0.0)
        # 2. kinematic pusher on A
        imp = 0.0
        driven = sa - ha - (sp + r) <= 1e-12 and vp >= va
        if driven and vp > va:
            imp += ma * (vp - va)
            va = vp
        # 3. box-box contact (closing and touching): a driven A is an infinite mass
        if sb - sa <= ha + hb + 1e-12 and va > vb:
            if driven:
                nb = va + e * (va - vb)
                imp += mb * (nb - vb)
                vb = nb
            else:
                vc = (ma * va + mb * vb) / (ma + mb)
                va, vb = vc - e * mb / (ma + mb) * (va - vb), vc + e * ma / (ma + mb) * (va - vb)
        # advance, remove overlaps (the box ahead moves)
        sp += vp * dt
        sa += va * dt
        sb += vb * dt
        sa = max(sa, sp + r + ha)
        sb = max(sb, sa + ha + hb)
        ts.append(t)
        ps.append(sp)
        as_.append(sa)
        bs.append(sb)
        vas.append(va)
        vbs.append(vb)
        fs.append(-imp / dt)
        if braking and vp == 0 and va == 0 and vb == 0 and stop_at is None:
            stop_at = t
        if stop_at is not None and t > stop_at + 0.5:
            break
        k += 1
    return ChainTruth(*(np.asarray(x) for x in (ts, ps, as_, bs, vas, vbs, fs)))


@dataclass(kw_only=True)
class TwoObjectTrajectory(ForcePushTrajectory):
    """A push measured like :class:`ForcePushTrajectory` (``object_*``: box A), plus box B's
    poses at the same camera stamps (``other_pos`` [N, 3] m, ``other_quat`` [N, 4] w x y z),
    also as ``others`` (``{"box_b": (t_ns, pos, quat)}``: the tracked-object form a recording
    and the scenario writer read)."""

    other_pos: np.ndarray
    other_quat: np.ndarray
    kind: str = "two_objects"

    @property
    def others(self) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
        return {"box_b": (self.t_ns, self.other_pos, self.other_quat)}


PUSHES = ((0.25, 0.06), (0.35, 0.07), (0.45, 0.08))
"""(push speed [m/s], pusher travel [m]) of the default pushes."""


def make_two_objects(
    *,
    seed: int = 0,
    noise: bool = True,
    truth: TwoBoxTruth | None = None,
    pushes: tuple[tuple[float, float], ...] = PUSHES,
    nominal: tuple[float, float] = (0.35, 0.35),
) -> ScenarioRecording:
    """Pushes of box A into box B, measured.

    Args:
        seed: noise, the placement (line origin and heading, the same for every push) and the
            clock phases.
        noise: add measurement noise (else exact samples).
        truth: the true scene (default :class:`TwoBoxTruth`).
        pushes: (speed, travel) per push.
        nominal: (box A, box B) friction written in the nominal physics.json.

    Returns:
        A recording of box A (``object_name="box_a"``) whose trajectories also carry box B
        (:class:`TwoObjectTrajectory`); ``meta["truth"]`` the true values, ``meta["fine"]`` the
        fine truth per push (:class:`ChainTruth`), ``meta["start"]`` per push the world start
        poses of both boxes ``{name: [x, y, z, qw, qx, qy, qz]}`` and the line's origin and
        heading.
    """
    truth = truth or TwoBoxTruth()
    rng = np.random.default_rng(seed)
    k = 1.0 if noise else 0.0
    hz_a, hz_b = 0.5 * truth.size_a[2], 0.5 * truth.size_b[2]
    trajs, fine, starts = [], [], []
    t_base = 1_700_000_000_000_000_000
    # one placement for every push (the boxes are put back): a scene model holds the other
    # box at one pose
    heading = float(rng.uniform(-np.pi, np.pi))
    origin = np.array([0.4 + rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05)])
    d = np.array([np.cos(heading), np.sin(heading)])
    for i, (speed, dist) in enumerate(pushes):
        ch = push_chain(truth, speed, dist)
        fine.append(ch)
        t_end = float(ch.t[-1])
        to = np.arange(rng.uniform(0, 1 / 30), t_end, 1 / 30)
        te = np.arange(rng.uniform(0, 1 / 500), t_end, 1 / 500)
        tw = np.arange(rng.uniform(0, 1 / 250), t_end, 1 / 250)

        def on_line(s: np.ndarray, z: float, o: np.ndarray = origin, d: np.ndarray = d):
            return np.column_stack([o[0] + s * d[0], o[1] + s * d[1], np.full(len(s), z)])

        def quat(n: int) -> np.ndarray:
            rv = rng.normal(0.0, k * truth.sigma_rot, (n, 3))
            q = _quat_yaw(heading + rv[:, 2])
            q[:, 1:3] += 0.5 * rv[:, :2] * q[:, :1]
            return q / np.linalg.norm(q, axis=1, keepdims=True)

        pa = on_line(np.interp(to, ch.t, ch.a), truth.table_z + hz_a)
        pb = on_line(np.interp(to, ch.t, ch.b), truth.table_z + hz_b)
        pa += rng.normal(0.0, k * truth.sigma_pos, pa.shape)
        pb += rng.normal(0.0, k * truth.sigma_pos, pb.shape)
        ee = on_line(np.interp(te, ch.t, ch.pusher), truth.table_z + truth.pusher_height)
        ee += rng.normal(0.0, k * truth.sigma_ee, ee.shape)
        # force samples: the fine force averaged over each sample's 4 ms window
        box4 = np.ones(int(round(4e-3 / FINE_DT)))
        f_avg = np.convolve(ch.force, box4 / box4.size, "same")
        f = np.interp(tw, ch.t, f_avg)
        wrench = np.column_stack([f * d[0], f * d[1], 0 * f]) + np.asarray(truth.sensor_offset)
        wrench += rng.normal(0.0, k * truth.sigma_force, wrench.shape)
        t0 = t_base + i * 10_000_000_000
        trajs.append(
            TwoObjectTrajectory(
                name=f"chain{i}",
                t_ns=t0 + np.round(to * 1e9).astype(np.int64),
                object_pos=pa,
                object_quat=quat(len(to)),
                ee_t_ns=t0 + np.round(te * 1e9).astype(np.int64),
                ee_pos=ee,
                ee_quat=np.repeat(_quat_yaw(np.array(heading))[None], len(te), axis=0),
                grasp=np.zeros(len(te), dtype=bool),
                wrench_t_ns=t0 + np.round(tw * 1e9).astype(np.int64),
                wrench_force=wrench,
                wrench_tool=wrench,
                other_pos=pb,
                other_quat=quat(len(to)),
            )
        )
        q0 = list(_quat_yaw(np.array(heading)))
        starts.append(
            {
                "box_a": [*on_line(ch.a[:1], truth.table_z + hz_a)[0], *q0],
                "box_b": [*on_line(ch.b[:1], truth.table_z + hz_b)[0], *q0],
                "origin": list(origin),
                "heading": heading,
            }
        )

    def box(size, mass, mu):
        sx, sy, sz = size
        return {
            "equation": "rigid",
            "size_m": list(size),
            "mass_kg": mass,
            "com_m": [0.0, 0.0, 0.0],
            "inertia_kgm2": [
                [mass * (sy**2 + sz**2) / 12, 0.0, 0.0],
                [0.0, mass * (sx**2 + sz**2) / 12, 0.0],
                [0.0, 0.0, mass * (sx**2 + sy**2) / 12],
            ],
            "friction_static": float(mu),
            "friction_dynamic": float(mu),
        }

    physics = {
        "revision": 1,
        "gravity_mps2": [0.0, 0.0, -G],
        "objects": {
            "box_a": box(truth.size_a, truth.mass_a, nominal[0]),
            "box_b": box(truth.size_b, truth.mass_b, nominal[1]),
            "table": {"equation": "static", "plane_z_m": truth.table_z},
            "pusher": {"equation": "kinematic", "shape": "sphere", "radius_m": truth.pusher_radius},
        },
        "effects": [],
    }
    meta = {
        "truth": {
            "mu_a": truth.mu_a,
            "mu_b": truth.mu_b,
            "restitution": truth.restitution,
            "slide_a_m": [p[0] ** 2 / (2 * truth.mu_a * G) for p in pushes],
            "slide_b_m": [p[0] ** 2 / (2 * truth.mu_b * G) for p in pushes],
        },
        "fine": fine,
        "start": starts,
        "seed": seed,
    }
    return ScenarioRecording(trajs, physics, "box_a", meta)


def write_two_objects(
    recording: ScenarioRecording, out_path: str | Path, *, wrench: bool = False, **kw: Any
) -> Any:
    """Write :func:`make_two_objects`' recording as a dataset a user would have, through
    :func:`robogs.synth.scenarios.write.write_scenario` (both boxes in ``object_poses``, the
    pusher in ``ee_poses``; with ``wrench`` the pusher's force sensor as ``wrenches``, frame
    ``world``). The truth beside it keeps ``truth``, ``start`` and ``seed`` (the fine per-step
    chains are left out); returns the ``Dataset``."""
    from robogs.synth.scenarios.write import write_scenario

    meta = {k: v for k, v in recording.meta.items() if k != "fine"}
    return write_scenario(replace(recording, meta=meta), out_path, wrenches=wrench, **kw)

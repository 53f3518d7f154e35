"""Force-controlled pushes measured with a force-torque sensor at the tool (ground truth).

An independent numpy simulator (it shares no code with ``robogs.physics`` or ``robogs.convert``)
of the experiment that makes an object's mass identifiable: a flat pusher (a capsule of radius
``r`` and length ``L`` along the tool's y axis, centred at the tool origin) approaches a box
resting on a table, touches its -x face (odd pushes: its -y face) and then pushes it with a
commanded force

    F(t) = F_a * s(t) * (1 + 0.5 sin(2 pi t / T_p)),   0 <= t <= T_p,

(``s`` a 25 ms cosine ramp up and down) along the face normal, staying on the face while
``F > 0``. The box slides with Coulomb friction (static ``mu_s``, dynamic ``mu_d``): it moves
once ``F > mu_s m g`` and accelerates at ``F / m - mu_d g``. When the force ends the tool
brakes at ``BRAKE`` = 10 m/s^2 (harder than friction brakes the box), so the box slides on alone and stops.
The motion is along a line through the box centre: the box does not turn.

The poses do not depend on the mass given the tool's motion (a kinematic pusher), but the
force does: ``F = m (a + mu_d g)`` while sliding. So the hidden effect is a mass that differs
from the nominal one; the sensor reads the force the box exerts on the tool, in the tool frame,
plus a constant offset (the tool's weight below the sensor) and white noise.

Measurement: object poses at 30 Hz (camera clock with a random phase, 1 mm / 0.5 deg noise),
tool poses at 500 Hz (0.06 mm), wrench at 250 Hz (its own clock phase).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.synth.scenarios.generate import ScenarioRecording, ScenarioTrajectory, _quat_yaw

__all__ = ["ForcePushTrajectory", "ForcePushRecording", "ForcePushTruth", "make_force_push"]

G = 9.81
FINE_DT = 1e-4
BRAKE = 10.0
"""Deceleration of the tool when the force ends [m/s^2] (friction brakes the box at mu_d g)."""


@dataclass(frozen=True)
class ForcePushTruth:
    """True scene: box edges [m], mass [kg], friction, table height [m], pusher [m]."""

    size: tuple[float, float, float] = (0.08, 0.06, 0.05)
    mass: float = 0.52
    mu_s: float = 0.45
    mu_d: float = 0.35
    table_z: float = 0.0
    pusher_radius: float = 0.01
    pusher_length: float = 0.04
    sensor_offset: tuple[float, float, float] = (0.3, -0.2, -2.5)
    sigma_force: float = 0.05
    sigma_pos: float = 1e-3
    sigma_rot: float = float(np.radians(0.5))
    sigma_ee: float = 6e-5


@dataclass(kw_only=True)
class ForcePushTrajectory(ScenarioTrajectory):
    """One push, measured: a scenario trajectory plus the tool's force sensor.

    ``wrench_force`` is in world axes (N); ``wrench_tool`` the same samples in the tool frame.
    ``ee_pos`` is the pusher's centre (the tool origin).
    """

    wrench_t_ns: np.ndarray
    wrench_force: np.ndarray
    wrench_tool: np.ndarray
    kind: str = "force_push"


ForcePushRecording = ScenarioRecording
"""Trajectories, the nominal physics.json the tool starts from, and the truth in ``meta``."""


def _ramp(t: np.ndarray, dur: float, rise: float = 0.025) -> np.ndarray:
    up = 0.5 - 0.5 * np.cos(np.pi * np.clip(t / rise, 0.0, 1.0))
    down = 0.5 - 0.5 * np.cos(np.pi * np.clip((dur - t) / rise, 0.0, 1.0))
    return np.where((t >= 0) & (t <= dur), up * down, 0.0)


def _one_push(truth: ForcePushTruth, half: float, f_a: float, t_p: float) -> dict[str, np.ndarray]:
    """Fine-step truth of one push on a face ``half`` [m] from the box centre: times [K] s, box
    travel [K] m along the push, tool travel and the force the box exerts on the tool along the
    push direction [K] N (<= 0)."""
    hx = half
    standoff, t_wait, t_app, t_rest0 = 0.03, 0.3, 0.4, 0.2
    t_force0 = t_wait + t_app + t_rest0
    n_max = int(6.0 / FINE_DT)
    ts, xs, es, fs = [], [], [], []
    x = v = 0.0
    ve = 0.0
    contact_x = -(hx + truth.pusher_radius)  # tool centre touching the -x face, box frame
    e = contact_x - standoff
    braking = False
    stopped_at = None
    for k in range(n_max):
        t = k * FINE_DT
        f = 0.0
        if t < t_wait:
            e = contact_x - standoff
        elif t < t_wait + t_app:  # minimum-jerk approach to the face
            u = (t - t_wait) / t_app
            e = contact_x - standoff + standoff * (10 * u**3 - 15 * u**4 + 6 * u**5)
        elif t < t_force0:
            e = contact_x
        elif t <= t_force0 + t_p:
            tt = np.asarray(t - t_force0)
            f = float(f_a * _ramp(tt, t_p) * (1.0 + 0.5 * np.sin(2 * np.pi * tt / t_p)))
            stuck = v == 0.0 and f <= truth.mu_s * truth.mass * G
            if not stuck:
                v = max(v + FINE_DT * (f / truth.mass - truth.mu_d * G), 0.0)
                x += FINE_DT * v
            e = x + contact_x
            ve = v
        else:
            braking = True
        if braking:
            if v > 0.0:
                v = max(v - FINE_DT * truth.mu_d * G, 0.0)
                x += FINE_DT * v
            ve = max(ve - FINE_DT * BRAKE, 0.0)
            e = min(e + FINE_DT * ve, x + contact_x)
            if v == 0.0 and ve == 0.0 and stopped_at is None:
                stopped_at = t
        ts.append(t)
        xs.append(x)
        es.append(e)
        fs.append(-f)
        if stopped_at is not None and t > stopped_at + 0.6:
            break
    return {"t": np.array(ts), "x": np.array(xs), "e": np.array(es), "f": np.array(fs)}


def _sample_times(t_end: float, hz: float, rng: np.random.Generator) -> np.ndarray:
    return np.arange(rng.uniform(0.0, 1.0 / hz), t_end, 1.0 / hz)


def make_force_push(
    *,
    mass_true: float = 0.52,
    mass_nominal: float = 0.4,
    seed: int = 0,
    n_traj: int = 6,
    table_z: float = 0.0,
) -> ForcePushRecording:
    """Force-controlled pushes in ``n_traj`` directions at three force levels.

    Args:
        mass_true: the box's true mass [kg] (the hidden effect when it differs from nominal).
        mass_nominal: the mass written in the nominal physics [kg].
        seed: random seed of the noise, start poses and clock phases.
        n_traj: number of pushes.
        table_z: table height [m].
    """
    rng = np.random.default_rng(seed)
    truth = ForcePushTruth(mass=mass_true, table_z=table_z)
    hz = 0.5 * truth.size[2]
    trajs = []
    t_base = 1_700_000_000_000_000_000
    for i in range(n_traj):
        yaw = float(2 * np.pi * i / n_traj + rng.uniform(-0.2, 0.2))
        start = np.array([0.45 + rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05)])
        f_a = truth.mass * G * (truth.mu_s + 0.05 + 0.08 * (i % 3))
        t_p = 0.25 + 0.05 * (i % 2)
        y_face = i % 2 == 1  # odd pushes on the box's -y face (both extents are seen)
        sim = _one_push(truth, 0.5 * truth.size[1 if y_face else 0], f_a, t_p)
        box_yaw = yaw - 0.5 * np.pi if y_face else yaw
        d = np.array([np.cos(yaw), np.sin(yaw)])
        t_end = float(sim["t"][-1])

        def at(arr: np.ndarray, t: np.ndarray, sim: dict = sim) -> np.ndarray:
            return np.interp(t, sim["t"], arr)

        to = _sample_times(t_end, 30.0, rng)
        box = start[None] + at(sim["x"], to)[:, None] * d[None]
        obj_pos = np.column_stack([box, np.full(len(to), table_z + hz)])
        obj_pos += rng.normal(0.0, truth.sigma_pos, obj_pos.shape)
        rv = rng.normal(0.0, truth.sigma_rot, (len(to), 3))
        obj_quat = _quat_yaw(box_yaw + rv[:, 2])
        tilt = 0.5 * rv[:, :2]
        obj_quat[:, 1:3] += tilt * obj_quat[:, :1]
        obj_quat /= np.linalg.norm(obj_quat, axis=1, keepdims=True)
        te = _sample_times(t_end, 500.0, rng)
        ee = start[None] + at(sim["e"], te)[:, None] * d[None]
        ee_pos = np.column_stack([ee, np.full(len(te), table_z + hz)])
        ee_pos += rng.normal(0.0, truth.sigma_ee, ee_pos.shape)
        tw = _sample_times(t_end, 250.0, rng)
        f_along = at(sim["f"], tw)
        # the force on the tool in its frame (x along the push) plus offset and noise
        tool = np.column_stack([f_along, 0 * f_along, 0 * f_along]) + np.asarray(
            truth.sensor_offset
        )
        tool += rng.normal(0.0, truth.sigma_force, tool.shape)
        c, s = np.cos(yaw), np.sin(yaw)
        world = np.column_stack(
            [c * tool[:, 0] - s * tool[:, 1], s * tool[:, 0] + c * tool[:, 1], tool[:, 2]]
        )
        t0 = t_base + i * 10_000_000_000
        trajs.append(
            ForcePushTrajectory(
                name=f"push{i}",
                t_ns=t0 + np.round(to * 1e9).astype(np.int64),
                object_pos=obj_pos,
                object_quat=obj_quat,
                ee_t_ns=t0 + np.round(te * 1e9).astype(np.int64),
                ee_pos=ee_pos,
                ee_quat=np.repeat(_quat_yaw(yaw)[None], len(te), axis=0),
                grasp=np.zeros(len(te), dtype=bool),
                wrench_t_ns=t0 + np.round(tw * 1e9).astype(np.int64),
                wrench_force=world,
                wrench_tool=tool,
            )
        )
    sx, sy, sz = truth.size
    m = mass_nominal
    physics = {
        "revision": 1,
        "gravity_mps2": [0.0, 0.0, -G],
        "objects": {
            "box": {
                "equation": "rigid",
                "size_m": list(truth.size),
                "mass_kg": m,
                "inertia_kgm2": [
                    [m * (sy**2 + sz**2) / 12, 0.0, 0.0],
                    [0.0, m * (sx**2 + sz**2) / 12, 0.0],
                    [0.0, 0.0, m * (sx**2 + sy**2) / 12],
                ],
                "friction_static": truth.mu_s,
                "friction_dynamic": 0.3,
            },
            "table": {"equation": "static", "plane_z_m": table_z},
            "pusher": {
                "equation": "kinematic",
                "shape": "capsule",
                "radius_m": truth.pusher_radius,
                "length_m": truth.pusher_length,
            },
        },
    }
    meta = {
        "truth": {
            "mass_kg": mass_true,
            "dm": mass_true / mass_nominal - 1.0,
            "mu_d": truth.mu_d,
            "sigma_force_n": truth.sigma_force,
        }
    }
    return ForcePushRecording(trajs, physics, "box", meta)

"""Slow pushes with pusher friction: a box turns while a point pusher slides along its face.

An independent numpy generator (no ``robogs.physics``, no MuJoCo) of quasi-static pushing
(inertia neglected: the box moves only while the pusher pushes and stops with it):

* **Table friction: the ellipsoidal limit surface** (Goyal, Ruina & Papadopoulos 1991;
  Lee & Cutkosky 1991). The table's friction wrench (F_x, F_y, M) on a sliding box lies on
  ``F_x^2 + F_y^2 + M^2 / c^2 = (mu_t m g)^2`` with ``c = m_max / f_max`` the mean distance of
  a uniform footprint's points from its centre; the box twist (v_x, v_y, omega), body axes at
  the centre, is along the normal: ``V ~ (F_x, F_y, M / c^2)``.
* **Pusher friction: a Coulomb point contact** of coefficient ``mu_p`` on the face. The twists
  the pusher can impose by sticking form the *motion cone* (Mason 1986; Lynch, Maekawa &
  Tanie 1992): the images of the friction-cone edges ``(1, +-mu_p)`` under the limit surface.
  A pusher velocity inside the cone sticks; outside it the contact slides and the force lies on
  the cone edge on the side of the slip. Closed forms as in Hogan & Rodriguez 2016, section 2:
  with ``J = [[1, 0, -y_c], [0, 1, x_c]]`` (contact (x_c, y_c), box frame) and
  ``H = diag(1, 1, 1 / c^2)``, the contact-point velocity of the box is ``v_c = J H J^T f``
  for a contact force f (normal, tangential) on the box.

The pusher is a small sphere (radius ``r``) whose centre moves along a straight line at an
angle ``beta`` to the face normal, slowly (``SPEED``), so that the box slides and turns
20-60 deg. The table's friction coefficient enters only the force scale (``mu_t m g``): the
poses alone do not depend on it (quasi-static), the measured pusher force does. The sensor
reads the force the box exerts on the pusher (world axes), plus a constant offset and white
noise, as in :mod:`robogs.synth.scenarios.force_push`.

Measurement: object poses at 30 Hz (random clock phase), tool poses at 500 Hz, wrench at 250 Hz;
noise levels :data:`NOISE`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robogs.synth.scenarios.force_push import ForcePushTrajectory
from robogs.synth.scenarios.generate import ScenarioRecording, _quat_yaw
from robogs.synth.scenarios.sim import mean_radius

__all__ = [
    "NOISE",
    "PushTruth",
    "PusherFrictionTruth",
    "make_pusher_friction",
    "motion_cone",
    "quasi_static_push",
    "twist_from_force",
]

G = 9.81
FINE_DT = 5e-4
SPEED = 0.04
"""Pusher speed along its line [m/s]: a 0.4 kg box on mu 0.35 stops within v / (mu g) = 12 ms
(0.2 mm) when the pusher stops, so the quasi-static model holds."""
RAMP_S = 0.2
"""Cosine speed ramps at the start and the end of a push [s] (no jerk for a dynamic model)."""

NOISE: dict[str, dict[str, float]] = {
    "low": {"pos": 3e-4, "rot": float(np.radians(0.2)), "ee": 6e-5, "force": 0.03},
    "zero": {"pos": 0.0, "rot": 0.0, "ee": 0.0, "force": 0.0},
}
"""Measurement noise: object position [m] and rotation [rad] per axis, tool position [m],
force [N] per axis (one sigma)."""


@dataclass(frozen=True)
class PusherFrictionTruth:
    """True scene: box edges [m], mass [kg], table and pusher friction, pusher sphere radius
    and centre height above the table [m], table height [m], sensor offset [N]."""

    size: tuple[float, float, float] = (0.08, 0.06, 0.05)
    mass: float = 0.4
    mu_t: float = 0.35
    mu_p: float = 0.3
    pusher_radius: float = 0.005
    pusher_height: float = 0.008
    table_z: float = 0.0
    sensor_offset: tuple[float, float, float] = (0.2, -0.1, -1.5)

    @property
    def c(self) -> float:
        """Limit-surface ratio m_max / f_max [m]: the footprint's mean radius."""
        return mean_radius(self.size[0], self.size[1])


@dataclass
class PushTruth:
    """Fine-step truth of one push: times [K] s, box pose (x, y, yaw) [K, 3] (m, rad, world),
    pusher centre [K, 2] m (world), force on the box at the contact [K, 2] N (world; zero out
    of contact), the contact's face coordinate y_c [K] m (nan out of contact), and whether the
    contact sticks [K]."""

    t: np.ndarray
    pose: np.ndarray
    pusher: np.ndarray
    force: np.ndarray
    y_c: np.ndarray
    stick: np.ndarray


def twist_from_force(f: np.ndarray, x_c: float, y_c: float, c: float) -> np.ndarray:
    """Box twist direction (v_x, v_y, omega) [body axes, at the centre] of a contact force
    ``f = (f_n, f_t)`` on the box at (x_c, y_c) under the ellipsoidal limit surface (unscaled)."""
    fx, fy = float(f[0]), float(f[1])
    moment = x_c * fy - y_c * fx
    return np.array([fx, fy, moment / c**2])


def motion_cone(x_c: float, y_c: float, c: float, mu_p: float) -> tuple[np.ndarray, np.ndarray]:
    """Contact-point velocities (normal, tangential) of the two motion-cone edges, each with a
    unit normal component: the box's contact velocity under the forces ``(1, +mu_p)`` and
    ``(1, -mu_p)``."""
    out = []
    for s in (1.0, -1.0):
        v = twist_from_force(np.array([1.0, s * mu_p]), x_c, y_c, c)
        vc = np.array([v[0] - v[2] * y_c, v[1] + v[2] * x_c])
        out.append(vc / vc[0])
    return out[0], out[1]


def _contact_map(x_c: float, y_c: float, c: float) -> np.ndarray:
    """[2, 2] map from a contact force (n, t) on the box to its contact-point velocity
    (normal, tangential) under the limit surface: J H J^T."""
    j = np.array([[1.0, 0.0, -y_c], [0.0, 1.0, x_c]])
    h = np.diag([1.0, 1.0, 1.0 / c**2])
    return j @ h @ j.T


def _step_force(v_p: np.ndarray, x_c: float, y_c: float, c: float, mu_p: float):
    """Contact force direction (n, t) on the box for a pusher velocity ``v_p`` (normal into the
    face, tangential; box axes) and whether it sticks. The force is up to a positive scale."""
    a = _contact_map(x_c, y_c, c)
    f = np.linalg.solve(a, v_p)
    if f[0] > 0 and abs(f[1]) <= mu_p * f[0] * (1 + 1e-12):
        return f, True
    # sliding: the force on the cone edge on the side of the pusher's slip relative to the box
    for s in (1.0, -1.0):
        fe = np.array([1.0, s * mu_p])
        vc = a @ fe
        slip = v_p[1] - vc[1] * v_p[0] / vc[0]  # tangential slip at the matched normal speed
        if slip * s > 0:
            return fe * (v_p[0] / vc[0]), False
    return np.array([1.0, 0.0]) * (v_p[0] / (a @ [1.0, 0.0])[0]), False  # pragma: no cover


def quasi_static_push(
    truth: PusherFrictionTruth,
    y_c0: float,
    beta: float,
    dist: float,
    *,
    box_xy: tuple[float, float] = (0.0, 0.0),
    box_yaw: float = 0.0,
    speed: float = SPEED,
    dt: float = FINE_DT,
    standoff: float = 0.02,
) -> PushTruth:
    """One push on the box's -x face, simulated on a fine grid.

    The pusher starts ``standoff`` [m] from the face at face coordinate ``y_c0`` [m], rests
    0.3 s, approaches along the face normal (minimum jerk, 0.3 s), pushes ``dist`` [m] along a
    fixed world direction at ``beta`` [rad] from the initial face normal (towards +y of the box),
    at ``speed`` with :data:`RAMP_S` ramps, rests 0.1 s, backs off 2 cm along the normal of the
    face as it is then and rests 0.2 s.

    Raises:
        ValueError: the contact left the face (|y_c| beyond the half face less the radius).
    """
    a, hy = 0.5 * truth.size[0], 0.5 * truth.size[1]
    c, r = truth.c, truth.pusher_radius
    f_max = truth.mu_t * truth.mass * G
    rot0 = np.array([[np.cos(box_yaw), -np.sin(box_yaw)], [np.sin(box_yaw), np.cos(box_yaw)]])
    p_touch = np.asarray(box_xy) + rot0 @ np.array([-a - r, y_c0])
    n0 = rot0 @ np.array([1.0, 0.0])
    d = rot0 @ np.array([np.cos(beta), np.sin(beta)])
    # pusher path: rest, approach, push, rest
    n_rest, n_app = int(round(0.3 / dt)), int(round(0.3 / dt))
    u = np.linspace(0.0, 1.0, n_app)
    app = p_touch[None] - standoff * n0[None] * (1 - (10 * u**3 - 15 * u**4 + 6 * u**5))[:, None]
    t_push = dist / speed + RAMP_S
    tt = np.arange(0.0, t_push + dt / 2, dt)
    v = speed * np.minimum(
        1.0, np.minimum(0.5 - 0.5 * np.cos(np.pi * np.clip(tt / RAMP_S, 0, 1)), 1.0)
    )
    v = v * np.where(
        tt > t_push - RAMP_S, 0.5 + 0.5 * np.cos(np.pi * (tt - t_push + RAMP_S) / RAMP_S), 1.0
    )
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1])) * dt])
    push = p_touch[None] + s[:, None] * d[None]
    path = [np.repeat(app[:1], n_rest, 0), app, push[1:], np.repeat(push[-1:], int(0.1 / dt), 0)]
    pusher = np.concatenate(path)
    k_push0 = n_rest + n_app  # index of the first push sample (pusher at p_touch before)
    k_push1 = k_push0 + len(push) - 1
    n_k = len(pusher)
    pose = np.zeros((n_k, 3))
    pose[0] = (box_xy[0], box_xy[1], box_yaw)
    force = np.zeros((n_k, 2))
    y_c = np.full(n_k, np.nan)
    stick = np.zeros(n_k, bool)
    for k in range(1, n_k):
        pose[k] = pose[k - 1]
        if not k_push0 <= k <= k_push1:
            continue
        x, y, th = pose[k - 1]
        cth, sth = np.cos(th), np.sin(th)
        rot = np.array([[cth, -sth], [sth, cth]])
        local = rot.T @ (pusher[k - 1] - np.array([x, y]))
        yc = float(local[1])
        if abs(yc) > hy - r:
            raise ValueError(f"the contact left the face (y_c = {yc * 1e3:.1f} mm)")
        dp = rot.T @ (pusher[k] - pusher[k - 1])  # pusher displacement, box axes
        if dp[0] <= 0:
            continue
        f, st = _step_force(dp, -a, yc, c, truth.mu_p)
        twist = twist_from_force(f, -a, yc, c)  # displacement (dx, dy, dth), body axes
        # scale the force onto the limit surface: (F_x^2 + F_y^2 + M^2 / c^2) = f_max^2
        fu = f / np.sqrt(f[0] ** 2 + f[1] ** 2 + (c * twist[2]) ** 2)
        force[k] = rot @ (f_max * fu)
        y_c[k], stick[k] = yc, st
        # midpoint heading for the translation
        thm = th + 0.5 * twist[2]
        rm = np.array([[np.cos(thm), -np.sin(thm)], [np.sin(thm), np.cos(thm)]])
        pose[k, :2] = pose[k - 1, :2] + rm @ twist[:2]
        pose[k, 2] = th + twist[2]
        # keep the contact on the face: remove the normal drift of the integration
        rk = np.array(
            [[np.cos(pose[k, 2]), -np.sin(pose[k, 2])], [np.sin(pose[k, 2]), np.cos(pose[k, 2])]]
        )
        gap = (rk.T @ (pusher[k] - pose[k, :2]))[0] - (-a - r)
        pose[k, :2] += rk @ np.array([gap, 0.0])
    # back off along the face normal as it is now, then rest
    th = pose[-1, 2]
    nb = np.array([np.cos(th), np.sin(th)])
    n_b = int(round(0.3 / dt))
    u = np.linspace(0.0, 1.0, n_b)[1:]
    back = pusher[-1][None] - 0.02 * nb[None] * (10 * u**3 - 15 * u**4 + 6 * u**5)[:, None]
    tail = np.repeat(back[-1:], int(round(0.2 / dt)), 0)
    pusher = np.concatenate([pusher, back, tail])
    extra = len(back) + len(tail)
    pose = np.concatenate([pose, np.repeat(pose[-1:], extra, 0)])
    force = np.concatenate([force, np.zeros((extra, 2))])
    y_c = np.concatenate([y_c, np.full(extra, np.nan)])
    stick = np.concatenate([stick, np.zeros(extra, bool)])
    return PushTruth(np.arange(len(pusher)) * dt, pose, pusher, force, y_c, stick)


PUSHES = ((-0.010, 0.5), (0.015, -0.7), (0.0, 0.35), (-0.005, -0.2))
"""(initial face coordinate y_c [m], pusher direction beta [rad] from the face normal) of the
default pushes. With mu_p 0.3 the first two slide along the face all the way, the other two
stick part of the way (30-55 % sliding); the box turns 28, 29, 41 and 43 deg."""


def make_pusher_friction(
    *,
    seed: int = 0,
    noise: str = "low",
    mu_t: float = 0.35,
    mu_p: float = 0.3,
    pushes: tuple[tuple[float, float], ...] = PUSHES,
    dist: float = 0.08,
    nominal: tuple[float, float] = (0.3, 0.2),
) -> ScenarioRecording:
    """Pushes with pusher friction, measured (see the module docstring).

    Args:
        seed: noise, start poses and clock phases.
        noise: a key of :data:`NOISE`.
        mu_t, mu_p: true table and pusher friction.
        pushes: (y_c0 [m], beta [rad]) per push.
        dist: pusher travel per push [m].
        nominal: (table, pusher) friction written in the nominal physics.json.

    Returns:
        A recording whose ``meta["truth"]`` holds the true values and ``meta["fine"]`` the
        noise-free fine-step truth of each push (:class:`PushTruth`).
    """
    rng = np.random.default_rng(seed)
    nz = NOISE[noise]
    truth = PusherFrictionTruth(mu_t=mu_t, mu_p=mu_p)
    hz = 0.5 * truth.size[2]
    z_p = truth.table_z + truth.pusher_height
    trajs, fine = [], []
    t_base = 1_700_000_000_000_000_000
    for i, (y0, beta) in enumerate(pushes):
        xy = (0.45 + rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05))
        yaw0 = float(2 * np.pi * i / len(pushes) + rng.uniform(-0.2, 0.2))
        tr = quasi_static_push(truth, y0, beta, dist, box_xy=xy, box_yaw=yaw0)
        fine.append(tr)
        t_end = float(tr.t[-1])

        def at(arr: np.ndarray, t: np.ndarray, tr: PushTruth = tr) -> np.ndarray:
            return np.stack([np.interp(t, tr.t, a) for a in np.atleast_2d(arr.T)], -1)

        to = np.arange(rng.uniform(0, 1 / 30), t_end, 1 / 30)
        box = at(tr.pose, to)
        obj_pos = np.column_stack([box[:, :2], np.full(len(to), truth.table_z + hz)])
        obj_pos += rng.normal(0.0, nz["pos"], obj_pos.shape)
        rv = rng.normal(0.0, nz["rot"], (len(to), 3))
        obj_quat = _quat_yaw(box[:, 2] + rv[:, 2])
        obj_quat[:, 1:3] += 0.5 * rv[:, :2] * obj_quat[:, :1]
        obj_quat /= np.linalg.norm(obj_quat, axis=1, keepdims=True)
        te = np.arange(rng.uniform(0, 1 / 500), t_end, 1 / 500)
        ee = at(tr.pusher, te)
        ee_pos = np.column_stack([ee, np.full(len(te), z_p)])
        ee_pos += rng.normal(0.0, nz["ee"], ee_pos.shape)
        tw = np.arange(rng.uniform(0, 1 / 250), t_end, 1 / 250)
        # the force the box exerts on the pusher: minus the contact force on the box; the
        # fine force is averaged over each sensor sample's 4 ms window (a low-pass sensor)
        box4 = np.ones(max(1, int(round(4e-3 / FINE_DT))))
        f_avg = np.stack([np.convolve(a, box4 / box4.size, "same") for a in tr.force.T], -1)
        fw = -at(f_avg, tw)
        wrench = np.column_stack([fw, np.zeros(len(tw))]) + np.asarray(truth.sensor_offset)
        wrench += rng.normal(0.0, nz["force"], wrench.shape)
        t0 = t_base + i * 10_000_000_000
        trajs.append(
            ForcePushTrajectory(
                name=f"slide_push{i}",
                t_ns=t0 + np.round(to * 1e9).astype(np.int64),
                object_pos=obj_pos,
                object_quat=obj_quat,
                ee_t_ns=t0 + np.round(te * 1e9).astype(np.int64),
                ee_pos=ee_pos,
                ee_quat=np.repeat(_quat_yaw(np.array(yaw0))[None], len(te), axis=0),
                grasp=np.zeros(len(te), dtype=bool),
                wrench_t_ns=t0 + np.round(tw * 1e9).astype(np.int64),
                wrench_force=wrench,
                wrench_tool=wrench,
                kind="pusher_friction",
            )
        )
    sx, sy, sz = truth.size
    m = truth.mass
    physics = {
        "revision": 1,
        "gravity_mps2": [0.0, 0.0, -G],
        "objects": {
            "box": {
                "equation": "rigid",
                "size_m": list(truth.size),
                "mass_kg": m,
                "com_m": [0.0, 0.0, 0.0],
                "inertia_kgm2": [
                    [m * (sy**2 + sz**2) / 12, 0.0, 0.0],
                    [0.0, m * (sx**2 + sz**2) / 12, 0.0],
                    [0.0, 0.0, m * (sx**2 + sy**2) / 12],
                ],
                "friction_static": float(nominal[0]),
                "friction_dynamic": float(nominal[0]),
            },
            "table": {"equation": "static", "plane_z_m": truth.table_z},
            "pusher": {
                "equation": "kinematic",
                "shape": "sphere",
                "radius_m": truth.pusher_radius,
                "friction_dynamic": float(nominal[1]),
            },
        },
        "effects": [],
    }
    turn = [float(np.degrees(tr.pose[-1, 2] - tr.pose[0, 2])) for tr in fine]
    meta = {
        "truth": {"mu_t": mu_t, "mu_p": mu_p, "c_m": truth.c, "turn_deg": turn},
        "noise": dict(nz),
        "fine": fine,
        "seed": seed,
    }
    return ScenarioRecording(trajs, physics, "box", meta)

"""Pusher strikes on the MuJoCo engine (``MujocoFit._strike``, issue 16): a sphere that closes on
the box faster than ``STRIKE_MIN_SPEED`` gives it the rigid, frictionless, inelastic impulse of
the planar model and the generator, instead of MuJoCo's soft pusher pair throwing it.

Oracles, written here from the rigid-body impulse laws (not from the engine's code):

* an off-centre strike on a frictionless table: the contact point leaves at the pusher's normal
  speed, ``lambda (1/m + d^2/I) = v``, so the CoM moves at ``lambda / m`` and the box turns at
  ``-lambda d / I`` (``d`` the lever along the face) until the next contact;
* the pusher force: over a strike and a push at constant speed the force on the pusher, summed
  over its bins, is the box's momentum plus the table friction's impulse ``mu m g T``.

Mutations that must fail: the soft pusher pair alone (``strike_events = False``) and a pusher
force without the strike's impulse.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")

from box_scene import box_on_table  # noqa: E402

from robogs.physics.engines.base import make_drive  # noqa: E402
from robogs.physics.engines.mujoco_fit import MujocoFit  # noqa: E402
from robogs.physics.scene import base_params, scene_from_physics  # noqa: E402
from robogs.physics.space import ParamSpace  # noqa: E402

SIZE = (0.08, 0.06, 0.05)
MASS, G, DT, R = 0.4, 9.81, 1e-3, 0.01


def _doc(mu: float) -> dict:
    """The shared box scene (``box_scene.box_on_table``) with a 1 cm sphere pusher."""
    doc = box_on_table(mu)
    doc["objects"]["pusher"] = {"equation": "kinematic", "shape": "sphere", "radius_m": R}
    return doc


def _push(v: float, d: float, gap: float, hold: float, brake: float, tail: float):
    """Pusher x [S] on the line y = ``d``: still 20 ms, then at ``v`` m/s from ``gap`` m before
    the -x face for ``gap / v + hold`` s, braking at ``brake`` m/s^2, still for ``tail`` s."""
    n_run = int(round((gap / v + hold) / DT))
    n_brake = int(np.ceil(v / brake / DT))
    vel = np.concatenate(
        [
            np.zeros(20),
            np.full(n_run, v),
            np.linspace(v, 0.0, n_brake + 1)[1:],
            np.zeros(int(tail / DT)),
        ]
    )
    x = -(0.5 * SIZE[0] + R + gap) + np.concatenate([[0.0], np.cumsum(vel) * DT])
    return x, 20 + int(round(gap / v / DT))


def _simulate(mu: float, x: np.ndarray, d: float, events: bool, bins: int = 0):
    """(dense CoM position [S, 3] m, yaw [S] rad, pusher force [W, 3] N or None) of the box at
    rest at the origin, the pusher sphere at x [S] on y = ``d``."""
    doc = _doc(mu)
    n = len(x)
    p = np.stack([x, np.full(n, d), np.full(n, SIZE[2] / 2)], -1)[None]
    drive = make_drive(
        DT,
        p,
        np.zeros((1, n)),
        (np.arange(n) * DT)[None],
        np.array([[0.0, 0.0, SIZE[2] / 2]]),
        np.zeros(1),
    )
    if bins:
        n_b = int(np.ceil(n / bins))
        drive.wrench_bin = torch.as_tensor((np.arange(n) // bins)[None])
        drive.wrench_width = torch.full((1, n_b), bins * DT, dtype=torch.float64)
    scene = scene_from_physics(doc, "box", dt=DT)
    space = ParamSpace(base_params(scene), [])
    sim = MujocoFit(doc, "box", dt=DT)
    sim.strike_events = events
    out = sim.simulate(torch.as_tensor(space.zero[None]), space, drive, scene)
    f = None if out.force is None else out.force[0, 0].numpy()
    return out.dense_pos[0, 0].numpy(), out.dense_yaw[0, 0].numpy(), f


@pytest.mark.parametrize("v,d", [(0.30, 0.0), (0.30, 0.015), (0.45, -0.02)])
def test_a_tap_leaves_the_box_with_the_rigid_impulse(v: float, d: float) -> None:
    """The sphere reaches the -x face at ``v`` m/s on the line y = ``d``, stays at speed for a
    step and brakes at 300 m/s^2 (a tap). On a table without friction the box then moves with
    the rigid impulse's CoM speed ``lambda / m`` and yaw rate ``-lambda d / I``: measured over
    the 5 ms after the pusher stops, within 1 % (0.3-0.6 % low: MuJoCo's table still takes a
    little, 0.15 m/s^2 with a zero coefficient), no sideways drift. The soft pusher pair alone
    (``strike_events = False``) has not finished the strike when the pusher leaves: the box
    keeps 7-39 % of the speed."""
    x, k = _push(v, d, 0.0045, 0.001, 300.0, 0.05)  # 4.5 mm: the face is reached on step k
    inertia = MASS * (SIZE[0] ** 2 + SIZE[1] ** 2) / 12.0
    lam = v / (1.0 / MASS + d * d / inertia)
    want = np.array([lam / MASS, -lam * d / inertia])
    a, b = k + 5, k + 10  # the pusher has stopped by step k + 3
    got = {}
    for events in (True, False):
        pos, yaw, _ = _simulate(0.0, x, d, events)
        span = (b - a) * DT
        got[events] = np.array([(pos[b, 0] - pos[a, 0]) / span, (yaw[b] - yaw[a]) / span])
        assert abs(pos[b, 1]) < 1e-5  # no sideways push from a frictionless sphere
    np.testing.assert_allclose(got[True], want, rtol=1e-2, atol=1e-6)
    assert got[False][0] < 0.5 * want[0], got[False]


def test_the_pusher_force_carries_the_strike_impulse() -> None:
    """A strike at 0.3 m/s and a 125 ms push at that speed, with table friction 0.3: the force on
    the pusher summed over its 10 ms bins up to the brake is the box's momentum plus the
    friction impulse, ``m v + mu m g T`` (-x), within 2 % (measured 1.0008 of it; the soft pair
    alone 0.993): the strike event's impulse enters the bins (``MujocoFit._pusher_force``).
    Without it the sum is 0.55 of the closed form: the box's momentum is missing."""
    mu, v = 0.3, 0.3
    x, k = _push(v, 0.0, 0.0045, 0.125, 20.0, 0.05)
    k_brake = k + int(round(0.125 / DT))  # 160: the brake starts with bin 16
    want = -(MASS * v + mu * MASS * G * (k_brake - k) * DT)
    _, _, f = _simulate(mu, x, 0.0, True, bins=10)
    got = float(f[: k_brake // 10, 0].sum() * 10 * DT)
    assert abs(got / want - 1.0) < 0.02, (got, want)
    with pytest.MonkeyPatch.context() as mp:
        plain = MujocoFit._pusher_force
        mp.setattr(MujocoFit, "_pusher_force", lambda self, *a: plain(self, *a[:4]))
        _, _, f0 = _simulate(mu, x, 0.0, True, bins=10)
    miss = float(f0[: k_brake // 10, 0].sum() * 10 * DT)
    assert abs(miss / want - 1.0) > 0.2, (miss, want)


def test_no_strike_from_a_pusher_parked_after_a_grasp() -> None:
    """A box carried at 0.3 m/s and released at step 150; the end effector backs off 81 mm and
    comes forward at 0.4 m/s, reaching the resting box's -x face (as the drive has it) near
    step 570. MuJoCo parks the pusher away from the grasp onset on (``PUSHER_PARK_M``), so no
    strike event may act either: the poses equal those without strike events, bit for bit
    (without the parked rows left out the events shoved the box up to 127 mm away)."""
    n = 700
    v = np.zeros(n)
    v[:150] = np.clip(np.arange(150) / 60.0, 0.0, 1.0) * 0.3
    v[150:420] = -0.3
    v[450:] = 0.4
    x = np.concatenate([[0.0], np.cumsum(v[:-1]) * DT])
    p = np.stack([x, np.zeros(n), np.full(n, SIZE[2] / 2)], -1)[None]
    obs = (np.arange(n) * DT)[None]
    start = np.array([[0.0, 0.0, SIZE[2] / 2]])
    drive = make_drive(DT, p, np.zeros((1, n)), obs, start, np.zeros(1))
    drive.grasp[0, :150] = True
    doc = _doc(0.3)
    scene = scene_from_physics(doc, "box", dt=DT)
    space = ParamSpace(base_params(scene), [])
    out = {}
    for events in (True, False):
        sim = MujocoFit(doc, "box", dt=DT)
        sim.strike_events = events
        res = sim.simulate(torch.as_tensor(space.zero[None]), space, drive, scene)
        out[events] = res.dense_pos[0, 0].numpy()
    assert out[True][-1, 0] > 0.03  # carried and slid
    np.testing.assert_array_equal(out[True], out[False])

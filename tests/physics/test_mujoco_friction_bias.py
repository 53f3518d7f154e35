"""Where MuJoCo's +2.8 % friction bias on centred pushes comes from (issue 16, h42).

On the 9-push timing scene (``make_scenario("none", seed=0, kinds=("push",))``) MuJoCo fits the
table friction 0.3597 against the generator's 0.35 (planar 0.3482). Closed-form cases, one
mechanism at a time, on the planar joint set (:data:`~robogs.format.mjcf.PLANAR_SETTINGS`):

* the table friction is Coulomb's: a box given v0 decelerates at mu g (within 0.05 % at 0.3 and
  0.5 m/s for mu 0.2 / 0.35 / 0.6, any mass) and stops at semi-implicit Euler's
  ``v0^2 / (2 mu g) - v0 dt / 2``;
* the pusher force of a steady push is mu m g (within 0.4 %);
* the bias is the strike: the pusher contact (``solref`` 4 ms, damping ratio 2) is overdamped,
  its slow mode relaxes in ``dmax tc zeta (zeta + sqrt(zeta^2 - 1))`` = 30 ms, so a strike's
  compression (0.6-0.9 mm at 0.5 m/s) is not gone when the pusher brakes 45 mm later: the box
  rides 0.40 / 0.86 % faster than the pusher at 0.45 / 0.55 m/s (1.4 % and 1 mm further on the
  scene's 0.55 m/s pushes) and leaves at that speed, which a fit reads as more friction.

The last test is a strict xfail on the default settings (the bias is there); with the pusher
pair's time constant at 3 steps and damping ratio 1.7
(``ContactSettings.pusher_timeconst_steps``, ``pusher_dampratio``) the struck box leaves at the
pusher's speed within the same bound, but these settings are not the default: see
``bench/RESULTS.md``, "issue 16 (h42)", for what they cost elsewhere.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest
from mujoco_push import brake, push_x, pusher_contacts, ramp_up

from robogs.format.mjcf import PLANAR_SETTINGS, ContactSettings
from robogs.physics.engines.base import ObjectState, make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine

SIZE, MASS, G, DT = (0.08, 0.06, 0.05), 0.4, 9.81, 1e-3
R, HX = 0.01, 0.04  # pusher radius, box half length along the push [m]
FIXED = dataclasses.replace(PLANAR_SETTINGS, pusher_timeconst_steps=3.0, pusher_dampratio=1.7)
"""The pusher pair that removes most of the bias (not the default; see the module docstring)."""


def _doc(mu: float, pusher: bool) -> dict:
    objects = {
        "table": {"equation": "static", "plane_z_m": 0.0},
        "box": {"equation": "rigid", "mass_kg": MASS, "size_m": list(SIZE), "friction_dynamic": mu},
    }
    if pusher:  # the generator's pusher: a capsule across the face, frictionless
        objects["pusher"] = {
            "equation": "kinematic",
            "shape": "capsule",
            "radius_m": R,
            "length_m": 0.04,
            "friction_dynamic": 0.0,
        }
    return {"gravity_mps2": [0.0, 0.0, -G], "objects": objects}


def _slide(mu: float, v0: float) -> tuple[float, float]:
    """A box given v0 along x: (mean deceleration over 20-80 % of the slide [m/s^2], stop
    distance [m])."""
    eng = MujocoEngine(_doc(mu, False))
    t_stop = v0 / (mu * G)
    n = int(round((t_stop + 0.1) / DT)) + 1
    init = np.array([[0.0, 0.0, SIZE[2] / 2]])
    drive = make_drive(
        DT, np.zeros((1, n, 3)), np.zeros((1, n)), (np.arange(n) * DT)[None], init, np.zeros(1)
    )
    start = ObjectState(pos=init, quat=np.array([[1.0, 0, 0, 0]]), vel=np.array([[v0, 0, 0]]))
    x = eng.rollout(drive, {"box": start}).pos["box"][0, 0][:, 0]
    v = np.diff(x) / DT
    t = (np.arange(len(v)) + 0.5) * DT
    mid = (t > 0.2 * t_stop) & (t < 0.8 * t_stop)
    return -float(np.polyfit(t[mid], v[mid], 1)[0]), float(x[-1])


def _push(mu: float, v: float, settings: ContactSettings, strike: bool) -> dict[str, float]:
    """The pusher moves along +x at ``v``: either arriving at speed from 20 mm behind the face
    (``strike``; 45 mm of contact including the brake, the generator's push) or starting
    0.2 mm behind it with a 60 ms cosine ramp and pushing 0.4 s (steady); then it brakes at
    12 m/s^2 (faster than mu g: the box leaves it). Returns the mean contact force on the
    pusher over the last 0.25 s before the brake [N], the box's speed over the pusher's at
    the brake, and the box's slide from the brake to rest [m]."""
    gap, n_up = (0.02, 1) if strike else (2e-4, 60)
    ramp = ramp_up(v, n_up)
    n_cruise = (
        int(round((gap + 0.045 - v * v / 24.0 - ramp.sum() * DT) / (v * DT)))
        if strike
        else int(round(0.4 / DT))
    )
    tail = np.zeros(int((v / (mu * G) + 0.1) / DT))
    vel = np.concatenate([np.zeros(20), ramp, np.full(n_cruise, v), brake(v, DT), tail])
    drive = push_x(vel, -(HX + R + gap), SIZE[2] / 2, DT)
    eng = MujocoEngine(_doc(mu, True), settings=settings)
    box_x, force, f6 = np.empty(len(vel)), np.zeros(len(vel)), np.zeros(6)
    for k, m, d in eng.step_states(drive):
        box_x[k] = d.qpos[eng.layout["box"].qpos]
        for i in pusher_contacts(m, d):
            if d.contact[i].efc_address >= 0:
                mujoco.mj_contactForce(m, d, i, f6)
                force[k] += f6[0]
    i_brake = 20 + n_up + n_cruise  # box_x[k] is the state after step k + 1
    v_box = (box_x[i_brake - 1] - box_x[i_brake - 2]) / DT
    return {
        "force": float(force[max(0, i_brake - 251) : i_brake - 1].mean()),
        "excess": v_box / v - 1.0,
        "slide": float(box_x[-1] - box_x[i_brake - 1]),
    }


@pytest.mark.parametrize("mu", [0.2, 0.35, 0.6])
def test_the_table_friction_is_coulombs_in_a_slide(mu: float) -> None:
    """A box given 0.5 m/s: mid-slide deceleration mu g within 0.2 % (measured 0.003-0.055 %),
    stop at ``v0^2 / (2 mu g) - v0 dt / 2`` (semi-implicit Euler's sum) within 0.1 mm
    (measured +0.02 to +0.06 mm). MuJoCo's soft contact does not weaken the sliding friction
    (the elliptic cone's sliding zone puts the force on the cone), so the bias is not here."""
    v0 = 0.5
    decel, stop = _slide(mu, v0)
    assert decel == pytest.approx(mu * G, rel=2e-3)
    assert abs(stop - (v0**2 / (2 * mu * G) - v0 * DT / 2)) < 1e-4, stop


@pytest.mark.parametrize("mu", [0.2, 0.35, 0.6])
def test_a_steady_push_feels_mu_m_g(mu: float) -> None:
    """Pushed at a constant 0.3 m/s after a gentle start: the contact force on the pusher is
    mu m g within 0.5 % (measured -0.09 to +0.36 %) and the box moves at the pusher's speed
    (0.02 %): neither the pusher contact in steady sliding nor the table friction is biased."""
    out = _push(mu, 0.3, PLANAR_SETTINGS, strike=False)
    assert out["force"] == pytest.approx(mu * MASS * G, rel=5e-3)
    assert abs(out["excess"]) < 1e-3


EXCESS_BOUND = 3e-3
"""Bound on a struck box's speed over the pusher's when the pusher brakes: the rigid (planar,
generator) strike is plastic and the box rides on the pusher at its speed. 0.3 % of speed is
0.6 % of the slide after release, of the friction a fit reads."""


@pytest.mark.parametrize("v", [0.45, 0.55])
@pytest.mark.parametrize(
    "settings",
    [
        pytest.param(
            PLANAR_SETTINGS,
            marks=pytest.mark.xfail(
                strict=True, raises=AssertionError, reason="the default pusher pair's slow mode"
            ),
            id="default",
        ),
        pytest.param(FIXED, id="tc3-zeta1.7"),
    ],
)
def test_a_struck_box_rides_the_pusher_at_its_speed(settings: ContactSettings, v: float) -> None:
    """The generator's push (capsule arriving at v, 45 mm of contact including the brake): at
    the brake the box moves at the pusher's speed within :data:`EXCESS_BOUND`. Default settings
    (pusher pair 4 ms, damping ratio 2: slow mode 30 ms): +0.40 / +0.86 % at 0.45 / 0.55 m/s,
    the strike's compression still relaxing (strict xfail: it fails while the bias is there).
    Pusher pair 3 ms, damping ratio 1.7 (slow mode 15 ms): +0.05 / +0.26 %."""
    out = _push(0.35, v, settings, strike=True)
    assert abs(out["excess"]) < EXCESS_BOUND, out

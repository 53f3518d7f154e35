"""The pusher onset ramp (``ContactSettings.pusher_onset_steps``; issue 16, h50).

With ``solimp`` (0.95, 0.99, 1 mm) a contact is almost fully stiff from its first step, so the
strike's impulse lands on the step where the onset happens to fall: the box's state after a
strike is a staircase in the start offset (period about ``v dt``). The ramp starts the pusher
pairs' impedance at MuJoCo's least and raises it linearly over ``c v_max dt`` of penetration,
so the force on the first penetrating step grows from zero with the penetration.

Oracle (no tolerance tuned to MuJoCo's numbers): on a frictionless table (no slip-normal
coupling, no hops, so only the pusher contact has onsets) a box struck at 0.45 m/s slides on
at the speed the strike gave it. Its position at the end, as a function of the start offset on
0..1 mm in 10 um, is refined 16-fold on the interval of its largest 10 um step: a jump keeps
its size under refinement, a Lipschitz function's step shrinks 16-fold. Without the ramp the
largest step survives refinement (a staircase); with it the step shrinks at least 4-fold.

Why the ramp still fails two closed-form bounds (h52), each against its own closed form: a
strike with the ramp overshoots as a linear spring-damper of the pair's damping ratio does
(``test_mujoco_contact.py``'s plastic bound 1.05 sits just above damping ratio 2's 4.78 %),
and a steady push sits inside the ramp where MuJoCo's soft-constraint balance puts it, at an
impedance of 0.49 that passes half the support's hop-cycle friction through to the box
(``test_mujoco_friction_bias.py``'s steady mu 0.6 push).
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from mujoco_push import brake, push_x, pusher_contacts, ramp_up

from robogs.format.errors import FormatError
from robogs.format.mjcf import (
    PLANAR_SETTINGS,
    PUSHER_ONSET_D0,
    ContactSettings,
    pusher_onset_solimp,
    scene_mjcf,
)
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine, drive_pusher_speed

SIZE, MASS, G, DT, R, HX = (0.08, 0.06, 0.05), 0.4, 9.81, 1e-3, 0.01, 0.04
V = 0.45  # m/s, the push (design B's fast pushes)


def _doc() -> dict:
    """A box on a frictionless table, a frictionless capsule pusher across its face."""
    return {
        "gravity_mps2": [0.0, 0.0, -G],
        "objects": {
            "table": {"equation": "static", "plane_z_m": 0.0},
            "box": {
                "equation": "rigid",
                "mass_kg": MASS,
                "size_m": list(SIZE),
                "friction_dynamic": 0.0,
            },
            "pusher": {
                "equation": "kinematic",
                "shape": "capsule",
                "radius_m": R,
                "length_m": 0.04,
                "friction_dynamic": 0.0,
            },
        },
    }


def _drive(offsets: np.ndarray, every_step: bool = False):
    """One trajectory per start offset [m] along +x: the pusher arrives at ``V`` from 10 mm
    behind the face, pushes 60 steps, brakes at 12 m/s^2 (the box leaves it), then 250 ms.
    The pose is wanted at the end only, or at every step (``every_step``)."""
    vel = np.concatenate([np.zeros(5), np.full(60, V), brake(V, DT), np.zeros(250)])
    return push_x(vel, -(HX + R + 0.01), SIZE[2] / 2, DT, offsets, every_step)


def _ends(eng: MujocoEngine, offsets: np.ndarray) -> np.ndarray:
    return eng.rollout(_drive(offsets)).pos["box"][0, :, -1, 0]


def _refined_step(settings: ContactSettings) -> tuple[float, float]:
    """(largest end-position step on the 10 um grid, largest step after refining its interval
    16-fold) [m]."""
    eng = MujocoEngine(_doc(), settings=settings, pusher_speed=V)
    off = np.arange(101) * 1e-5
    ends = _ends(eng, off)
    steps = np.abs(np.diff(ends))
    k = int(np.argmax(steps))
    fine = np.linspace(off[k], off[k + 1], 17)
    return float(steps[k]), float(np.abs(np.diff(_ends(eng, fine))).max())


def test_without_the_ramp_the_strike_is_a_staircase_in_the_onset() -> None:
    """Default pusher pair: the largest 10 um step (3.2 mm measured) keeps at least half its
    size when its interval is refined 16-fold (measured 1.0x): a jump, not a slope."""
    coarse, fine = _refined_step(PLANAR_SETTINGS)
    assert coarse > 1e-4, coarse
    assert fine > 0.5 * coarse, (coarse, fine)


@pytest.mark.parametrize("c", [1.0, 2.0])
def test_with_the_ramp_the_strike_is_continuous_in_the_onset(c: float) -> None:
    """Ramp over c v dt: the largest step shrinks at least 4-fold under 16-fold refinement
    (measured 13.9x / 12.7x for c = 1 / 2; a Lipschitz function gives 16x)."""
    settings = dataclasses.replace(PLANAR_SETTINGS, pusher_onset_steps=c)
    coarse, fine = _refined_step(settings)
    assert fine < 0.25 * coarse, (coarse, fine)


def test_onset_solimp_and_the_pairs_it_reaches() -> None:
    """Off: the pairs' ``solimp``. On: (least impedance, dmax, c v dt, midpoint, power 1) on
    the object-pusher pairs only, the support pairs unchanged."""
    off = pusher_onset_solimp(PLANAR_SETTINGS)
    assert off == tuple(PLANAR_SETTINGS.solimp)
    on = dataclasses.replace(PLANAR_SETTINGS, pusher_onset_steps=2.0, pusher_speed=0.5)
    lo, hi, width, mid, power = pusher_onset_solimp(on)
    assert (lo, hi, mid, power) == (PUSHER_ONSET_D0, on.solimp[1], on.solimp[3], 1.0)
    assert width == pytest.approx(2.0 * 0.5 * on.timestep, rel=1e-12)

    def imps(settings: ContactSettings) -> dict[tuple[str, str], str]:
        root = ET.fromstring(scene_mjcf(_doc(), settings=settings).xml)
        return {(p.get("geom1"), p.get("geom2")): p.get("solimp") for p in root.iter("pair")}

    a, b = imps(PLANAR_SETTINGS), imps(on)
    assert a.keys() == b.keys()
    for key in a:
        if "pusher" in key[1]:
            assert a[key] != b[key] and float(b[key].split()[2]) == pytest.approx(1e-3)
        else:
            assert a[key] == b[key]


def test_the_ramp_without_a_speed_is_refused() -> None:
    on = dataclasses.replace(PLANAR_SETTINGS, pusher_onset_steps=1.0)
    with pytest.raises(FormatError, match="pusher_speed"):
        pusher_onset_solimp(on)
    with pytest.raises(FormatError, match="pusher_speed"):
        scene_mjcf(_doc(), settings=on)


def test_drive_pusher_speed_is_the_fastest_step_speed() -> None:
    """Closed form: a path at 0.3 m/s then 0.45 m/s along a diagonal gives 0.45 m/s."""
    drive = _drive(np.zeros(2))
    assert drive_pusher_speed(drive) == pytest.approx(V, rel=1e-9)
    speed = np.concatenate([np.full(20, 0.3), np.full(30, 0.45)])
    step = speed[None, :, None] * DT / math.sqrt(3) * np.ones((1, 50, 3))
    diag = np.cumsum(step, axis=1)
    d2 = make_drive(DT, diag, np.zeros((1, 50)), np.zeros((1, 1)), np.zeros((1, 3)), np.zeros(1))
    assert drive_pusher_speed(d2) == pytest.approx(0.45, rel=1e-9)


def test_the_engine_sizes_the_ramp_from_the_recordings_drive(monkeypatch) -> None:
    """The fitting engine passes the prepared drive's fastest pusher speed: on the 9-push scene
    (pushes at 0.30 / 0.425 / 0.55 m/s) it is 0.55 m/s within 1 %, and with the ramp on the
    compiled pusher pairs' width is c times that speed times dt."""
    import robogs.physics.engines.mujoco_engine as me
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios.generate import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",), noise="zero")
    monkeypatch.setattr(
        me, "PLANAR_SETTINGS", dataclasses.replace(PLANAR_SETTINGS, pusher_onset_steps=1.0)
    )
    eng = Engine(rec, backend="mujoco")
    mj_eng = eng._mujoco.eng
    v = drive_pusher_speed(eng.prep.drive)
    assert mj_eng.settings.pusher_speed == v
    assert v == pytest.approx(0.55, rel=1e-2)
    model = mj_eng.model
    pusher = [k for k, pair in enumerate(mj_eng.scene.pairs) if "pusher" in pair[1]]
    assert pusher
    for k in pusher:
        assert model.pair_solimp[k][2] == pytest.approx(v * 1e-3, rel=1e-9)
        assert model.pair_solimp[k][4] == 1.0


# ------------------------------------------------------------- the strike's overshoot (h52)
def _overshoot_closed_form(zeta: float) -> float:
    """Peak speed over the pusher's, minus 1, of a free mass struck through a linear
    spring-damper of damping ratio ``zeta > 1`` by a pusher moving at a constant speed.

    The penetration obeys ``r'' + 2 zeta w r' + w^2 r = 0``, ``r(0) = 0``, ``r'(0) = V``, and
    the mass moves at ``V - r'``; with ``s1,2 = -w (zeta -+ sqrt(zeta^2 - 1))``,
    ``r' = V (s1 e^(s1 t) - s2 e^(s2 t)) / (s1 - s2)`` is most negative at
    ``t* = 2 ln(s2 / s1) / (s1 - s2)`` (``w = 1``: the overshoot is independent of the
    stiffness ``w^2`` and of ``V``)."""
    root = math.sqrt(zeta * zeta - 1.0)
    s1, s2 = -(zeta - root), -(zeta + root)
    t = 2.0 * math.log(s2 / s1) / (s1 - s2)
    return -(s1 * math.exp(s1 * t) - s2 * math.exp(s2 * t)) / (s1 - s2)


def _peak_speeds(settings: ContactSettings, offsets: np.ndarray) -> np.ndarray:
    """The box's peak speed over the pusher's, minus 1, in :func:`_drive`'s strike, per start
    offset [m] (every step stamped)."""
    drive = _drive(offsets, every_step=True)
    x = MujocoEngine(_doc(), settings=settings, pusher_speed=V).rollout(drive).pos["box"][0, ..., 0]
    return np.diff(x, axis=1).max(axis=1) / (V * DT) - 1.0


@pytest.mark.parametrize(("steps", "zeta"), [(0.0, 2.0), (3.0, 2.5)])
def test_with_the_ramp_a_strike_overshoots_as_a_linear_damped_contact(
    steps: float, zeta: float
) -> None:
    """With the ramp the strike starts from zero force, so the box's peak speed is that of a
    mass struck through a linear spring-damper of the pair's damping ratio (closed form
    :func:`_overshoot_closed_form`: 4.78 % at 2, 3.27 % at 2.5), whatever the onset's phase:
    measured 4.40-5.03 % and 2.92-3.47 % over nine phases (the impedance ramp makes the
    contact slightly nonlinear; bound 0.6 points). This is why the ramp with the default
    pusher pair (4 ms, damping ratio 2) meets ``test_mujoco_contact.py``'s plastic-strike bound
    of 5 % only just (1.0503 there): without the ramp the first step's full-impedance impulse
    makes the overshoot phase-dependent (2.8-5.0 %), and that test's phase sits low. A pusher
    pair of 3 steps and damping ratio 2.5 (``pusher_timeconst_steps``, ``pusher_dampratio``)
    brings it to 3.3 % (``bench/RESULTS.md``, "issue 16 (h52)")."""
    settings = dataclasses.replace(
        PLANAR_SETTINGS,
        pusher_onset_steps=1.0,
        pusher_timeconst_steps=steps,
        pusher_dampratio=zeta,
    )
    over = _peak_speeds(settings, np.arange(9) * 5e-5)
    expected = _overshoot_closed_form(zeta)
    assert np.all(np.abs(over - expected) < 6e-3), (over, expected)


# ------------------------------------------------------------- the steady push's operating point
def _impedance(solimp: np.ndarray, r: float) -> float:
    """MuJoCo's impedance ``d(r)`` of a constraint at violation ``r`` [m] (``solimp`` = dmin,
    dmax, width, midpoint, power; MuJoCo documentation, "Modeling", solimp)."""
    lo, hi, width, mid, power = (float(v) for v in solimp)
    x = min(r / width, 1.0)
    if power == 1.0:
        y = x
    elif x <= mid:
        y = x**power / mid ** (power - 1.0)
    else:
        y = 1.0 - (1.0 - x) ** power / (1.0 - mid) ** (power - 1.0)
    return lo + y * (hi - lo)


def _steady_push(settings: ContactSettings, mu: float) -> dict[str, float]:
    """The box on a table of friction ``mu`` pushed at 0.3 m/s (gentle 60 ms start, 0.4 s of
    push): mean penetration of the pusher contacts over the last 200 steps [m], their number,
    and the compiled pair's impedance, ``K = 1 / (dmax tc zeta)^2`` and ``A0`` (the sum of the
    two bodies' ``body_invweight0``)."""
    doc = _doc()
    doc["objects"]["box"]["friction_dynamic"] = mu
    v, n_push = 0.3, 400
    vel = np.concatenate([np.zeros(20), ramp_up(v, 60), np.full(n_push, v)])
    drive = push_x(vel, -(HX + R + 2e-4), SIZE[2] / 2, DT)
    eng = MujocoEngine(doc, settings=settings)
    pens, count = [], 0
    for k, m, d in eng.step_states(drive):
        if k >= len(vel) - 200:
            rows = [-d.contact[i].dist for i in pusher_contacts(m, d)]
            pens.append(np.mean(rows))
            count = len(rows)
    m = eng.model
    k = next(i for i, pair in enumerate(eng.scene.pairs) if "pusher" in pair[1])
    (tc, zeta), solimp = m.pair_solref[k], m.pair_solimp[k]
    b_box, b_pusher = m.body("box").id, m.body("pusher").id
    return {
        "r": float(np.mean(pens)),
        "contacts": count,
        "solimp": solimp.copy(),
        "K": 1.0 / (solimp[1] * tc * zeta) ** 2,
        "A0": float(m.body_invweight0[b_box, 0] + m.body_invweight0[b_pusher, 0]),
    }


def test_a_steady_push_sits_inside_the_ramp_where_the_closed_form_puts_it() -> None:
    """Why the ramp makes a steady push chatter (``test_mujoco_friction_bias.py``'s mu 0.6
    push: the box 0.41 % off the pusher's speed at the brake, RMS 0.26 %, mean -0.001 %).

    Closed form (MuJoCo documentation, "Computation", soft constraints: a row's force is
    ``f = (a_ref - a0) / (A + R)`` with ``R = (1 - d) / d A0`` and ``a_ref = -b v - K d r``):
    at rest relative to the pusher (``v = 0``, the row's own force balancing the share ``F``
    of the friction ``mu m g`` each of the capsule's two end contacts carries), ``R F = K d r``,
    so ``d(r)^2 r / (1 - d(r)) = A0 F / K``: the same load puts both pairs where this holds.
    Default pair: 10.4 um, ``d`` 0.93. Ramp over 0.55 mm: 274 um, ``d`` 0.49 -- and a contact
    of impedance ``d`` passes ``1 - d`` of an unconstrained acceleration through, so the
    support's hop cycle (its friction swinging over 14 steps) reaches the box 7x as much.
    The relation holds within 1 % (measured 0.03 / 0.15 %) for both pairs."""
    mu = 0.6
    ramp = dataclasses.replace(PLANAR_SETTINGS, pusher_onset_steps=1.0, pusher_speed=0.55)
    imps = []
    for settings in (PLANAR_SETTINGS, ramp):
        out = _steady_push(settings, mu)
        assert out["contacts"] == 2, out  # the capsule's two end spheres (capsule_ends)
        r = out["r"]
        imp = _impedance(out["solimp"], r)
        force = mu * MASS * G / out["contacts"]
        assert imp**2 * r / (1 - imp) == pytest.approx(out["A0"] * force / out["K"], rel=1e-2)
        imps.append(imp)
    assert imps[0] > 0.9 and imps[1] < 0.6, imps

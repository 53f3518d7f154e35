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
"""

from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

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


def _drive(offsets: np.ndarray):
    """One trajectory per start offset [m] along +x: the pusher arrives at ``V`` from 10 mm
    behind the face, pushes 60 steps, brakes at 12 m/s^2 (the box leaves it), then 250 ms."""
    n_brake = int(math.ceil(V / 12.0 / DT))
    vel = np.concatenate(
        [np.zeros(5), np.full(60, V), np.linspace(V, 0.0, n_brake + 1)[1:], np.zeros(250)]
    )
    x = -(HX + R + 0.01) + np.concatenate([[0.0], np.cumsum(vel) * DT])
    n, t = len(x), len(offsets)
    path = np.repeat(np.stack([x, np.zeros(n), np.full(n, SIZE[2] / 2)], -1)[None], t, 0)
    init = np.stack([offsets, np.zeros(t), np.full(t, SIZE[2] / 2)], -1)
    return make_drive(DT, path, np.zeros((t, n)), np.full((t, 1), (n - 1) * DT), init, np.zeros(t))


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

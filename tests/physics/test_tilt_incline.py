"""The table tilt on both engines against the incline's closed form (issue 16, h53).

A box sliding on a plane tilted so that gravity has the in-plane component ``g_t`` decelerates at
``g (mu cos a -+ sin a)``: with the catalogue's tilt (the planar model's bias acceleration
``(g_x, g_y)``, MuJoCo's gravity ``(g_x, g_y, -g)``, the normal load ``m g`` unchanged, i.e. the
small-angle form) that is ``mu g - g_t.u`` along the slide direction ``u`` while the box moves
in a straight line (``u`` parallel to ``g_t``). Released uphill and downhill at the same speed,
half the difference of the two decelerations is the tilt and half their sum is the friction:
each engine must read the tilt within 1 % and mu g within 0.5 %, in magnitude and sign, along
both table axes (g_x alone, g_y alone) and along the design-A truth (0.25, -0.15). A slide
across the slope (``u`` perpendicular to ``g_t``) bends downhill; its path follows the 2-D
ODE ``dv/dt = g_t - mu g v/|v|`` (integrated at 10 us, the oracle) within 1 mm.

Measured (h53, 2026-11-27): uphill / downhill, both engines read the tilt within 0.07 % and
mu g within 0.003 %, so the catalogue's tilt is mapped right on MuJoCo (sign, axes, size).
Across the slope MuJoCo's bend falls 4.8 % short at its default 10 ms friction reference (0.5 %
at 2 ms): its soft friction holds part of a sideways pull while the box slides (strict xfail
below). That, and the pusher strike, bias design A's fitted tilt on MuJoCo
(``bench/RESULTS.md``, "issue 16 (h53)").
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from box_scene import box_on_table

from robogs.physics.effects import get_effect
from robogs.physics.engines.base import make_drive
from robogs.physics.model import simulate
from robogs.physics.scene import base_params, scene_from_physics
from robogs.physics.space import ParamSpace

G, MU, V0, DT = 9.81, 0.35, 0.6, 1e-3
HZ = 0.025  # box half height [m]
SECONDS = 0.3
STAMPS = np.arange(0.0, SECONDS + 1e-9, 2e-3)  # 2 ms samples


def _physics() -> dict:
    return box_on_table(MU)


def _run(g: tuple[float, float], headings: list[float], backend: str) -> np.ndarray:
    """Planar box paths [H, N, 2] m: released at V0 along each heading [rad] from the
    origin on a table tilted by ``g`` [m/s^2], the pusher parked 1 m above."""
    phys = _physics()
    scene = scene_from_physics(phys, "box", dt=DT)
    tilt = get_effect("table_tilt")
    space = ParamSpace(base_params(scene), [tilt])
    th = torch.as_tensor(space.zero[None].copy())
    th[0, space.index("table_tilt", "g_x")] = g[0]
    th[0, space.index("table_tilt", "g_y")] = g[1]
    n_h = len(headings)
    s = int(round(SECONDS / DT)) + 1
    pusher = np.zeros((n_h, s, 3))
    pusher[..., 2] = 1.0
    obs = np.repeat(STAMPS[None], n_h, 0)
    init = np.tile([0.0, 0.0, HZ], (n_h, 1))
    drive = make_drive(DT, pusher, np.zeros((n_h, s)), obs, init, np.zeros(n_h))
    vel = [[V0 * math.cos(h), V0 * math.sin(h), 0.0] for h in headings]
    drive.init_vel = torch.tensor(vel, dtype=torch.float64)
    if backend == "mujoco":
        from robogs.physics.engines.mujoco_fit import MujocoFit

        sim = MujocoFit(phys, "box", dt=DT).simulate(th, space, drive, scene)
    else:
        sim = simulate(th, space, drive, scene)
    return sim.pos[0, :, :, :2].numpy()


def _decel(path: np.ndarray, u: np.ndarray) -> float:
    """Deceleration [m/s^2] along ``u`` of a straight slide: the curvature of a quadratic fit
    to the distance over 15-75 % of the time to rest (away from the release and the stop)."""
    d = path @ u
    v = np.gradient(d, STAMPS)
    t_stop = STAMPS[np.argmax(v < 1e-3 * V0)]
    sel = (STAMPS > 0.15 * t_stop) & (STAMPS < 0.75 * t_stop)
    assert sel.sum() >= 10, "too few samples in the mid-slide window"
    return -2.0 * float(np.polyfit(STAMPS[sel], d[sel], 2)[0])


def _ode(g: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Oracle: the 2-D path [N, 2] of dv/dt = g - mu g v/|v| from V0 u until rest, 10 us steps
    (the box sticks at rest: |g| < mu g)."""
    h, x, v, ti, out = 1e-5, np.zeros(2), V0 * u, 0.0, []
    for tq in STAMPS:
        while ti < tq - 1e-12 and np.hypot(*v) > 0.0:
            sp = float(np.hypot(*v))
            a = g - MU * G * v / sp
            v_new = v + h * a
            if v_new @ v <= 0.0 or np.hypot(*v_new) < MU * G * h:  # stops within the step
                v_new = np.zeros(2)
            x = x + 0.5 * h * (v + v_new)
            v, ti = v_new, ti + h
        out.append(x.copy())
    return np.asarray(out)


TILTS = [(0.3, 0.0), (0.0, -0.3), (0.25, -0.15)]


@pytest.mark.parametrize("backend", ["planar", "mujoco"])
@pytest.mark.parametrize("g", TILTS)
def test_incline_uphill_downhill_reads_the_tilt(backend: str, g: tuple[float, float]) -> None:
    """Released downhill and uphill: (a_up - a_down) / 2 is |g_t| within 1 %, (a_up +
    a_down) / 2 is mu g within 0.5 %; each slide's path is the closed form's within 1 mm
    (semi-implicit Euler's stop is v0 dt / 2 = 0.3 mm short of the continuous one)."""
    if backend == "mujoco":
        pytest.importorskip("mujoco")
    gt = np.asarray(g)
    mag = float(np.hypot(*gt))
    u = gt / mag  # downhill
    down = math.atan2(u[1], u[0])
    paths = _run(g, [down, down + math.pi], backend)
    a_down, a_up = _decel(paths[0], u), _decel(paths[1], -u)
    assert abs(0.5 * (a_up - a_down) - mag) < 0.01 * mag, (a_up, a_down, mag)
    assert abs(0.5 * (a_up + a_down) - MU * G) < 0.005 * MU * G, (a_up, a_down)
    for path, sign in zip(paths, (1.0, -1.0), strict=True):
        a = MU * G - sign * mag  # closed form: x(t) = V0 t - a t^2 / 2 until V0 / a
        tt = np.minimum(STAMPS, V0 / a)
        want = (V0 * tt - 0.5 * a * tt * tt)[:, None] * (sign * u)[None]
        assert np.max(np.hypot(*(path - want).T)) < 1e-3, np.max(np.hypot(*(path - want).T))
        # the box stays on its line: no sideways drift
        side = path @ np.array([-u[1], u[0]])
        assert np.max(np.abs(side)) < 1e-4


ACROSS = np.array([1.0, -0.6])
"""The cross-slope tilt: the design-A truth's direction, four times its size [m/s^2]."""


def _across(backend: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(engine path [N, 2], oracle path [N, 2], downhill unit vector) of a slide released
    across the slope of :data:`ACROSS`."""
    u = ACROSS / np.hypot(*ACROSS)
    across = np.array([-u[1], u[0]])
    path = _run(tuple(ACROSS), [math.atan2(across[1], across[0])], backend)[0]
    return path, _ode(ACROSS, across), u


@pytest.mark.parametrize("backend", ["planar", "mujoco"])
def test_slide_across_the_slope_follows_the_ode(backend: str) -> None:
    """Released across the slope: the path follows the 2-D ODE within 1 mm (measured 0.30 mm
    planar, 0.54 mm MuJoCo), and it bends downhill by ten times that (10.1 mm)."""
    if backend == "mujoco":
        pytest.importorskip("mujoco")
    path, want, u = _across(backend)
    assert np.max(np.hypot(*(path - want).T)) < 1e-3, np.max(np.hypot(*(path - want).T))
    assert float(want[-1] @ u) > 8e-3


def test_planar_bend_matches_the_ode() -> None:
    """The planar engine's downhill bend across the slope is the ODE's within 1 % (measured
    -0.6 %)."""
    path, want, u = _across("planar")
    assert abs(float(path[-1] @ u) / float(want[-1] @ u) - 1.0) < 0.01


@pytest.mark.parametrize(
    "friction_tc",
    [
        pytest.param(None, marks=pytest.mark.xfail(strict=True, reason="10 ms: -4.8 %")),
        0.002,
    ],
)
def test_mujoco_bend_matches_the_ode(monkeypatch, friction_tc: float | None) -> None:
    """MuJoCo's downhill bend across the slope within 1 % of the ODE's: a strict xfail on the
    default friction reference (``PLANAR_SETTINGS.solreffriction`` 10 ms: -4.8 %), passing at
    2 ms (-0.5 %). Measured 5 / 10 / 20 ms: -2.2 / -4.8 / -9.7 %: the shortfall grows with the
    friction rows' time constant. MuJoCo's soft friction acts against the friction residual
    ``a_t + b v_t`` (``b = 2 / (d_max timeconst)``; MuJoCo documentation, "Computation", soft
    constraints), not against the slip velocity alone, so part of a sideways pull (the tilt
    across the slide, any lateral force) is held by friction while the box slides. The tilt
    itself is mapped right (uphill / downhill above); the 2 ms reference is not the default
    for other reasons (``robogs.physics.engines.mujoco_engine``, "Planar joint set")."""
    pytest.importorskip("mujoco")
    if friction_tc is not None:
        import dataclasses

        import robogs.format.mjcf as mj
        import robogs.physics.engines.mujoco_engine as me

        s = dataclasses.replace(mj.PLANAR_SETTINGS, solreffriction=(friction_tc, 1.0))
        monkeypatch.setattr(mj, "PLANAR_SETTINGS", s)
        monkeypatch.setattr(me, "PLANAR_SETTINGS", s)
    path, want, u = _across("mujoco")
    assert abs(float(path[-1] @ u) / float(want[-1] @ u) - 1.0) < 0.01


def test_tilt_sign_flips_the_slide() -> None:
    """Mutation: the tilt negated on the planar engine moves the downhill stop by more than
    the 1 mm tolerance, so the tests above can fail on a sign error."""
    g = (0.25, -0.15)
    u = np.asarray(g) / np.hypot(*g)
    down = math.atan2(u[1], u[0])
    good = _run(g, [down], "planar")[0]
    bad = _run((-g[0], -g[1]), [down], "planar")[0]
    assert np.hypot(*(good[-1] - bad[-1])) > 5e-3


@pytest.mark.parametrize("mutation", ["swap_axes", "small_angle_halved", "negated"])
def test_mutated_mujoco_mapping_is_caught(monkeypatch, mutation: str) -> None:
    """Mutations of MuJoCo's tilt mapping (``NATIVE["table_tilt"]``: axes swapped, half the
    pull, the sign flipped) read a tilt off by far more than the uphill / downhill test's 1 %."""
    pytest.importorskip("mujoco")
    from robogs.physics.engines import mujoco_effects

    def bad(model, th, slots) -> None:
        gx, gy = th["g_x"], th["g_y"]
        if mutation == "swap_axes":
            gx, gy = gy, gx
        elif mutation == "small_angle_halved":
            gx, gy = 0.5 * gx, 0.5 * gy
        else:
            gx, gy = -gx, -gy
        model.opt.gravity[0] += gx
        model.opt.gravity[1] += gy

    monkeypatch.setitem(mujoco_effects.NATIVE, "table_tilt", bad)
    u = np.array([1.0, 0.0])
    paths = _run((0.3, 0.0), [0.0, math.pi], "mujoco")
    read = 0.5 * (_decel(paths[1], -u) - _decel(paths[0], u))
    assert abs(read - 0.3) > 0.1 * 0.3, read

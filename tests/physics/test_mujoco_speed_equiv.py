"""The fast MuJoCo fitting path gives the old path's answers (issue 16, speed).

``MujocoFit`` runs its rollouts on ``mujoco.batch`` (persistent states, per-group schedules,
each distinct rollout once). Oracles:

* without steps taken alone (no grasp, no force effect) the old ``mujoco.rollout`` path
  (``stepper="rollout"``) must agree within 1e-9 m;
* with a per-step force effect (on in one set, off in the other) and a grasp-and-release
  trajectory beside a push, a plain loop of ``mj_step`` on one ``MjData`` per rollout, the force
  computed every step for every rollout, must agree within 1e-9 m; the old path, whose single
  steps restart the solver cold, stays within the stated bound;
* a rollout repeated in the batch (a sensor-only change, an untouched trajectory) is run once and
  gives the same poses as its own call;
* the rest cut (steps where the box rests and the pusher is out of reach repeat the rest pose)
  agrees with the same rollouts stepped in full within 1e-6 m.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
import torch

pytest.importorskip("mujoco.batch")

from robogs.format.errors import InputError  # noqa: E402
from robogs.physics.effects import get_effect  # noqa: E402
from robogs.physics.engines import mujoco_fit  # noqa: E402
from robogs.physics.engines.base import make_drive  # noqa: E402
from robogs.physics.engines.mujoco_fit import MujocoFit  # noqa: E402
from robogs.physics.scene import base_params, scene_from_physics  # noqa: E402
from robogs.physics.space import ParamSpace  # noqa: E402

DT = 1e-3
HZ = 0.025  # box half height [m]
OLD_PATH_BOUND_M = 1e-5
"""Bound on |batch - rollout path| with single steps: the rollout path restarts MuJoCo's solver
cold at every call (each single step), the batch keeps the warm start; the converged contact
forces differ within the solver tolerance (measured up to 5e-7 m on the 9-push scenario)."""


def _physics() -> dict:
    return {
        "gravity_mps2": [0.0, 0.0, -9.81],
        "objects": {
            "box": {
                "equation": "rigid",
                "mass_kg": 0.4,
                "size_m": [0.08, 0.06, 0.05],
                "friction_dynamic": 0.3,
                "friction_static": 0.3,
            },
            "table": {"equation": "static", "plane_z_m": 0.0},
            "pusher": {"equation": "kinematic", "shape": "sphere", "radius_m": 0.01},
        },
    }


def _ramp(n: int, v: float, start: int = 0, ramp: int = 60) -> np.ndarray:
    """[n] positions [m] of a smooth start to speed ``v`` [m/s] at step ``start``."""
    s = np.clip((np.arange(n) - start) / ramp, 0.0, 1.0)
    vel = v * s * s * (3 - 2 * s)
    return np.concatenate([[0.0], np.cumsum(vel[:-1]) * DT])


def _drive(grasp: bool, n: int = 401):
    """Trajectory 0: a push along +x, 20 mm off the centre line. Trajectory 1: a box carried
    along +x from rest (grasped from the start), released at step 200 to slide (``grasp``), or
    a centred push."""
    pusher = np.zeros((2, n, 3))
    pusher[0, :, 0] = -0.058 + _ramp(n, 0.25)
    pusher[0, :, 1] = 0.02
    pusher[:, :, 2] = HZ
    if grasp:
        pusher[1, :, 0] = _ramp(n, 0.4)
    else:
        pusher[1, :, 0] = -0.058 + _ramp(n, 0.3)
    obs = np.tile(np.linspace(0.0, (n - 1) * DT, 21), (2, 1))
    drive = make_drive(DT, pusher, np.zeros((2, n)), obs, np.array([[0, 0, HZ]] * 2), np.zeros(2))
    if grasp:
        drive.grasp[1, :200] = True
    return drive


def _setup(effects: list[str]):
    phys = _physics()
    scene = scene_from_physics(phys, "box", dt=DT)
    space = ParamSpace(base_params(scene), [get_effect(n) for n in effects])
    return phys, scene, space


def _sets(space: ParamSpace, n: int = 2) -> torch.Tensor:
    """``n`` parameter sets: the nominal base, the second with 10 % more dynamic friction."""
    th = np.stack([space.zero] * n)
    c = space.index("base", "friction_dynamic")
    th[1, c] = th[0, c] * 1.1
    return torch.as_tensor(th)


def _dense(sim: MujocoFit, th, space, drive, scene, local=None) -> np.ndarray:
    out = sim.simulate(th, space, drive, scene, init_offset=local)
    return out.dense_pos.numpy()


def test_batch_equals_rollout_path_without_single_steps(monkeypatch):
    """Two friction values x two pushes: the batch and the old rollout path agree within
    OLD_PATH_BOUND_M (the old path's calls, 256 steps at most and split at the strike events,
    each restart the solver cold: 2e-8 m here); without strike events, and the old path running
    each rollout in one call, within 1e-9 m."""
    phys, scene, space = _setup([])
    drive = _drive(grasp=False)
    th = _sets(space)
    a = _dense(MujocoFit(phys, "box", dt=DT, stepper="batch"), th, space, drive, scene)
    old = MujocoFit(phys, "box", dt=DT, stepper="rollout")
    b = _dense(old, th, space, drive, scene)
    assert np.ptp(a[..., 0], axis=-1).min() > 0.02  # the boxes were pushed
    assert np.abs(a[0] - a[1]).max() > 1e-4  # the friction change shows
    assert np.abs(a - b).max() <= OLD_PATH_BOUND_M, np.abs(a - b).max()
    new = MujocoFit(phys, "box", dt=DT, stepper="batch")
    new.strike_events = old.strike_events = False
    a = _dense(new, th, space, drive, scene)
    monkeypatch.setattr(mujoco_fit, "_MAX_CHUNK", drive.n_steps)
    b = _dense(old, th, space, drive, scene)
    assert np.abs(a - b).max() <= 1e-9, np.abs(a - b).max()
    c = _dense(new, th, space, drive, scene)
    assert np.array_equal(a, c)  # the batch does not depend on its call lengths
    two = MujocoFit(phys, "box", dt=DT, threads=2, stepper="batch")
    two.strike_events = False
    assert np.array_equal(a, _dense(two, th, space, drive, scene))  # nor on its threads


def _mj_step_loop(sim: MujocoFit, args: dict, scene) -> tuple[np.ndarray, int]:
    """Dense poses [R, S, 7]: one MjData per rollout, one ``mj_step`` per step, the force
    effects' wrench computed every step for every rollout, grasps held by :func:`_carry_ref`,
    the pusher's strike events (``MujocoFit._strike``) checked at every step (the runners check
    only from each strike horizon on); and the number of steps with a strike."""
    full = mujoco.mjtState.mjSTATE_FULLPHYSICS
    drive, t_of = args["drive"], args["t_of"]
    n_s = drive.n_steps
    grasp, park, body, force_fx = args["grasp"], args["park"], args["body"], args["force_fx"]
    pusher = drive.pusher.numpy()
    ee_yaw = drive.ee_yaw.numpy()
    cvel = drive.pusher_vel.numpy()
    rate = drive.ee_yaw_rate.numpy()
    onset = grasp & ~np.pad(grasp, ((0, 0), (1, 0)))[:, :-1]
    out = np.empty((len(t_of), n_s, 7))
    sim._strike_begin(drive, scene, len(t_of), False)
    strikes = 0
    for r, t in enumerate(t_of):
        m = args["models_r"][r]
        d = mujoco.MjData(m)
        mujoco.mj_setState(m, d, args["x"][r], full)
        x = np.empty((1, mujoco.mj_stateSize(m, full)))
        mujoco.mj_getState(m, d, x[0], full)
        out[r, 0] = sim.lay.pose(x)[0]
        tt = np.array([t])
        rel_p, rel_q = np.zeros((1, 3)), np.array([[1.0, 0, 0, 0]])
        body_r = type(body)(**{k: v[r : r + 1] for k, v in vars(body).items()})
        fx_r = [(e, {k: v[r : r + 1] for k, v in th.items()}) for e, th in force_fx]
        if onset[t, 0]:
            rel_p, rel_q = sim._grasp_rel(
                x, pusher[:, 0], ee_yaw[:, 0], tt, onset[:, 0], rel_p, rel_q
            )
        for k in range(n_s - 1):
            if onset[t, k + 1]:
                rel_p, rel_q = sim._grasp_rel(
                    x, pusher[:, k], ee_yaw[:, k], tt, onset[:, k + 1], rel_p, rel_q
                )
            if sim._strike(x, k, tt, body_r, grasp[tt, k] | (park[tt, k] != 0), [r]).any():
                mujoco.mj_setState(m, d, x[0], full)
                strikes += 1
            if fx_r:
                d.xfrc_applied[:] = 0.0
                d.xfrc_applied[sim.slots.body] = sim._forces(x, body_r, fx_r)[0]
            d.ctrl[:] = args["ctrl"][t, k]
            mujoco.mj_step(m, d)
            mujoco.mj_getState(m, d, x[0], full)
            if sim.pq is not None:
                x[0, sim.pq + 2] += park[t, k + 1] - park[t, k]
            if grasp[t, k + 1]:
                j = k + 1
                _carry_ref(
                    sim, x, pusher[t, j], cvel[t, j], ee_yaw[t, j], rate[t, j], rel_p[0], rel_q[0]
                )
            mujoco.mj_setState(m, d, x[0], full)
            out[r, k + 1] = sim.lay.pose(x)[0]
    sim._strike_ctx = None
    return out, strikes


def _carry_ref(sim: MujocoFit, x: np.ndarray, ee, v_ee, yaw: float, rate: float, rel_p, rel_q):
    """The rigid carry, one scalar at a time, into state row ``x`` [1, nstate]: the object at
    ``ee + R(yaw) rel_p`` (not below its resting height), turned ``q(yaw) rel_q``, moving at
    ``v_ee + rate z x R(yaw) rel_p`` and turning at ``rate`` about z."""
    c, s = math.cos(yaw), math.sin(yaw)
    rx, ry = c * rel_p[0] - s * rel_p[1], s * rel_p[0] + c * rel_p[1]
    pos = [ee[0] + rx, ee[1] + ry, max(ee[2] + rel_p[2], sim.rest_z)]
    hw, hz = math.cos(yaw / 2), math.sin(yaw / 2)  # q(yaw) = (hw, 0, 0, hz)
    aw, ax, ay, az = rel_q
    q = [hw * aw - hz * az, hw * ax - hz * ay, hw * ay + hz * ax, hw * az + hz * aw]
    sim.lay.set_pose(x, np.array([pos]), np.array([q]))
    vel = [v_ee[0] - rate * ry, v_ee[1] + rate * rx, v_ee[2]]
    sim.lay.set_vel(x, np.array([vel]), np.array([[0.0, 0.0, rate]]))


@pytest.mark.parametrize("joints", ["planar", "free"])
def test_the_carried_states_are_the_rigid_carry(joints):
    """The runners' held states, made for every step of a grasp at its onset, equal the scalar
    rigid carry (:func:`_carry_ref`) at random EE poses, velocities and grasp poses, on both
    joint sets (1e-12); a grasp held below the resting height is lifted to it."""
    sim = MujocoFit(_physics(), "box", dt=DT, joints=joints)
    assert sim.lay.planar == (joints == "planar")
    rng = np.random.default_rng(3)
    t_n, s_n = 3, 40
    arrays = (
        rng.normal(size=(t_n, s_n, 3)) * 0.1,
        rng.uniform(-3.0, 3.0, (t_n, s_n)),
        rng.normal(size=(t_n, s_n, 3)),
        rng.normal(size=(t_n, s_n)),
    )
    tt, ks = np.array([2, 0, 2]), np.array([0, 7, 39])
    rel_p = rng.normal(size=(3, 3)) * 0.05
    rel_q = rng.normal(size=(3, 4))
    rel_q /= np.linalg.norm(rel_q, axis=1, keepdims=True)
    got = sim._carried(tt, ks, arrays, rel_p, rel_q)
    n_x = mujoco.mj_stateSize(sim.eng.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    lifted = 0
    for i, t in enumerate(tt):
        for j, k in enumerate(ks):
            x = np.zeros((1, n_x))
            p, y, v, w = (a[t, k] for a in arrays)
            _carry_ref(sim, x, p, v, y, w, rel_p[i], rel_q[i])
            np.testing.assert_allclose(got[i, j], x[0, sim.lay.columns()], rtol=0, atol=1e-12)
            lifted += p[2] + rel_p[i, 2] < sim.rest_z
    assert lifted > 0


@pytest.mark.parametrize("windows", [((0, 200),), ((0, 120), (200, 300))], ids=["one", "regrasp"])
def test_batch_with_force_effect_and_grasp_equals_mj_step_loop(windows):
    """Quadratic drag on in set 1 (off in set 0), a push beside a carry-and-release (or a carry,
    a release and a second grasp where the box lies): the batch runner equals a plain mj_step
    loop (1e-9 m) and the old rollout path within OLD_PATH_BOUND_M; its held states made in
    blocks of 7 steps (a block straddles the release and the second grasp) give the same
    poses."""
    phys, scene, space = _setup(["quadratic_drag"])
    drive = _drive(grasp=True)
    drive.grasp[1] = False
    for a, b in windows:
        drive.grasp[1, a:b] = True
    th = _sets(space)
    th[1, space.owner_columns("quadratic_drag")[0]] = 2.0
    sim = MujocoFit(phys, "box", dt=DT, stepper="batch")
    seen = {}
    run = sim._run_batch

    def spy(models_r, x, ctrl, t_of, drive, body, force_fx, grasp, park, pstate=None):
        seen.update(models_r=models_r, x=np.array(x), ctrl=ctrl, t_of=t_of, drive=drive)
        seen.update(body=body, force_fx=force_fx, grasp=grasp, park=park)
        out = run(models_r, x, ctrl, t_of, drive, body, force_fx, grasp, park, pstate)
        seen["dense"] = out
        return out

    sim._run_batch = spy
    a = _dense(sim, th, space, drive, scene)
    assert sim.last_rollouts == 4
    assert np.ptp(a[:, 1, :, 0], axis=-1).min() > 0.05  # carried and slid
    assert np.abs(a[0] - a[1]).max() > 1e-4  # drag and friction show
    ref, strikes = _mj_step_loop(sim, seen, scene)
    assert strikes >= 2  # the push starts with a strike event (one per set)
    assert np.abs(seen["dense"] - ref).max() <= 1e-9, np.abs(seen["dense"] - ref).max()
    b = _dense(MujocoFit(phys, "box", dt=DT, stepper="rollout"), th, space, drive, scene)
    assert np.abs(a - b).max() <= OLD_PATH_BOUND_M, np.abs(a - b).max()
    with pytest.MonkeyPatch.context() as mp:  # held states made 7 steps at a time: the same
        mp.setattr(mujoco_fit, "_CARRY_BLOCK", 7)
        sim7 = MujocoFit(phys, "box", dt=DT, stepper="batch")
        assert np.array_equal(a, _dense(sim7, th, space, drive, scene))


def test_repeated_rollouts_run_once_and_agree_with_their_own_call():
    """Rows: base, base + time offset (sensor only), more friction, base again; trajectory 1 of
    the base shifted 0.1 mm in one row. 2 dynamics sets x 2 trajectories + 1 shifted start =
    5 distinct rollouts of 8, each equal to the same row simulated alone."""
    phys, scene, space = _setup(["time_offset"])
    drive = _drive(grasp=False, n=201)
    th = torch.as_tensor(np.stack([space.zero] * 4))
    th[1, space.owner_columns("time_offset")[0]] = 2e-3
    th[2, space.index("base", "friction_dynamic")] *= 1.2
    local = torch.zeros((4, 2, 3), dtype=torch.float64)
    local[3, 1, 0] = 1e-4
    sim = MujocoFit(phys, "box", dt=DT)
    got = sim.simulate(th, space, drive, scene, init_offset=local)
    assert sim.last_rollouts == 5
    for i in range(4):
        one = sim.simulate(th[i : i + 1], space, drive, scene, init_offset=local[i : i + 1])
        assert sim.last_rollouts == 2
        assert torch.equal(one.dense_pos[0], got.dense_pos[i])
        assert torch.equal(one.pos[0], got.pos[i])
    assert torch.equal(got.dense_pos[0], got.dense_pos[1])  # a sensor parameter: same motion
    assert not torch.equal(got.pos[0], got.pos[1])  # ... sampled later


def test_unknown_stepper_is_refused():
    with pytest.raises(InputError, match="stepper"):
        MujocoFit(_physics(), "box", dt=DT, stepper="gpu")


REST_CUT_BOUND_M = 1e-6
"""Bound on |rest cut - full rollout|: the cut repeats the rest pose where the full rollout
keeps an equilibrium; only a tilted table lets the soft friction creep there (0.05-0.12 um
measured on the 9 pushes at g_x = 0.05 m/s^2; 4e-9 m without tilt)."""


def test_rest_cut_equals_the_full_rollouts(monkeypatch):
    """The batch runner skips the steps before the pusher comes within reach of the resting
    box and after the box rests for good (pusher out of reach for the rest of the trajectory),
    repeating the rest pose. Oracle: the same rollouts stepped in full (the cut switched off),
    on the generator's 9 centred pushes with no effect, a table tilt, Stribeck (a per-step
    force effect) and viscous damping: within :data:`REST_CUT_BOUND_M`, yaw within 1e-6 rad,
    in under 40 % of the steps (the box moves 0.3 of the 1.2 s). A tilt beyond the friction
    angle (the box slides from the start; its first steps show it) takes no cut, and nor does
    the rest of its group: the same bounds."""
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",))
    eng = Engine(rec, backend="mujoco", threads=1)
    sim = eng._mujoco
    names = ("table_tilt", "stribeck", "viscous_damping")
    sp = eng.space([get_effect(n) for n in names])
    th = np.stack([eng.start(sp)] * 5)
    th[1, sp.index("table_tilt", "g_x")] = 0.05
    th[2, sp.index("stribeck", "dmu")] = 0.1
    th[3, sp.index("viscous_damping", "c")] = 1.0
    th[4, sp.index("table_tilt", "g_x")] = 1.0  # beyond the friction angle: it slides off
    th[4, sp.index("base", "friction_dynamic")] = 0.05
    th = torch.as_tensor(th)
    args = (sp, eng.prep.drive, eng.prep.scene)
    cut = [sim.simulate(th[:4], *args), sim.simulate(th, *args)]
    steps_cut = sim.last_steps
    # its group (no force effect: sets 0, 1, 3, 4) steps in full; Stribeck's group is cut
    assert steps_cut > 0.75 * sim.last_rollouts * (eng.prep.drive.n_steps - 1)
    sim.simulate(th[:4], *args)
    steps_cut = sim.last_steps
    monkeypatch.setattr(MujocoFit, "_cut_ok", lambda self: False)
    full = sim.simulate(th, *args)
    assert sim.last_steps == sim.last_rollouts * (eng.prep.drive.n_steps - 1)
    assert steps_cut < 0.4 * sim.last_steps * 4 / 5, (steps_cut, sim.last_steps)
    moved = (full.dense_pos[4, :, 300] - full.dense_pos[4, :, 0]).norm(dim=-1)
    assert float(moved.min()) > 0.01  # the steep tilt moves the box before the pusher comes
    for got, n in ((cut[0], 4), (cut[1], 5)):
        assert float((got.dense_pos - full.dense_pos[:n]).abs().max()) < REST_CUT_BOUND_M
        assert float((got.dense_yaw - full.dense_yaw[:n]).abs().max()) < 1e-6
    # no tilt: the rest is an equilibrium to the solver's tolerance (4e-9 m measured)
    assert float((cut[0].dense_pos[0] - full.dense_pos[0]).abs().max()) < 1e-8


def test_impact_events_are_the_same_on_both_runners():
    """Restitution's impact events (``MujocoFit._bounce``) on both runners: a box dropped 3 cm
    while sliding at 0.4 m/s, and one carried 3 cm up and released (a grasp), e = 0.5 in one
    set and 0 in the other: the batch runner and the old rollout path agree within
    OLD_PATH_BOUND_M, and the sets differ where the box bounces (e^2 of 3 cm, 7.5 mm up)."""
    phys, scene, space = _setup(["restitution"])
    n = 401
    pusher = np.zeros((2, n, 3))
    pusher[0, :, 2] = 1.0  # out of reach
    pusher[1, :, 2] = HZ + 0.03
    obs = np.tile(np.linspace(0.0, (n - 1) * DT, 81), (2, 1))
    start = np.array([[0, 0, HZ + 0.03], [0.3, 0, HZ + 0.03]])
    drive = make_drive(DT, pusher, np.zeros((2, n)), obs, start, np.zeros(2))
    drive.init_vel = torch.tensor([[0.4, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    drive.grasp[1, :100] = True
    th = np.stack([space.zero] * 2)
    th[1, space.index("restitution", "e_delta")] = 0.5
    th = torch.as_tensor(th)
    a = _dense(MujocoFit(phys, "box", dt=DT, stepper="batch"), th, space, drive, scene)
    b = _dense(MujocoFit(phys, "box", dt=DT, stepper="rollout"), th, space, drive, scene)
    assert np.abs(a - b).max() <= OLD_PATH_BOUND_M, np.abs(a - b).max()
    for t in (0, 1):
        z = a[:, t, :, 2] - HZ
        assert z[0].max(initial=0.0) < 0.03 + 1e-6  # plastic: no rise after the drop
        hit = int(np.argmax(z[1] < 1e-3))
        assert 0.0065 < z[1, hit:].max() < 0.0085, z[1, hit:].max()  # 7.5 mm

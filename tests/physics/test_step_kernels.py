"""The compiled steps of the planar model (:mod:`robogs.physics.step_kernels`) against the numpy
reference (:data:`robogs.physics.model.REFERENCE_STEPS`): the same results to the bit.

Oracles: the reference functions on random states that cover every branch (pusher: outside and
inside the box, one and two end spheres, each LCP case, a capsule flush with a face, grasped
trajectories, spheres above the box; table: flight, resting contact, bounces above and below the
bounce speed, sticking and sliding, per-state friction coefficients as effect hooks return
them; grasped objects against the rigid carry's closed form); and whole rollouts of both scenario designs with the kernels switched off.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import robogs.physics.model as M
import robogs.physics.step_kernels as CK

pytest.importorskip("numba", reason="the compiled kernels need the optional package numba")

SCENE = SimpleNamespace(size=(0.08, 0.06, 0.05), pusher_radius=0.01)


def _states(j_n: int, seed: int, m_n: int = 3, t_n: int = 400):
    """Random states [M, T] of a box near the pushers [T, J] (positions within 6 cm of the box
    centre, so that a third to a half of them touch), with a flush capsule on every 10th
    trajectory."""
    r = np.random.default_rng(seed)
    hx, hy, hz = (0.5 * s for s in SCENE.size)
    p = np.zeros((m_n, t_n, 3))
    p[..., :2] = r.normal(0.0, 0.01, (m_n, t_n, 2))
    p[..., 2] = hz + r.normal(0.0, 0.01, (m_n, t_n))
    yaw = r.uniform(-np.pi, np.pi, (m_n, t_n))
    pts = np.zeros((t_n, j_n, 3))
    pts[..., :2] = r.uniform(-0.06, 0.06, (t_n, 1, 2)) + r.normal(0.0, 0.02, (t_n, j_n, 2))
    pts[..., 2] = hz + r.uniform(-2.0 * hz, 2.0 * hz, (t_n, j_n))
    if j_n == 2:  # a capsule against the box's +x face (box 0 at the origin, yaw 0), 0.5 mm off
        flush = np.arange(0, t_n, 10)
        p[0, flush] = (0.0, 0.0, hz)
        yaw[0, flush] = 0.0
        pts[flush, 0] = (hx + SCENE.pusher_radius + 5e-4, -0.02, hz)
        pts[flush, 1] = (hx + SCENE.pusher_radius + 5e-4, 0.02, hz)
    pv = r.normal(0.0, 0.3, (t_n, j_n, 3))
    vx, vy = r.normal(0.0, 0.2, (m_n, t_n)), r.normal(0.0, 0.2, (m_n, t_n))
    wf = r.normal(0.0, 2.0, (m_n, t_n))
    com = r.normal(0.0, 0.005, (m_n, 2, 1))
    mass = r.uniform(0.2, 0.6, (m_n, 1))
    inertia = mass * (SCENE.size[0] ** 2 + SCENE.size[1] ** 2) / 12.0 * r.uniform(0.8, 1.2)
    grasp = r.uniform(size=t_n) < 0.05
    return p, yaw, vx, vy, wf, com[:, 0], com[:, 1], mass, inertia, pts, pv, grasp


@pytest.mark.parametrize("j_n", [1, 2])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_impulse_matches_the_numpy_reference_to_the_bit(j_n: int, seed: int) -> None:
    p, yaw, vx, vy, wf, cx, cy, mass, inertia, pts, pv, grasp = _states(j_n, seed)
    args = (np.cos(yaw), np.sin(yaw), vx, vy, wf, cx, cy, mass, inertia, pts, pv, grasp, 1e-3)
    ref = M._pusher_impulse(SCENE, p, *args)
    fast = M._steps(np.dtype(np.float64))
    assert fast.impulse is not M._pusher_impulse  # the compiled one
    out = fast.impulse(SCENE, p, *args)
    touched = ref[3] != 0.0
    assert 0.1 < touched.mean() < 0.9  # the states exercise contact and no contact
    for a, b in zip(ref, out, strict=True):
        assert a.shape == b.shape and np.array_equal(a, b)


@pytest.mark.parametrize("j_n", [1, 2])
def test_apart_matches_the_numpy_reference(j_n: int) -> None:
    """Per trajectory (T = 1, so that both answers are seen) over 2000 random states."""
    p, _, vx, vy, wf, cx, cy, _, _, pts, _, grasp = _states(j_n, 7, m_n=2, t_n=2000)
    speed = np.hypot(*np.moveaxis(np.random.default_rng(8).normal(0, 0.3, (2000, j_n, 2)), -1, 0))
    com_r = np.hypot(cx, cy)
    apart = M._steps(np.dtype(np.float64)).apart
    got = []
    for t in range(2000):
        s = slice(t, t + 1)
        args = (p[:, s], vx[:, s], vy[:, s], wf[:, s], com_r, pts[s], speed[s], grasp[s], 2e-3)
        ref = M._pusher_apart(SCENE, *args)
        assert apart(SCENE, *args) is ref
        got.append(ref)
    assert 0.2 < np.mean(got) < 0.8


def _table_states(seed: int, m_n: int = 3, t_n: int = 500):
    """Random [M, T] states around the table: a third in flight (gap up to 5 mm), the rest
    touching or just below, falling at 0-1.5 m/s (bounce speed 0.3 m/s) or at rest."""
    r = np.random.default_rng(seed)
    v = r.normal(0.0, 0.3, (m_n, t_n, 3))
    v[..., 2] = np.where(r.uniform(size=(m_n, t_n)) < 0.5, -r.uniform(0, 1.5, (m_n, t_n)), 0.0)
    v[:, ::7] = 0.0  # at rest
    w = r.normal(0.0, 3.0, (m_n, t_n))
    w[:, ::7] = 0.0
    acc = r.normal(0.0, 0.5, (m_n, t_n, 3))
    alpha = r.normal(0.0, 5.0, (m_n, t_n))
    gap = np.where(r.uniform(size=(m_n, t_n)) < 0.33, r.uniform(0, 5e-3, (m_n, t_n)), 0.0)
    gap -= r.uniform(0.0, 1e-4, (m_n, t_n)) * (r.uniform(size=(m_n, t_n)) < 0.2)
    e_rest = r.uniform(0.0, 0.6, (m_n, 1))
    return v, w, acc, alpha, gap, e_rest


@pytest.mark.parametrize("seed", [0, 1])
def test_table_steps_match_the_numpy_reference_to_the_bit(seed: int) -> None:
    ref, fast = M.REFERENCE_STEPS, M._steps(np.dtype(np.float64))
    assert fast.normal is not ref.normal
    v, w, acc, alpha, gap, e_rest = _table_states(seed)
    args = (v, w, acc, alpha, gap, e_rest, 1e-3, 9.81, 0.3)
    a, b = ref.normal(*args), fast.normal(*args)
    for x, y in zip(a, b, strict=True):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    vx, vy, vz, wf, lam_n, contact, rebound, approach, speed2, _ = a
    assert 0.2 < contact.mean() < 0.9 and rebound.any() and (contact & ~rebound).any()
    r = np.random.default_rng(10 + seed)
    kr = r.uniform(0.5, 2.0, (3, 1))
    for mu_s, mu_d in (
        (np.full((3, 1), 0.4), np.full((3, 1), 0.3)),  # the body's, [M, 1]
        (r.uniform(0.2, 0.6, vx.shape), r.uniform(0.1, 0.5, vx.shape)),  # a hook's, [M, T]
    ):
        fargs = (vx, vy, wf, speed2, lam_n, contact, mu_s, mu_d, kr, 0.03)
        fa, fb = ref.friction(*fargs), fast.friction(*fargs)
        for x, y in zip(fa, fb, strict=True):
            assert np.array_equal(x, y)
        sticking = contact & (fa[0] == 0.0) & (vx != 0.0)
        assert sticking.any() and (contact & (fa[0] != 0.0)).any()
    p = r.normal(0.0, 0.1, vx.shape + (3,))
    yaw = r.uniform(-3.0, 3.0, vx.shape)
    iargs = (p, vx, vy, vz, wf, yaw, rebound, gap, approach, 1e-3, 0.025)
    for x, y in zip(ref.integrate(*iargs), fast.integrate(*iargs), strict=True):
        assert np.array_equal(x, y)


def _carry_states(seed: int, m_n: int = 3, t_n: int = 300):
    """Random states [M, T], an EE pose and twist [T] and grasp-frame offsets [M, T]; every
    third trajectory grasped, and one reads at a non-contiguous column as the model passes."""
    r = np.random.default_rng(seed)
    p, v = r.normal(0.0, 0.1, (m_n, t_n, 3)), r.normal(0.0, 0.3, (m_n, t_n, 3))
    yaw, w = r.uniform(-3.0, 3.0, (m_n, t_n)), r.normal(0.0, 2.0, (m_n, t_n))
    att = np.arange(t_n) % 3 == 0
    ee_yaw = r.uniform(-3.0, 3.0, (t_n, 4))[:, 1]
    rel_p, rel_yaw = r.normal(0.0, 0.03, (m_n, t_n, 3)), r.normal(0.0, 0.5, (m_n, t_n))
    ee_pos = r.normal(0.0, 0.3, (t_n, 4, 3))[:, 2]
    ee_rate, ee_vel = r.normal(0.0, 1.0, (t_n, 4))[:, 3], r.normal(0.0, 0.4, (t_n, 4, 3))[:, 0]
    c, s = np.cos(ee_yaw), np.sin(ee_yaw)
    return p, v, yaw, w, att, c, s, ee_yaw, rel_p, rel_yaw, ee_pos, ee_rate, ee_vel


@pytest.mark.parametrize("seed", [0, 1])
def test_grasp_carry_matches_the_reference_and_the_rigid_closed_form(seed: int) -> None:
    """Oracle besides the reference: a grasped point rides the EE rigidly, so its world
    position is ``ee + R(ee_yaw) rel`` and its velocity ``ee_vel + rate z x (R rel)``; the
    free trajectories keep their state."""
    ref, fast = M.REFERENCE_STEPS.carry, M._steps(np.dtype(np.float64)).carry
    assert fast is not ref
    args = _carry_states(seed)
    a, b = ref(*args), fast(*args)
    for x, y in zip(a, b, strict=True):
        assert x.shape == y.shape and np.array_equal(x, y)
    p, v, yaw, w, att, c, s, ee_yaw, rel_p, rel_yaw, ee_pos, ee_rate, ee_vel = args
    p2, v2, yaw2, w2 = a
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # [T, 2, 2]
    off = np.einsum("tij,mtj->mti", rot, rel_p[..., :2])
    assert np.allclose(p2[:, att, :2], (ee_pos[:, :2] + off)[:, att], atol=1e-15)
    assert np.allclose(p2[:, att, 2], (ee_pos[:, 2] + rel_p[..., 2])[:, att], atol=1e-15)
    swirl = ee_rate[:, None] * np.stack([-off[..., 1], off[..., 0]], -1)
    assert np.allclose(v2[:, att, :2], (ee_vel[:, :2] + swirl)[:, att], atol=1e-15)
    assert np.allclose(yaw2[:, att], (ee_yaw + rel_yaw)[:, att])
    assert (w2[:, att] == ee_rate[att]).all()
    for new, old in ((p2, p), (v2, v), (yaw2, yaw), (w2, w)):
        assert np.array_equal(new[:, ~att], old[:, ~att])
    assert not np.shares_memory(b[0], p)  # the caller's state is not written


@pytest.mark.slow
@pytest.mark.parametrize("design", ["A", "B"])
def test_rollouts_are_the_same_with_and_without_the_kernels(monkeypatch, design: str) -> None:
    """Design A (capsule pusher, 20 trajectories) and design B (sphere, 9): perturbed parameter
    sets and start poses through ``Engine.evaluate``, kernels on and off."""
    from robogs.physics.engine import Engine

    if design == "A":
        from robogs.synth.scenarios import make_scenario

        rec = make_scenario("com_offset+stribeck", seed=1, noise="nominal")
    else:
        from robogs.synth.scenarios.design_b import make_design_b

        rec = make_design_b("restitution", seed=3, with_detectability=False)
    eng = Engine(rec, backend="planar")
    space = eng.space(eng.check_effects(["table_tilt", "stribeck", "com_offset", "restitution"]))
    r = np.random.default_rng(0)
    th = np.repeat(eng.start(space)[None], 4, 0)
    th[1:] += r.normal(0.0, 0.01, th[1:].shape)
    loc = r.normal(0.0, 1e-3, (4, eng.prep.n_traj, 3))
    fast = eng.evaluate(space, th, loc)
    monkeypatch.setattr(CK, "kernels", lambda: None)
    assert M._steps(np.dtype(np.float64)) is M.REFERENCE_STEPS
    ref = eng.evaluate(space, th, loc)
    assert np.array_equal(np.isnan(ref), np.isnan(fast))
    assert np.array_equal(np.nan_to_num(ref), np.nan_to_num(fast))


def test_without_numba_the_reference_runs_and_the_reason_is_kept(monkeypatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "numba" else real(name, *a)
    )
    CK.kernels.cache_clear()
    try:
        assert CK.kernels() is None
        assert "numba" in (CK.unavailable_reason() or "")
        assert M._steps(np.dtype(np.float64)) is M.REFERENCE_STEPS
    finally:
        CK.kernels.cache_clear()
    assert M._steps(np.dtype(np.float32)) is M.REFERENCE_STEPS

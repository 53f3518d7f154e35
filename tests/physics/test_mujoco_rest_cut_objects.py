"""The MuJoCo batch runner's rest cut on a scene of several objects (issue 16).

The cut repeats the rest pose where nothing can move: before the pusher first comes within
2 mm of any object and after every object rests for good, while no two objects are within 2 mm
of each other (:meth:`~robogs.physics.engines.mujoco_fit.MujocoFit._first_reach`,
``_still``, ``_apart``). Oracles:

* the same rollouts stepped in full (the cut switched off) on the two-box scenario
  (:mod:`robogs.synth.scenarios.two_objects`: box A pushed into box B 10 mm ahead), both
  boxes within 1e-6 m and 1e-6 rad, with and without a table tilt;
* a box B started 1 mm from A: no step is cut before the pusher comes (a contact could start);
* the lower bound of the distance between two boxes (``_apart``) against a brute-force distance
  of points on their outlines, and exactly at face-to-face gaps;
* grasping drives and a wanted pusher force step in full (the code says why not).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco.batch")

from robogs.physics.effects import get_effect  # noqa: E402
from robogs.physics.engine import Engine  # noqa: E402
from robogs.physics.engines.mujoco_fit import MujocoFit  # noqa: E402
from robogs.synth.scenarios.two_objects import TwoBoxTruth, make_two_objects  # noqa: E402

TRUTH = TwoBoxTruth()
BOUND_M = 1e-6
"""|cut - full|: the rest pose repeats where the full rollout keeps an equilibrium (measured
5e-8 m, 7e-7 rad with a 0.05 m/s^2 tilt, whose soft friction creeps; 3e-14 m on box B)."""


@pytest.fixture(scope="module")
def scene():
    rec = make_two_objects(seed=0, noise=False)
    eng = Engine(rec, backend="mujoco", threads=1)
    space = eng.space([get_effect("table_tilt")])
    th = np.stack([eng.start(space)] * 3)
    th[0, :2] = [TRUTH.mu_a, TRUTH.mu_b]  # B slides further than A: they part
    th[2, space.index("table_tilt", "g_x")] = 0.05  # 0.35 / 0.35: they end touching
    drive = dataclasses.replace(eng.prep.drive, wrench_bin=None)  # poses only
    return eng, space, torch.as_tensor(th), drive


def _run(eng, space, th, drive, cut: bool, monkeypatch):
    sim = eng._mujoco
    with monkeypatch.context() as mp:
        if not cut:
            mp.setattr(MujocoFit, "_cut_ok", lambda self: False)
        res = sim.simulate(th, space, drive, eng.prep.scene)
    return res, sim.last_steps, sim.last_rollouts * (drive.n_steps - 1)


def _max_diff(a, b) -> tuple[float, float]:
    """Largest position [m] and yaw [rad] difference of box A (dense) and B (at its stamps)."""
    pos = float((a.dense_pos - b.dense_pos).abs().max())
    yaw = float((a.dense_yaw - b.dense_yaw).abs().max())
    (pa, ya), (pb, yb) = a.others["box_b"], b.others["box_b"]
    return max(pos, float((pa - pb).abs().max())), max(yaw, float((ya - yb).abs().max()))


def test_rest_cut_two_objects_equals_full_rollouts(scene, monkeypatch):
    """Cut vs full on the two-box scene: within :data:`BOUND_M` for both boxes; the cut steps
    at most 70 % of the steps (measured 67.5 %: the pusher reaches A about a third of the way
    in; the sets ending with A and B touching keep stepping to the end), and the true set
    alone, whose boxes part and rest, at most 55 % (start and end cut)."""
    eng, space, th, drive = scene
    cut, n_cut, n_all = _run(eng, space, th, drive, True, monkeypatch)
    full, n_full, _ = _run(eng, space, th, drive, False, monkeypatch)
    assert n_full == n_all
    dp, dy = _max_diff(cut, full)
    print(f"steps cut {n_cut} of {n_full}; max |cut - full| {dp:.2e} m, {dy:.2e} rad")
    assert dp < BOUND_M and dy < BOUND_M
    assert n_cut < 0.70 * n_full
    true_cut, n_true, n_true_all = _run(eng, space, th[:1], drive, True, monkeypatch)
    true_full, _, _ = _run(eng, space, th[:1], drive, False, monkeypatch)
    print(f"true set: steps cut {n_true} of {n_true_all}")
    assert n_true < 0.55 * n_true_all
    dp, dy = _max_diff(true_cut, true_full)
    assert dp < BOUND_M and dy < BOUND_M


def _first_move(res) -> int:
    """First step at which box A has moved 1 um from its start in any rollout."""
    d = (res.dense_pos - res.dense_pos[:, :, :1]).norm(dim=-1).numpy()
    return int(np.argmax((d > 1e-6).any((0, 1))))


def test_no_start_cut_with_objects_within_reach(scene, monkeypatch):
    """Box B started 1 mm ahead of A's front face (a contact may start between them): every
    rollout steps at least up to the step where A starts to move (no start cut); cut and full
    rollouts still agree."""
    eng, space, th, drive = scene
    sim = eng._mujoco
    (b,) = sim.tracked
    start, yaw = drive.init_pos.numpy(), drive.init_yaw.numpy()
    head = b.init_pos[:, :2] - start[:, :2]
    head /= np.linalg.norm(head, axis=1, keepdims=True)  # B lies ahead of A along its push
    # the pushes are face-on: A's x axis along the heading
    assert np.allclose(np.abs(np.cos(yaw) * head[:, 0] + np.sin(yaw) * head[:, 1]), 1.0)
    close = dataclasses.replace(b, init_pos=b.init_pos.copy())
    reach = 0.5 * (TRUTH.size_a[0] + TRUTH.size_b[0]) + 1e-3
    close.init_pos[:, :2] = start[:, :2] + head * reach
    _, n_far, _ = _run(eng, space, th, drive, True, monkeypatch)
    monkeypatch.setattr(sim, "tracked", [close])
    cut, n_cut, n_all = _run(eng, space, th, drive, True, monkeypatch)
    full, _, _ = _run(eng, space, th, drive, False, monkeypatch)
    k = _first_move(full)
    print(f"B 1 mm from A: steps {n_cut} of {n_all} (B at 10 mm: {n_far}); A moves at {k}")
    assert n_cut >= len(th) * drive.n_traj * k
    dp, dy = _max_diff(cut, full)
    assert dp < BOUND_M and dy < BOUND_M


def _corners(c: np.ndarray, half: np.ndarray, yaw: float) -> np.ndarray:
    """[4, 2] corners of a rectangle (centre [m], half sizes [m], yaw [rad]), in order."""
    pts = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * half[:2]
    r = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    return pts @ r.T + c


def _distance(pa: np.ndarray, pb: np.ndarray) -> float:
    """Distance [m] between two convex polygons (corners in order), 0 where they overlap: the
    least corner-to-edge distance both ways, by brute force."""

    def inside(p, poly):  # p within the convex polygon (counter-clockwise corners)
        e = np.roll(poly, -1, 0) - poly
        w = p - poly
        return bool((e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0] >= 0).all())

    if any(inside(p, pb) for p in pa) or any(inside(p, pa) for p in pb):
        return 0.0
    best = np.inf
    for pts, poly in ((pa, pb), (pb, pa)):
        for a, b in zip(poly, np.roll(poly, -1, 0), strict=True):
            t = np.clip((pts - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
            best = min(best, float(np.linalg.norm(pts - a - t[:, None] * (b - a), axis=1).min()))
    return best


def test_apart_bounds_the_distance(scene):
    """``_apart`` is False whenever two boxes are within 2 mm (brute-force corner-to-edge
    distance, 400 random poses near contact: it never reports apart what is close), and exact
    for faces parallel at 1.9 / 2.1 mm."""
    eng, _, _, _ = scene
    sim = eng._mujoco
    assert sim._cut_ok()
    (la, ha, _, _), (lb, hb, _, _) = sim._cut_objs
    nstate = max(la.q, lb.q) + 8 + max(la.v, lb.v) + 8
    rng = np.random.default_rng(0)
    missed = apart = 0
    for _ in range(400):
        x = np.zeros((1, nstate))
        ya, yb = rng.uniform(-np.pi, np.pi, 2)
        d = rng.normal(size=2)
        d *= (ha[0] + hb[0] + rng.uniform(-0.02, 0.02)) / np.linalg.norm(d)
        la.set_pose(x, [0.0, 0.0, 0.025], [np.cos(ya / 2), 0, 0, np.sin(ya / 2)])
        lb.set_pose(x, [d[0], d[1], 0.025], [np.cos(yb / 2), 0, 0, np.sin(yb / 2)])
        dist = _distance(_corners(np.zeros(2), ha, ya), _corners(d, hb, yb))
        ok = sim._apart(x)
        apart += ok
        missed += ok and dist <= 2e-3
    print(f"{apart} of 400 reported apart")
    assert missed == 0 and 50 < apart < 350
    for gap, want in ((1.9e-3, False), (2.1e-3, True)):
        x = np.zeros((1, nstate))
        la.set_pose(x, [0.0, 0.0, 0.025], [1.0, 0, 0, 0])
        lb.set_pose(x, [ha[0] + hb[0] + gap, 0.003, 0.025], [1.0, 0, 0, 0])
        assert sim._apart(x) is want


def test_rest_cut_off_for_wrench_and_grasp(scene, monkeypatch):
    """A wanted pusher force (the recording's wrench bins) or a grasp in the drive: every
    rollout steps in full."""
    eng, space, th, drive = scene
    _, n, n_all = _run(eng, space, th, eng.prep.drive, True, monkeypatch)
    assert eng.prep.drive.wrench_bin is not None and n == n_all
    grasp = drive.grasp.clone()
    grasp[:, -50:] = True  # held at the end, after everything rests
    _, n, n_all = _run(eng, space, th, dataclasses.replace(drive, grasp=grasp), True, monkeypatch)
    assert n == n_all

"""The optimised rollout reproduces the frozen per-step reference (``_reference_simulate``).

:func:`robogs.physics.model.simulate` steps its states in numpy with the drive's pusher
geometry computed once; ``_reference_simulate.simulate_reference`` is the model as it was
before (torch, everything per step). Both must agree to 1e-12 (m, rad, N) on drives that
exercise every branch: capsule and sphere pushers, off-centre pushes, a grasp from the first
step and one mid-rollout, drops with a bounce, a free slide, wrench bins, the quiet start and
the early stop, the per-trajectory start corrections, and every rigid effect of the catalogue
at once, for several parameter sets.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from _reference_simulate import simulate_reference
from physics_scenarios import scenario

from robogs.physics.effects import Param, get_effect
from robogs.physics.engine import Engine
from robogs.physics.model import BoxScene, Drive, SimResult, simulate
from robogs.physics.space import ParamSpace

F = torch.float64
TOL = 1e-12
DT = 1e-3
SCENE = BoxScene(
    size=(0.08, 0.06, 0.05),
    mass=0.4,
    inertia_z=0.4 * (0.08**2 + 0.06**2) / 12,
    friction_static=0.45,
    friction_dynamic=0.3,
    restitution=0.2,
    pusher_radius=0.01,
    pusher_length=0.04,
)
BASE = [
    Param("friction_dynamic", "-", 0.02, 2.0, 0.3, 0.3),
    Param("friction_static", "-", 0.02, 2.0, 0.45, 0.3),
    Param("damping_linear", "1/s", 0.0, 5.0, 0.0, 1.0),
]
#: effect -> parameter values of the second parameter set (the third gets half of them)
EFFECTS = {
    "table_tilt": {"g_x": 0.3, "g_y": -0.2},
    "stribeck": {"dmu": 0.3, "v_s": 0.1},
    "anisotropic_friction": {"a_c": 0.2, "a_s": -0.1},
    "viscous_damping": {"c": 0.5},
    "quadratic_drag": {"k": 1.0},
    "restitution": {"e_delta": 0.4},
    "com_offset": {"dx": 0.006, "dy": -0.004},
    "mass": {"dm": 0.2},
    "time_offset": {"delta": 0.012},
    "camera_extrinsics": {"dx": 0.002, "dy": -0.001, "dyaw": 0.01},
}


def _space() -> tuple[ParamSpace, torch.Tensor]:
    """Every catalogue effect of the rigid model, three parameter sets [3, Q]."""
    space = ParamSpace(BASE, [get_effect(n) for n in EFFECTS])
    th = space.defaults(3)
    for name, values in EFFECTS.items():
        for p, val in values.items():
            th[1, space.index(name, p)] = val
            th[2, space.index(name, p)] = 0.5 * val
    th[1, space.index("base", "damping_linear")] = 0.3
    th[2, space.index("base", "friction_dynamic")] = 0.5
    th[2, space.index("base", "friction_static")] = 0.4  # below mu_d: raised to it
    return space, torch.as_tensor(th, dtype=F)


def _drive(steps: int = 900) -> Drive:
    """Five trajectories on one box at the origin: a flat push along +x, an off-centre push
    along +y, a grasp from the first step lifted and dropped (bounce), a grasp from step 60
    lifted and dropped, and a free slide from an initial velocity under a far pusher."""
    t = np.arange(steps) * DT
    n = len(t)
    pos = np.zeros((5, n, 3))
    yaw = np.zeros((5, n))
    grasp = np.zeros((5, n), dtype=bool)
    tp = np.minimum(t, 0.4)
    pos[0] = np.stack([-0.1 + 0.3 * tp, 0.004 * np.sin(5 * tp), np.full(n, 0.025)], -1)
    yaw[0] = 0.05 * np.sin(3 * tp)
    pos[1] = np.stack([np.full(n, 0.02), -0.1 + 0.35 * tp, np.full(n, 0.02)], -1)
    yaw[1] = 0.5 * np.pi
    lift = np.clip(t / 0.25, 0.0, 1.0)
    pos[2] = np.stack([0.1 * lift, 0.03 * lift, 0.06 + 0.1 * lift], -1)
    yaw[2] = 0.4 * lift
    grasp[2] = t < 0.3
    lift3 = np.clip((t - 0.06) / 0.15, 0.0, 1.0)
    pos[3] = np.stack([-0.05 * lift3, np.zeros(n), 0.06 + 0.04 * lift3], -1)
    yaw[3] = -0.3 * lift3
    grasp[3] = (t >= 0.06) & (t < 0.25)
    pos[4] = np.stack([np.zeros(n), np.zeros(n), np.full(n, 1.0)], -1)
    vel = np.zeros_like(pos)
    vel[:, :-1] = np.diff(pos, axis=1) / DT
    rate = np.zeros_like(yaw)
    rate[:, :-1] = np.diff(yaw, axis=1) / DT
    obs = np.arange(0, n - 1, 10) * DT
    bins = np.where(t < 0.8, np.arange(n) // 25, -1)
    n_bins = int(bins.max()) + 1
    return Drive(
        DT,
        torch.as_tensor(pos, dtype=F),
        torch.as_tensor(vel, dtype=F),
        torch.as_tensor(yaw, dtype=F),
        torch.as_tensor(rate, dtype=F),
        torch.as_tensor(grasp),
        torch.tensor([[0.0, 0.0, 0.025]] * 4 + [[0.2, 0.1, 0.025]], dtype=F),
        torch.tensor([0.0, 0.1, 0.0, -0.2, 0.3], dtype=F),
        torch.as_tensor(np.tile(obs, (5, 1)), dtype=F),
        torch.ones(5, len(obs), dtype=torch.bool),
        init_vel=torch.tensor([[0.0] * 3] * 4 + [[0.4, -0.3, 0.0]], dtype=F),
        wrench_bin=torch.as_tensor(np.tile(bins, (5, 1))),
        wrench_width=torch.full((5, n_bins), 25 * DT, dtype=F),
    )


def _max_diff(a: SimResult, b: SimResult) -> float:
    pairs = [(a.pos, b.pos), (a.yaw, b.yaw), (a.dense_pos, b.dense_pos), (a.dense_yaw, b.dense_yaw)]
    if a.force is not None or b.force is not None:
        assert a.force is not None and b.force is not None
        pairs.append((a.force, b.force))
    for x, y in pairs:
        assert x.shape == y.shape
    return max(float((x - y).abs().max()) for x, y in pairs)


def _offsets(m: int, n_t: int) -> torch.Tensor:
    rng = np.random.default_rng(7)
    return torch.as_tensor(rng.normal(0.0, [1e-3, 1e-3, 0.01], (m, n_t, 3)), dtype=F)


@pytest.mark.parametrize("pusher_length", [0.04, 0.0], ids=["capsule", "sphere"])
@pytest.mark.parametrize("subset", [None, [0, 1]], ids=["all", "pushes"])
def test_simulate_matches_frozen_reference(pusher_length, subset):
    scene = replace(SCENE, pusher_length=pusher_length)
    space, th = _space()
    drive = _drive()
    if subset is not None:  # pushes alone: the quiet start is skipped, the rollout stops early
        drive = drive.subset(subset)
    off = _offsets(3, drive.n_traj)
    ref = simulate_reference(th, space, drive, scene, init_offset=off)
    new = simulate(th, space, drive, scene, init_offset=off)
    assert _max_diff(ref, new) <= TOL

    # the drives do what they are meant to (else the comparison would be vacuous)
    force = ref.force.norm(dim=-1)
    assert float(force[:, 0].max()) > 0.5  # the flat push loads the pusher
    moved = (ref.dense_pos[:, :, -1, :2] - ref.dense_pos[:, :, 0, :2]).norm(dim=-1)
    assert float(moved[:, 0].min()) > 0.03
    assert float(ref.dense_yaw[:, 1, -1].sub(ref.dense_yaw[:, 1, 0]).abs().min()) > 0.01
    if subset is None:
        z = ref.dense_pos[..., 2]
        assert float(z[:, 2].max()) > 0.1 and float(z[:, 3].max()) > 0.05  # carried up
        # a bounce with restitution: the box leaves the table again after the first impact
        landed = int(torch.nonzero(z[1, 2, 310:] < 0.0251)[0]) + 310
        assert float(z[1, 2, landed:].max()) > 0.0255
        assert float(moved[:, 4].min()) > 0.01  # the free slide
    # the comparison resolves a change of 1e-9 in friction (it is not blind at 1e-12)
    th2 = th.clone()
    th2[:, 0] += 1e-9
    assert _max_diff(ref, simulate(th2, space, drive, scene, init_offset=off)) > 100 * TOL


def test_design_a_scenario_matches_frozen_reference():
    """The 6-push design-A scenario the fitter tests use, tilt fitted, start corrections."""
    eng = Engine(scenario("table_tilt"))
    space = eng.space(eng.check_effects(["table_tilt", "time_offset"]))
    th = np.stack([eng.start(space)] * 3)
    th[1, space.index("table_tilt", "g_x")] = 0.2
    th[2, space.index("table_tilt", "g_y")] = -0.15
    th[2, space.index("time_offset", "delta")] = 0.01
    th = torch.as_tensor(th, dtype=F)
    off = _offsets(3, eng.prep.n_traj)
    ref = simulate_reference(th, space, eng.prep.drive, eng.prep.scene, init_offset=off)
    new = simulate(th, space, eng.prep.drive, eng.prep.scene, init_offset=off)
    assert _max_diff(ref, new) <= TOL
    assert float((ref.pos[1] - ref.pos[0]).abs().max()) > 1e-3  # the tilt shows

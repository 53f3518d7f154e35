"""Closed-form and consistency checks of the batched rigid-box model."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.physics.effects import Param, get_effect
from robogs.physics.model import BoxScene, Drive, simulate
from robogs.physics.space import ParamSpace

F = torch.float64
SCENE = BoxScene(
    size=(0.08, 0.06, 0.05),
    mass=0.4,
    inertia_z=0.4 * 0.01 / 12,
    friction_static=0.45,
    friction_dynamic=0.3,
    pusher_radius=0.01,
    pusher_length=0.04,
)
MU = Param("friction_dynamic", "-", 0.02, 2.0, 0.3, 0.3)


def _free_drive(
    n_traj: int, steps: int, v0: np.ndarray, z0: float = 0.025, dt: float = 1e-3
) -> Drive:
    far = torch.zeros(n_traj, steps, 3, dtype=F)
    far[..., 2] = 1.0  # EE far above: no contact
    t = torch.arange(0, steps - 1, 10, dtype=F) * dt
    return Drive(
        dt,
        far,
        torch.zeros_like(far),
        torch.zeros(n_traj, steps, dtype=F),
        torch.zeros(n_traj, steps, dtype=F),
        torch.zeros(n_traj, steps, dtype=torch.bool),
        torch.tensor([[0.0, 0.0, z0]] * n_traj, dtype=F),
        torch.zeros(n_traj, dtype=F),
        t.repeat(n_traj, 1),
        torch.ones(n_traj, len(t), dtype=torch.bool),
        init_vel=torch.as_tensor(v0, dtype=F),
    )


def test_coulomb_slide_stops_at_v2_over_2mug():
    v0 = np.array([[0.5, 0.0, 0.0], [0.3, 0.4, 0.0], [0.0, -0.2, 0.0]])
    space = ParamSpace([MU], [])
    res = simulate(space.defaults(1), space, _free_drive(3, 900, v0), SCENE)
    dist = res.pos[0, :, -1, :2].norm(dim=-1).numpy()
    speed = np.linalg.norm(v0, axis=1)
    expected = speed**2 / (2 * 0.3 * 9.81)
    # semi-implicit Euler stops within half a step of travel: |error| <= v0 dt / 2
    assert np.all(np.abs(dist - expected) <= 0.5 * speed * 1e-3 + 1e-9)
    # the box stays exactly on the table and does not turn
    assert torch.allclose(res.pos[0, :, -1, 2], torch.full((3,), 0.025, dtype=F))
    assert float(res.yaw.abs().max()) == 0.0


def test_sticking_below_static_limit_and_sliding_above():
    tilt = get_effect("table_tilt")
    space = ParamSpace([MU], [tilt])
    th = space.defaults(2)
    th[0, space.index("table_tilt", "g_x")] = 0.9 * 0.45 * 9.81  # below mu_s g: sticks exactly
    th[1, space.index("table_tilt", "g_x")] = 0.5 * 9.81  # above: slides with g_x - mu_d g
    res = simulate(th, space, _free_drive(1, 500, np.zeros((1, 3))), SCENE)
    assert float(res.dense_pos[0, 0, :, :2].abs().max()) == 0.0
    t = 0.45
    x = float(res.dense_pos[1, 0, 450, 0])
    a = 0.5 * 9.81 - 0.3 * 9.81
    assert x == pytest.approx(0.5 * a * t**2, rel=0.01)


def test_batched_rollouts_equal_single_rollouts():
    v0 = np.array([[0.4, 0.1, 0.0], [0.2, -0.3, 0.0]])
    space = ParamSpace([MU], [get_effect("viscous_damping")])
    th = space.defaults(3)
    th[1, 0] = 0.5
    th[2, 1] = 1.5
    drive = _free_drive(2, 400, v0)
    batched = simulate(th, space, drive, SCENE).pos
    for m in range(3):
        single = simulate(th[m : m + 1], space, drive, SCENE).pos
        assert torch.equal(batched[m : m + 1], single)


def test_restitution_bounce_height():
    space = ParamSpace([MU], [get_effect("restitution")])
    th = space.defaults(1)
    th[0, 1] = 0.6
    h = 0.05
    res = simulate(th, space, _free_drive(1, 600, np.zeros((1, 3)), z0=0.025 + h), SCENE)
    z = res.dense_pos[0, 0, :, 2].numpy() - 0.025
    first_impact = int(np.argmax(np.diff(z) > 0))  # the box starts to rise
    assert z[first_impact] < 1e-3  # it bounced off the table (speculative contact: < v dt above)
    apex = z[first_impact:].max()
    assert apex == pytest.approx(0.6**2 * h, rel=0.08)


def test_pusher_moves_box_and_grasp_carries_it():
    steps, dt = 600, 1e-3
    t = np.arange(steps) * dt
    x = np.minimum(-0.075 + 0.3 * np.clip(t - 0.05, 0, None), 0.0)
    pos = np.zeros((2, steps, 3))
    pos[0, :, 0], pos[0, :, 2] = x, 0.025  # push along +x
    pos[1, :, 0], pos[1, :, 2] = 0.1 * t, 0.25 + 0.1 * t  # carry: EE moves up and along x
    grasp = np.zeros((2, steps), bool)
    grasp[1, :300] = True
    vel = np.zeros_like(pos)
    vel[:, :-1] = np.diff(pos, axis=1) / dt
    obs = torch.tensor(t[::20], dtype=F).repeat(2, 1)
    drive = Drive(
        dt,
        torch.tensor(pos),
        torch.tensor(vel),
        torch.zeros(2, steps, dtype=F),
        torch.zeros(2, steps, dtype=F),
        torch.tensor(grasp),
        torch.tensor([[0.0, 0.0, 0.025], [0.0, 0.0, 0.225]], dtype=F),
        torch.zeros(2, dtype=F),
        obs,
        torch.ones_like(obs, dtype=torch.bool),
    )
    space = ParamSpace([MU], [])
    res = simulate(space.defaults(1), space, drive, SCENE)
    # pushed box: its back face (x - 0.04) stays at the capsule surface (x + 0.01) while pushed
    k = 250
    assert float(res.dense_pos[0, 0, k, 0]) - 0.04 == pytest.approx(pos[0, k, 0] + 0.01, abs=2e-4)
    # carried box keeps its offset to the EE (0.025 m below) while grasped
    assert np.allclose(res.dense_pos[0, 1, 299].numpy(), pos[1, 299] + [0, 0, -0.025], atol=1e-6)
    # released at 0.25 m height: it falls and ends on the table
    assert float(res.dense_pos[0, 1, -1, 2]) == pytest.approx(0.025, abs=1e-9)

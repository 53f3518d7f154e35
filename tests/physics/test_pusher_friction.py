"""Pusher friction on the MuJoCo engine (issue 16): a box that turns while the pusher slides
along its face, against the independent quasi-static generator
(:mod:`robogs.synth.scenarios.pusher_friction`: ellipsoidal limit surface, Coulomb point
contact at the pusher, mu_t 0.35, mu_p 0.3; 4 pushes turning 28-43 deg).

The table friction sets only the force scale of a quasi-static push (the poses do not depend on
it), the pusher friction the turning: both are fitted from poses and the pusher force, the
pusher friction as the engine-only base slot ``pusher_friction``
(:func:`robogs.physics.engines.mujoco_fit.pusher_friction_param`).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from robogs.physics.engine import Engine
from robogs.physics.engines.mujoco_fit import MujocoFit, pusher_friction_param
from robogs.physics.fit import Problem, fit_problems
from robogs.physics.prepare import prepare
from robogs.physics.scene import base_params
from robogs.physics.space import ParamSpace
from robogs.synth.scenarios.pusher_friction import G, PusherFrictionTruth, make_pusher_friction

MU_T, MU_P = 0.35, 0.3


@pytest.fixture(scope="module")
def rec():
    return make_pusher_friction(seed=0, mu_t=MU_T, mu_p=MU_P, nominal=(0.3, 0.2))


def _space(prep, physics) -> ParamSpace:
    return ParamSpace([*base_params(prep.scene), pusher_friction_param(physics)], [])


@pytest.mark.parametrize("mu_p, rel", [(0.0, 0.02), (MU_P, 0.02)])
def test_pusher_force_of_a_central_push_is_mu_m_g(mu_p, rel):
    """Oracle for the MuJoCo pusher force (pusher dynamics minus servo force): a central push
    along the face normal translates the box at ``mu_t m g`` (the generator's force too), for
    two table frictions, within 2 % with and without pusher friction (measured -0.5 % at
    both). Before the planar joint set's z ballast (``ContactSettings.z_ballast``) MuJoCo read
    +6.6 % / +11.9 % with pusher friction: the sliding table contact's soft friction pushed the
    box up by about mu b |v_t| (MuJoCo's convex contact couples slip into the normal) and the
    pusher's sticking vertical friction held it down, loading the table; the ballast divides
    that coupling by 1 + k."""
    rec = make_pusher_friction(noise="zero", pushes=((0.0, 0.0),), nominal=(MU_T, mu_p))
    prep = prepare(rec)
    space = _space(prep, rec.physics)
    sim = MujocoFit(rec.physics, "box").simulate(
        torch.tensor([[0.3, mu_p], [0.45, mu_p]]), space, prep.drive, prep.scene
    )
    meas = prep.wrench.meas[0].numpy()[:, :2]
    m_g = PusherFrictionTruth().mass * G
    steady = np.abs(np.linalg.norm(meas, axis=1) - MU_T * m_g) < 0.005 * MU_T * m_g
    assert steady.sum() > 50  # 1 s of full-speed push
    for i, mu in enumerate((0.3, 0.45)):
        mean = sim.force[i, 0].numpy()[steady, :2].mean(0)
        assert np.linalg.norm(mean) == pytest.approx(mu * m_g, rel=rel)
        along = mean @ meas[steady].mean(0) / np.linalg.norm(meas[steady].mean(0))
        assert along / np.linalg.norm(mean) > np.cos(np.radians(1.0))
        assert abs(float(sim.dense_yaw[i, 0, -1] - sim.dense_yaw[i, 0, 0])) < 1e-6


@pytest.mark.slow
def test_mujoco_fits_table_and_pusher_friction_from_poses_and_force(rec):
    """Fitted from (0.3, 0.2): both coefficients within 10 %, poses within 2 mm / 2 deg RMS.

    The finite-difference step is 10 % of each scale (not the default 1 %): MuJoCo's pusher
    force chatters by about 0.08 N per 20 ms bin from one parameter set to the next (stick-slip
    of the soft contacts), more than a 1 % change of mu_t moves it (0.014 N). The start poses
    are the measured ones (0.3 mm noise), not refitted."""
    eng = Engine(rec, backend="mujoco")
    assert eng.prep.wrench is not None
    space = _space(eng.prep, rec.physics)
    prob = Problem(free=[0, 1], theta0=space.zero.copy(), fit_local=False)
    (out,) = fit_problems(
        eng.residual_fn(space),
        space,
        [prob],
        n_traj=eng.prep.n_traj,
        rel_step=0.1,
        damping=(0.1, 1.0, 10.0),
        max_iter=8,
    )
    s = eng.summarise(out, [0, 1])
    mu_t, mu_p = out.theta
    print(f"mujoco fit: mu_t {mu_t:.4f} mu_p {mu_p:.4f}; {s.rms_mm:.2f} mm {s.rms_deg:.2f} deg")
    assert s.rms_mm <= 2.0 and s.rms_deg <= 2.0
    assert mu_t == pytest.approx(MU_T, rel=0.10)
    assert mu_p == pytest.approx(MU_P, rel=0.10)


@pytest.mark.slow
def test_planar_frictionless_pusher_cannot_turn_the_box(rec):
    """The planar model (frictionless pusher) fitted to the same data: the force still gives it
    the table friction, but the box turns degrees away (measured 5.9 deg, 5.4 mm RMS)."""
    flat = copy.deepcopy(rec)
    del flat.physics["objects"]["pusher"]["friction_dynamic"]
    eng = Engine(flat, backend="planar")
    space = eng.space([])
    prob = Problem(free=eng.base_columns(space), theta0=eng.start(space), fit_local=False)
    (out,) = eng.fit(space, [prob], max_iter=4)
    s = eng.summarise(out, prob.free)
    print(f"planar fit: mu_t {out.theta[0]:.4f}; {s.rms_mm:.2f} mm {s.rms_deg:.2f} deg")
    assert s.rms_deg > 4.0  # twice the budget
    assert out.theta[0] == pytest.approx(MU_T, rel=0.10)

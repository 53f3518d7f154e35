"""Two objects in one scene (issue 16): box A driven face-on into box B, simulated on MuJoCo and
both table frictions fitted, against the independent 1-D generator
(:mod:`robogs.synth.scenarios.two_objects`: kinematic pusher, plastic impact, Coulomb
slide-outs; mu_a 0.45, mu_b 0.25, pushes at 0.25, 0.35 and 0.45 m/s).

The box-box pair is overdamped (``OBJECT_PAIR_DAMPRATIO`` 2) so that B does not bounce off A.
The first MuJoCo tests call the simulator and the fitter directly: the fit uses the poses of
both boxes (the engine interface,
:meth:`~robogs.physics.engines.mujoco_engine.MujocoEngine.rollout`, returns every object); the
pusher force of both boxes (:class:`~robogs.physics.engines.mujoco_fit.MujocoFit` with the base
slot ``objects.box_b.friction_dynamic``) is checked at the fitted values, not fitted: the
pusher-A-B chain of soft contacts rings at about 25 Hz (+-0.4 N from one 20 ms bin to the next).
The tests at the end take the user path (a recording with both boxes tracked -> prepare ->
Engine -> residuals), the force included over 100 ms bins; the dataset and ``robogs fit`` /
``compare`` / ``diagnose`` are in ``test_two_objects_cli.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.format.errors import InputError
from robogs.physics.engine import Engine, resolve_backend
from robogs.physics.engines.base import ObjectState, yaw_quat
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.engines.mujoco_fit import MujocoFit, object_friction_param
from robogs.physics.fit import Problem, fit_problems
from robogs.physics.prepare import prepare
from robogs.physics.recording import as_recording
from robogs.physics.residuals import (
    SceneSimResult,
    residual_fn,
    tracked_rms,
    weighted_residuals,
)
from robogs.physics.scene import base_params
from robogs.physics.space import ParamSpace
from robogs.synth.scenarios.two_objects import G, TwoBoxTruth, make_two_objects, push_chain

TRUTH = TwoBoxTruth()
SIG_POS = TRUTH.sigma_pos


# ---------------------------------------------------------------- the generator, closed forms
@pytest.mark.parametrize("speed", [0.25, 0.45])
def test_generator_chain_closed_forms(speed):
    """Pushing both: force (mu_a m_a + mu_b m_b) g; the plastic impact sets B to the pusher's
    speed; after the pusher brakes, A slides v^2 / (2 mu_a g) and B v^2 / (2 mu_b g)."""
    ch = push_chain(TRUTH, speed, 0.07)
    both = (np.abs(ch.v_a - speed) < 1e-12) & (np.abs(ch.v_b - speed) < 1e-12)
    f_both = (TRUTH.mu_a * TRUTH.mass_a + TRUTH.mu_b * TRUTH.mass_b) * G
    assert np.allclose(-ch.force[both][1:], f_both, rtol=1e-9)
    hit = int(np.argmax(ch.v_b > 0))
    assert ch.v_b[hit] == pytest.approx(ch.v_a[hit], abs=1e-12)  # plastic: one speed
    free = int(np.flatnonzero(ch.force < 0)[-1]) + 1  # the pusher's last push
    v0 = ch.v_a[free - 1]
    slide_a = ch.a[-1] - ch.a[free - 1]
    slide_b = ch.b[-1] - ch.b[free - 1]
    # semi-implicit Euler on a 0.1 ms grid: within one step's travel of the closed form
    assert slide_a == pytest.approx(v0**2 / (2 * TRUTH.mu_a * G), abs=v0 * 1e-4 + 1e-6)
    assert slide_b == pytest.approx(v0**2 / (2 * TRUTH.mu_b * G), abs=v0 * 1e-4 + 1e-6)


def test_generator_restitution_launches_b_ahead():
    """With restitution e the driven A (the pusher's speed v) launches B at (1 + e) v."""
    truth = TwoBoxTruth(restitution=0.5)
    ch = push_chain(truth, 0.3, 0.05)
    hit = int(np.argmax(ch.v_b > 0))
    assert ch.v_b[hit] == pytest.approx(1.5 * 0.3, rel=1e-6)


# ---------------------------------------------------------------- MuJoCo
def _setup(noise: bool, nominal=(0.4, 0.3), truth: TwoBoxTruth = TRUTH):
    rec = make_two_objects(seed=0, noise=noise, nominal=nominal, truth=truth)
    prep = prepare(rec)
    eng = MujocoEngine(
        rec.physics, object_name="box_a", poses={"box_b": rec.meta["start"][0]["box_b"]}
    )
    meas = np.zeros((2, prep.n_traj, prep.mask.shape[1], 3))
    for i, tr in enumerate(rec.trajectories):
        n = len(tr.t_ns)
        meas[0, i, :n], meas[1, i, :n] = tr.object_pos, tr.other_pos
    return rec, prep, eng, meas


def _poses(eng, prep, mu: np.ndarray) -> np.ndarray:
    """[2 (A, B), M, T, N, 3] predicted positions for frictions ``mu`` [M, 2]; box A starts
    at its measured (x, y, yaw), resting on the table (half its height above it)."""
    pos = prep.drive.init_pos.numpy().copy()
    pos[:, 2] = TRUTH.table_z + 0.5 * TRUTH.size_a[2]
    start = ObjectState(pos=pos, quat=yaw_quat(prep.drive.init_yaw.numpy()))
    pr = eng.rollout(
        prep.drive,
        initial={"box_a": start},
        params={
            "objects.box_a.friction_dynamic": mu[:, 0],
            "objects.box_b.friction_dynamic": mu[:, 1],
        },
    )
    return np.stack([pr.pos["box_a"], pr.pos["box_b"]])


def test_mujoco_simulates_a_box_pushed_into_another():
    """Noise-free, true frictions: both boxes within 1 mm of the generator at every sample
    (measured at most 0.19 / 0.33 / 0.41 mm for box A and 0.16 / 0.91 / 0.44 mm for box B in
    the three pushes with the 2.5 ms x 1.7 pusher pair; 0.37 / 0.36 / 0.69 and 0.14 / 0.40 /
    0.81 mm with the 4 ms x 2 pair of before: the noise-free drive is not smoothed,
    ``prepare``'s derived window is 0.
    With the 80 ms smoothing of before, which rounds the generator's sharp 10 m/s^2 brake,
    0.62 / 0.83 / 1.08 and 0.76 / 1.13 / 2.02 mm: it fails the bound; the pusher pair 3 ms x
    1.7: 0.25 / 0.16 / 0.51 and 0.31 / 0.67 / 0.46 mm); B leaves A at under 1.1 x the push
    speed (1.13 with a critically damped box-box pair)."""
    rec, prep, eng, meas = _setup(noise=False)
    pred = _poses(eng, prep, np.array([[TRUTH.mu_a, TRUTH.mu_b]]))[:, 0]
    mask = prep.mask.numpy()
    err = np.linalg.norm(pred - meas, axis=-1)
    print("max error A, B per push [mm]:", np.round(1e3 * np.where(mask, err, 0).max(-1), 2))
    assert err[:, mask].max() < 1.0e-3
    for i, (speed, _) in enumerate(((0.25, 0), (0.35, 0), (0.45, 0))):
        d = np.array(
            [np.cos(rec.meta["start"][i]["heading"]), np.sin(rec.meta["start"][i]["heading"])]
        )
        b = eng.rollout(prep.drive).pos["box_b"][0, i] @ np.r_[d, 0.0]
        t = prep.drive.obs_t[i].numpy()
        v_b = np.diff(b[mask[i]]) / np.diff(t[mask[i]])
        assert v_b.max() < 1.1 * speed


@pytest.mark.parametrize(
    ("sigma_ee", "bound", "pair"),
    [
        pytest.param(
            TRUTH.sigma_ee,
            0.06,
            None,
            id="ee-60um-default",
            marks=pytest.mark.xfail(
                strict=True,
                raises=AssertionError,
                reason="prepare's 80 ms smoothing of the noisy pusher path: mu_a -6.9 %",
            ),
        ),
        pytest.param(0.0, 0.03, (3.0, 1.7), id="ee-clean-tc3-zeta1.7"),
        pytest.param(0.0, 0.03, None, id="ee-clean-default"),
    ],
)
def test_mujoco_fits_both_table_frictions(monkeypatch, sigma_ee: float, bound: float, pair):
    """From (0.4, 0.3): both frictions within ``bound`` and both boxes near the noise floor
    (0.5 mm per axis: sqrt(3) x 0.5 = 0.87 mm RMS; measured 0.95-0.96 and 0.85-0.87 mm); the
    pusher force of the fitted scene, pushing both, within 5 % of (mu_a m_a + mu_b m_b) g, over
    20 ms bins (the bins of a single object: the steady push lasts a few of them).

    The pusher's path measured with the generator's 60 um noise (``ee-60um-default``):
    ``prepare`` smooths it over 80 ms (the reference window, which that noise needs), which
    rounds the generator's sharp 10 m/s^2 brake; the generator's own rigid rules on that drive
    fit mu_a 6-12 % low (h42). Measured mu_a -6.9 %, mu_b -3.3 % on the default pusher pair
    (5 steps x 1.2 since stop 54's check; strict xfail; the 2.5 ms x 1.7 pair of stops 49-52:
    -7.5 / -3.5 %; the 4 ms x 2 pair before: -6.8 %, and -4.7 % before the engine smoothed the
    servo targets over the drive's 2 ms knots, h67: the old pair's strike bias offset part of
    the drive's). The same recording with a noise-free pusher path (``ee-clean-*``: no
    smoothing, the brake as measured) isolates the contact model: pair 3 ms x 1.7 mu_a -2.9 %,
    mu_b +0.7 %, force +1.2 %; the default pair mu_a -2.5 %, mu_b -0.6 %, force +1.2 % (the
    2.5 ms x 1.7 pair: -2.1 %, -0.7 %, +0.5 %; the 4 ms x 2 pair: -2.0 %, -0.3 %, +3.8 %;
    h67; the 80 ms smoothing there: mu_a -6.3 %, which fails).

    Finite-difference step 10 % of each scale: the contact chain makes the objective rough at
    a finer scale (steps of 1 % and 3 % stopped at (0.405, 0.290) and (0.421, 0.267))."""
    import dataclasses

    import robogs.physics.prepare as prepare_mod

    monkeypatch.setattr(prepare_mod, "CHAIN_FORCE_BIN_S", prepare_mod.FORCE_BIN_S)
    truth = dataclasses.replace(TRUTH, sigma_ee=sigma_ee)
    rec, prep, eng, meas = _setup(noise=True, truth=truth)
    if pair is not None:
        from robogs.format.mjcf import PLANAR_SETTINGS

        settings = dataclasses.replace(
            PLANAR_SETTINGS, pusher_timeconst_steps=pair[0], pusher_dampratio=pair[1]
        )
        eng = MujocoEngine(
            rec.physics,
            object_name="box_a",
            poses={"box_b": rec.meta["start"][0]["box_b"]},
            settings=settings,
        )
    mask = prep.mask.numpy()
    space = ParamSpace([*base_params(prep.scene), object_friction_param(rec.physics, "box_b")], [])

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        r = (
            (meas[:, None] - _poses(eng, prep, theta.numpy()))
            / SIG_POS
            * mask[None, None, ..., None]
        )
        return torch.as_tensor(
            np.concatenate([r[0], r[1]], axis=-2).reshape(theta.shape[0], prep.n_traj, -1)
        )

    prob = Problem(free=[0, 1], theta0=space.zero.copy(), fit_local=False)
    (out,) = fit_problems(
        fn, space, [prob], n_traj=prep.n_traj, rel_step=0.1, damping=(0.1, 1.0, 10.0), max_iter=15
    )
    mu_a, mu_b = out.theta
    r = out.resid.reshape(prep.n_traj, 2, -1, 3)
    rms = [1e3 * SIG_POS * np.sqrt(np.mean(np.sum(r[:, k][mask] ** 2, -1))) for k in (0, 1)]
    print(f"two boxes: mu_a {mu_a:.4f} mu_b {mu_b:.4f}; A {rms[0]:.2f} mm, B {rms[1]:.2f} mm")
    assert mu_a == pytest.approx(TRUTH.mu_a, rel=bound)
    assert mu_b == pytest.approx(TRUTH.mu_b, rel=bound)
    assert max(rms) < 1.2
    # the pusher force of both boxes at the fitted frictions, where the generator pushes both
    sim = MujocoFit(rec.physics, "box_a", engine=eng).simulate(
        torch.tensor([[mu_a, mu_b]]), space, prep.drive, prep.scene
    )
    f_both = (TRUTH.mu_a * TRUTH.mass_a + TRUTH.mu_b * TRUTH.mass_b) * G
    meas_f = np.linalg.norm(prep.wrench.meas.numpy()[..., :2], axis=-1)
    pred_f = np.linalg.norm(sim.force[0].numpy()[..., :2], axis=-1)
    steady = prep.wrench.mask.numpy() & (np.abs(meas_f - f_both) < 0.05 * f_both)
    assert steady.sum() >= 10
    print(f"pusher force pushing both: {pred_f[steady].mean():.3f} N vs {f_both:.3f} N")
    assert pred_f[steady].mean() == pytest.approx(f_both, rel=0.05)


# ---------------------------------------------------------------- the user path, its blocks
def test_tracked_object_has_its_own_block_and_noise():
    """Box B's poses form their own residual block after box A's, whitened by B's own noise:
    B measured with 1.5 mm more noise than A (generator 0.5 mm on both; B's truth
    sqrt(0.5^2 + 1.5^2) = 1.58 mm) is estimated at 1.31 mm (the estimator of
    :mod:`robogs.physics.noise` reads 17 % low at this level from B's 107 samples; 0.49 mm with
    no extra noise), A stays at 0.50 mm; a prediction off by a constant
    (1, -2, 0) mm on B alone gives B's block exactly that offset over B's sigma, RMS sqrt(5) mm,
    and a zero block for A."""
    rec = make_two_objects(seed=1, noise=True)
    rng = np.random.default_rng(7)
    for tr in rec.trajectories:
        tr.other_pos = tr.other_pos + rng.normal(0.0, 1.5e-3, tr.other_pos.shape)
    prep = prepare(rec)
    (b,) = prep.tracked
    assert b.name == "box_b" and prep.rec.tracked == ["box_b"]
    assert prep.noise.sigma_pos == pytest.approx(5e-4, rel=0.15)
    assert b.noise.sigma_pos == pytest.approx(np.hypot(5e-4, 1.5e-3), rel=0.25)
    assert b.noise.sigma_pos > 2.0 * prep.noise.sigma_pos
    d = torch.tensor([1e-3, -2e-3, 0.0], dtype=torch.float64)
    sim = SceneSimResult(
        pos=prep.meas_pos[None],
        yaw=prep.meas_yaw[None],
        dense_pos=torch.zeros(1),
        dense_yaw=torch.zeros(1),
        others={"box_b": (b.meas_pos[None] - d, b.meas_yaw[None])},
    )
    w = weighted_residuals(sim, prep)[0].numpy()
    n_a = prep.mask.shape[1] * 4
    assert w.shape[-1] == prep.pose_width == n_a + b.width  # no force: sim.force is None
    assert np.abs(w[:, :n_a]).max() == 0.0
    blk = w[:, n_a:].reshape(prep.n_traj, -1, 4)
    m = b.mask.numpy()
    expect = (d.numpy() / b.sig_pos.numpy())[m]
    np.testing.assert_allclose(blk[m][:, :3], expect, rtol=1e-12)
    assert np.abs(blk[~m]).max() == 0.0
    assert tracked_rms(prep, w)["box_b"]["rms_mm"] == pytest.approx(np.sqrt(5.0), rel=1e-9)


def test_planar_refuses_a_recording_with_two_objects():
    """The planar engine names the fix; its residuals refuse a recording that tracks B; auto
    picks MuJoCo and says in one line why planar cannot."""
    rec = make_two_objects(seed=0, noise=False)
    with pytest.raises(InputError, match="planar engine cannot represent") as err:
        Engine(rec, backend="planar")
    assert "--engine mujoco" in err.value.one_line()
    name, why = resolve_backend(rec.physics, "auto")
    assert name == "mujoco" and "planar cannot represent it: 2 rigid objects" in why
    assert "\n" not in why
    prep = prepare(rec)
    fn = residual_fn(prep, ParamSpace(base_params(prep.scene), []))
    with pytest.raises(InputError, match="--engine mujoco"):
        fn(torch.tensor([[0.4]]), torch.zeros(1, prep.n_traj, 3))


def test_tracked_objects_are_checked():
    """A tracked object missing from one trajectory, or not a rigid object of physics.json, is
    an InputError naming it."""
    rec = as_recording(make_two_objects(seed=0, noise=False))
    rec.trajectories[1].others = {}
    with pytest.raises(InputError, match="'box_b' is tracked in some trajectories but not in"):
        as_recording(rec)
    rec = as_recording(make_two_objects(seed=0, noise=False))
    rec.trajectories[0].others = {"crate": rec.trajectories[0].others["box_b"]}
    with pytest.raises(InputError, match="'crate' is not another rigid object"):
        as_recording(rec)


def test_engine_mujoco_predicts_both_boxes():
    """Through the Engine (prepare -> MujocoFit -> residuals), noise-free data at the true
    frictions: both boxes within 2 mm at every sample (as the direct rollout above), and B's
    residual at the nominal 0.35 / 0.35 several times that (the comparison can fail)."""
    rec = make_two_objects(seed=0, noise=False)
    eng = Engine(rec, backend="mujoco", threads=1)
    space = eng.space([])
    assert [s.key for s in space.slots] == [
        "base.friction_dynamic",
        "base.objects.box_b.friction_dynamic",
    ]
    th = np.array([[TRUTH.mu_a, TRUTH.mu_b], [0.35, 0.35]])
    r = eng.evaluate(space, th, np.zeros((2, eng.prep.n_traj, 3)))
    (b,) = eng.prep.tracked
    for k in range(2):
        a = np.linalg.norm(eng.raw(r[k])[..., :3], axis=-1)[eng.mask] * 1e3
        n_a = eng.prep.mask.shape[1] * 4
        rb = r[k][:, n_a : n_a + b.width].reshape(eng.prep.n_traj, -1, 4)[..., :3]
        e_b = np.linalg.norm(rb * b.sig_pos.numpy(), axis=-1)[b.mask.numpy()] * 1e3
        rms_b = tracked_rms(eng.prep, r[k])["box_b"]["rms_mm"]
        print(f"set {k}: max A {a.max():.2f} mm, B {e_b.max():.2f} mm; B rms {rms_b:.2f} mm")
        assert rms_b == pytest.approx(np.sqrt(np.mean(e_b**2)), rel=1e-9)
        if k == 0:  # measured max 1.01 / 1.75 mm, B rms 1.02 mm
            assert a.max() < 2.0 and e_b.max() < 2.0
        else:  # measured B rms 6.43 mm
            assert rms_b > 4.0


def test_fit_with_the_pusher_force_over_long_bins(monkeypatch):
    """Both boxes' poses and the pusher force, through the Engine: with other tracked objects
    the force is compared over 100 ms bins (``CHAIN_FORCE_BIN_S``, 2.5 periods of the chain's
    ~25 Hz ring). Seed 0: mu_a +3.5 %, mu_b -3.0 %, force residual 0.023 N RMS against a 0.011 N
    floor (seeds 1, 2: mu_b -1.6 %, +0.2 %; 0.031, 0.032 N). The same fitted scene compared
    over the 20 ms bins of a single object leaves the ring in the residual: 0.2 N RMS, about 9x
    its floor (fitted with 20 ms bins, seeds 0-2: mu_b -4.4 / -6.0 / -2.0 %; poses only
    -2.3 / -4.0 / -3.1 %). With the pusher pair 3 ms x 1.7 (not the default): +1.7 %, -0.8 %,
    0.026 N, and 0.099 N (4.2x) over 20 ms bins."""
    import robogs.physics.prepare as prepare_mod
    from robogs.physics.prepare import force_rms

    rec = make_two_objects(seed=0, noise=True)
    eng = Engine(rec, backend="mujoco", threads=1)
    assert "bins of 100 ms" in eng.prep.wrench_note
    space = eng.space([])
    (out,) = eng.fit(space, [Problem(free=eng.base_columns(space), theta0=eng.start(space))])
    mu_a, mu_b = out.theta
    f = force_rms(eng.prep, out.resid)
    print(f"with force: mu_a {mu_a:.4f} mu_b {mu_b:.4f}; force {f}")
    assert mu_a == pytest.approx(TRUTH.mu_a, rel=0.10)
    assert mu_b == pytest.approx(TRUTH.mu_b, rel=0.10)
    assert f["rms_n"] < 4.0 * f["noise_floor_n"]
    monkeypatch.setattr(prepare_mod, "CHAIN_FORCE_BIN_S", prepare_mod.FORCE_BIN_S)
    short = Engine(rec, backend="mujoco", threads=1)
    assert "bins of 20 ms" in short.prep.wrench_note
    r = short.evaluate(short.space([]), out.theta[None], out.local[None])[0]
    f20 = force_rms(short.prep, r)
    print(f"same scene, 20 ms bins: force {f20}")
    assert f20["rms_n"] > 5.0 * f20["noise_floor_n"]

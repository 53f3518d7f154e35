"""Wrench residuals: the model predicts the pusher's contact force and mass becomes identifiable.

Oracles: the closed-form force of a box pushed at constant acceleration, the truth of an
independent force-controlled push generator (``robogs.synth.scenarios.force_push``), and the
null scenario (nominal mass true) that must report nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.physics.diagnose import diagnose_recording
from robogs.physics.model import BoxScene, simulate
from robogs.physics.prepare import prepare
from robogs.physics.scene import base_params
from robogs.physics.space import ParamSpace
from robogs.synth.scenarios.force_push import ForcePushTruth, make_force_push


def _accelerating_drive(scene: BoxScene, a: float, dt: float, n_s: int, k_bin: int):
    """A capsule flat on the box's -x face, accelerating at ``a`` [m/s^2] from rest."""
    from robogs.physics.engines.base import make_drive

    t = np.arange(n_s) * dt
    contact = -(0.5 * scene.size[0] + scene.pusher_radius)
    x = contact + 0.5 * a * np.clip(t - 0.05, 0.0, None) ** 2
    pusher = np.zeros((1, n_s, 3))
    pusher[0, :, 0] = x
    pusher[0, :, 2] = 0.5 * scene.size[2]
    drive = make_drive(
        dt,
        pusher,
        np.zeros((1, n_s)),
        t[None, ::10],
        np.array([[0.0, 0.0, 0.5 * scene.size[2]]]),
        np.zeros(1),
    )
    n_b = int(np.ceil(n_s / k_bin))
    drive.wrench_bin = torch.as_tensor((np.arange(n_s) // k_bin)[None])
    drive.wrench_width = torch.full((1, n_b), k_bin * dt, dtype=torch.float64)
    return drive


@pytest.mark.parametrize("mass,a", [(0.4, 1.5), (1.3, 0.6)])
def test_contact_force_closed_form(mass, a):
    """Sliding at constant acceleration, the box pushes back on the tool with m (a + mu_d g)."""
    scene = BoxScene(
        size=(0.08, 0.06, 0.05),
        mass=mass,
        inertia_z=mass * 0.01 / 12,
        friction_static=0.5,
        friction_dynamic=0.3,
        pusher_radius=0.01,
        pusher_length=0.04,
    )
    dt, k_bin = 1e-3, 20
    drive = _accelerating_drive(scene, a, dt, 600, k_bin)
    space = ParamSpace(base_params(scene), [])
    sim = simulate(space.defaults(1), space, drive, scene)
    f = sim.force[0, 0].numpy()  # [W, 3]
    steady = f[6:28]  # bins from 0.12 s to 0.56 s: sliding with the pusher
    expect = mass * (a + 0.3 * 9.81)
    # the box pushes the tool backwards (-x), nothing sideways or vertically
    np.testing.assert_allclose(steady[:, 0], -expect, rtol=2e-3)
    assert np.abs(steady[:, 1:]).max() < 1e-9
    assert np.abs(f[:2]).max() < 1e-12  # before contact: no force


def test_sensor_offset_and_noise_from_rest():
    """The offset is the per-trajectory median out of contact, the noise floor its MAD."""
    rec = make_force_push(seed=3)
    prep = prepare(rec)
    truth = ForcePushTruth()
    w = prep.wrench
    assert w is not None and "wrenches" in prep.excitation
    np.testing.assert_allclose(w.sigma.numpy(), truth.sigma_force, rtol=0.1)
    for i, tr in enumerate(rec.trajectories):
        yaw = 2 * np.arctan2(tr.ee_quat[0, 3], tr.ee_quat[0, 0])
        ox, oy, oz = truth.sensor_offset
        world = [np.cos(yaw) * ox - np.sin(yaw) * oy, np.sin(yaw) * ox + np.cos(yaw) * oy, oz]
        np.testing.assert_allclose(w.offset[i], world, atol=0.02)


def test_mass_hidden_in_force_controlled_push_is_found():
    """A box 30 % heavier than physics.json says: poses alone cannot tell, the wrench does."""
    rec = make_force_push(mass_true=0.52, mass_nominal=0.4, seed=1)
    res = diagnose_recording(rec, effects=["mass"])
    row = next(r for r in res.rows if r.name == "mass")
    assert row.reported and row.verdict == "add", row
    (dm,) = row.params
    assert dm.low <= rec.meta["truth"]["dm"] <= dm.high
    assert abs(dm.value - 0.3) < 0.03
    assert row.heldout_rms_after < 0.5 * row.heldout_rms_before


def test_mass_null_gives_no_false_positive():
    rec = make_force_push(mass_true=0.4, mass_nominal=0.4, seed=1)
    res = diagnose_recording(rec, effects=["mass"])
    row = next(r for r in res.rows if r.name == "mass")
    assert not row.reported and row.verdict != "add"
    assert abs(row.params[0].value) < 0.03


def test_without_wrench_mass_stays_unidentifiable():
    """The same pushes without the sensor: poses do not move with mass."""
    rec = make_force_push(mass_true=0.52, seed=1)
    for tr in rec.trajectories:
        tr.wrench_t_ns = tr.wrench_force = None
    prep = prepare(rec)
    assert prep.wrench is None and "wrenches" not in prep.excitation
    res = diagnose_recording(rec, effects=["mass"])
    row = next(r for r in res.rows if r.name == "mass")
    assert row.verdict == "unidentifiable" and not row.reported


def test_both_engines_use_the_wrench():
    """The measured wrench enters the residuals on both engines, without a warning. At the true
    mass and friction MuJoCo's pusher force (from the pusher's own dynamics,
    ``MujocoFit._pusher_force``) matches the sensor about as closely as the planar model's
    (measured 0.230 vs 0.211 N RMS per 20 ms bin, transients included); at the nominal mass
    (23 % light) it rises by about as much as the planar one (0.331 vs 0.322 N: +0.101 vs
    +0.111 N), so the force tells the mass on MuJoCo too."""
    import copy
    import warnings

    from robogs.physics.engine import Engine
    from robogs.physics.prepare import force_rms

    rec = make_force_push(seed=3)
    true = copy.deepcopy(rec)
    box = true.physics["objects"]["box"]
    box["mass_kg"], box["friction_dynamic"] = 0.52, 0.35
    box["inertia_kgm2"] = [[v * 0.52 / 0.4 for v in row] for row in box["inertia_kgm2"]]
    light = copy.deepcopy(true)
    light.physics["objects"]["box"]["mass_kg"] = 0.4
    rms = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for backend in ("planar", "mujoco"):
            for name, r in (("true", true), ("light", light)):
                eng = Engine(r, dt=1e-3, backend=backend)
                sp = eng.space([])
                res = eng.evaluate(sp, sp.zero[None], np.zeros((1, eng.prep.n_traj, 3)))
                rms[backend, name] = force_rms(eng.prep, res[0])["rms_n"]
    assert rms["mujoco", "true"] < 1.2 * rms["planar", "true"]
    rise = {b: rms[b, "light"] - rms[b, "true"] for b in ("planar", "mujoco")}
    assert rise["mujoco"] > 0.7 * rise["planar"] > 0


def test_force_rms_and_the_wrench_note():
    """force_rms against a known force error: 0.5 N on every used bin gives 0.5 N; the noise
    floor is the per-bin sigma / sqrt(count) by a plain loop. The note says how the wrench is
    used, or why not."""
    from robogs.physics.prepare import force_rms

    rec = make_force_push(seed=3)
    prep = prepare(rec)
    w = prep.wrench
    assert prep.wrench_note.startswith("wrench used:") and "out of contact" in prep.wrench_note
    n_t, n_b = w.mask.shape
    n_pose = prep.mask.shape[1] * 4
    sig, cnt, m = w.sigma.numpy(), w.count.numpy(), w.mask.numpy()
    err = np.array([0.3, -0.4, 0.0])  # N, |err| = 0.5
    weighted = np.zeros((n_t, n_pose + n_b * 4))
    floor2 = []
    for t in range(n_t):
        for b in range(n_b):
            sf = sig / np.sqrt(cnt[t, b])
            weighted[t, n_pose + 4 * b : n_pose + 4 * b + 3] = err / sf
            if m[t, b]:
                floor2.append(np.sum(sf**2))
    f = force_rms(prep, weighted)
    assert f["rms_n"] == pytest.approx(0.5, rel=1e-12)
    assert f["noise_floor_n"] == pytest.approx(np.sqrt(np.mean(floor2)), rel=1e-12)
    assert f["bins"] == int(m.sum()) > 0
    assert force_rms(prep, weighted[:, :n_pose]) is None  # no force block: no force RMS
    for tr in rec.trajectories:
        tr.wrench_t_ns = tr.wrench_force = None
    bare = prepare(rec)
    assert bare.wrench is None and bare.wrench_note.startswith("no wrench stream")

"""The arm's kinematic model on recorded end-effector poses: hidden elasticity, backlash and
kinematic offsets found first and recovered, null poses report nothing, unidentifiable
offsets are said to be so.

Oracles: the generator of :mod:`robogs.synth.armlogs.kinematic` (its own URDF parser, numpy forward
kinematics, world-frame gravity torques and a 1 kHz play operator) and its truth; brute-force
loops for the play operator and the identifiability screen.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from robogs.format.kinematics import Chain
from robogs.format.urdf import load_urdf
from robogs.physics.arm import diagnose_arm
from robogs.physics.arm.api import open_arm
from robogs.physics.arm.identify import identifiable_columns
from robogs.physics.arm.kinematic_model import forward_ee, play_offset
from robogs.synth.armlogs import KinLogSpec, generate_kinematic_dataset, kin_truth_path
from robogs.synth.armlogs.dynamics import parse_arm
from robogs.synth.armlogs.kinematic import urdf_fk

SMALL = {"segments": 3, "duration_s": 4.0, "ee_rate_hz": 40.0}
"""Three trajectories of 4 s, poses at 40 Hz (480 poses): small enough for a fast test."""


def _dataset(tmp_path, urdf, effect: str, seed: int = 0, **kw) -> tuple:
    ds = tmp_path / f"ds_{effect}_{seed}"
    generate_kinematic_dataset(ds, urdf, KinLogSpec(effect=effect, seed=seed, **(SMALL | kw)))
    return ds, json.loads(kin_truth_path(ds).read_text())


def test_forward_kinematics_with_offsets_matches_the_independent_fixture(tmp_path, ur5):
    """Model FK (torch, composite bodies) vs the fixture's numpy FK over the URDF joints, with
    random link angles and random frame offsets; at zero offsets also vs robogs' Chain."""
    ds, _ = _dataset(tmp_path, ur5, "none")
    s = open_arm(ds)
    rng = np.random.default_rng(3)
    theta = rng.uniform(-2.5, 2.5, (50, 6))
    off = rng.uniform(-0.02, 0.02, (6, 2))  # (da, dd) per joint, m
    pos, rot = forward_ee(
        s.kin.frames,
        torch.as_tensor(theta)[None],
        torch.as_tensor(off)[None],
    )
    p_ref, r_ref = urdf_fk(parse_arm(ur5), theta, "tool0", da=off[:, 0], dd=off[:, 1])
    np.testing.assert_allclose(pos[0].numpy(), p_ref, atol=1e-12)
    np.testing.assert_allclose(rot[0].numpy(), r_ref, atol=1e-12)
    chain = Chain.from_urdf(load_urdf(ur5, load_meshes=False))
    t = chain.forward(torch.as_tensor(theta))[:, chain.link_index("tool0")]
    p0, _ = forward_ee(s.kin.frames, torch.as_tensor(theta)[None], None)
    np.testing.assert_allclose(p0[0].numpy(), t[:, :3, 3].numpy(), atol=1e-12)
    assert np.abs(p0[0].numpy() - pos[0].numpy()).max() > 5e-3  # the offsets do move the tool


def test_play_operator_matches_a_brute_force_loop(tmp_path, ur5):
    ds, _ = _dataset(tmp_path, ur5, "none")
    kp = open_arm(ds).kin
    b = np.array([[1e-3, 2e-3, 5e-4, 3e-3, 1e-3, 0.0], [-1e-3, 0, 0, 0, 0, 2e-3]])
    got = play_offset(kp, torch.as_tensor(b)).numpy()
    qc = kp.data.q_clock
    i0, i1, w = kp.data.at
    for m in range(len(b)):
        d = np.zeros_like(qc)
        for tr in range(qc.shape[0]):
            for j in range(qc.shape[2]):
                bb = abs(b[m, j])
                x = qc[tr, 0, j] - bb * kp.data.dir0[tr, j]
                for k in range(qc.shape[1]):
                    x = min(max(x, qc[tr, k, j] - bb), qc[tr, k, j] + bb)
                    d[tr, k, j] = np.sign(b[m, j]) * (x - qc[tr, k, j])
        flat = d.reshape(-1, qc.shape[2])
        ref = flat[i0] * (1 - w[:, None]) + flat[i1] * w[:, None]
        np.testing.assert_allclose(got[m], ref, atol=1e-15)
    # engaged and moving: the link lags the motor by b against the motion
    assert np.isclose(np.abs(got[0]).max(axis=0), np.abs(b[0]), rtol=1e-9).all()


def test_identifiability_screen_on_a_constructed_jacobian():
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 200))
    jac = np.stack([a, b, 2 * a - 0.5 * b + 1e-6 * rng.normal(size=200), 0 * a, c], axis=1)
    kept, why = identifiable_columns(jac, [10, 11, 12, 13, 14], np.ones(5), list("abxzc"))
    assert kept == [10, 11, 14]
    assert why[12].startswith("acts only together with a, b")
    assert why[13] == "the predictions do not change with it"


@pytest.mark.parametrize("effect", ["joint_elasticity", "backlash", "kinematic_offsets"])
def test_hidden_kinematic_effect_is_found_first_and_recovered(tmp_path, ur5, effect):
    """Tolerances: compliance of the two gravity-loaded joints within 10 % (the wrists carry
    under 3 N m: truth inside 4 sd only); backlash within 10 % on every joint; offsets within
    0.4 mrad and 0.25 mm (truth 0.5-2.5 mrad and 0.5-1.5 mm; 480 poses with noise 0.2 mm and
    0.05 deg per axis); every identifiable parameter within 4 sd of its own interval."""
    ds, truth = _dataset(tmp_path, ur5, effect, seed=1)
    rep = diagnose_arm(ds)
    json.dumps(rep)
    top = rep["effects"][0]
    assert top["name"] == effect and top["reported"] and top["residual"] == "kinematic"
    assert rep["selected"] == [effect], [(e["name"], e["delta_bic"]) for e in rep["effects"]]
    assert top["delta_bic"] <= -10 and top["effect_size_sigma"] > 1
    assert top["heldout_rms_after"] < 0.5 * top["heldout_rms_before"]
    assert top["heldout_rms_after"] < 1.15 * np.sqrt(3) * 0.2  # position noise 0.2 mm per axis
    p = top["params"]
    joints = truth["joints"]

    def check(name: str, true: float, tol: float) -> None:
        v = p[name]
        assert v.get("identifiable", True), (name, v)
        assert abs(v["value"] - true) < tol, (name, v["value"], true)
        sd = (v["high"] - v["low"]) / (2 * 1.96)
        assert abs(v["value"] - true) < 4 * sd + 1e-12, (name, v, true)

    if effect == "joint_elasticity":
        c = truth["params"]["compliance"]
        for j in ("shoulder_lift_joint", "elbow_joint"):
            check(f"c.{j}", c[joints.index(j)], 0.10 * c[joints.index(j)])
        for j in ("wrist_1_joint", "wrist_2_joint"):
            check(f"c.{j}", c[joints.index(j)], np.inf)
        # vertical base axis, and a wrist whose centre of mass is on its axis: no gravity torque
        for j in ("shoulder_pan_joint", "wrist_3_joint"):
            assert p[f"c.{j}"]["identifiable"] is False
            assert p[f"c.{j}"]["why"] == "the predictions do not change with it"
    elif effect == "backlash":
        for i, j in enumerate(joints):
            check(f"b.{j}", truth["params"]["backlash"][i], 0.10 * truth["params"]["backlash"][i])
    else:
        for name, tol in (("dtheta", 4e-4), ("dd", 2.5e-4), ("da", 2.5e-4)):
            for i, j in enumerate(joints):
                if f"{name}.{j}" in ("dd.elbow_joint", "dd.wrist_1_joint"):
                    continue
                check(f"{name}.{j}", truth["params"][name][i], tol)
        # translations along the three parallel axes (2, 3, 4) act only as their sum
        for j in ("elbow_joint", "wrist_1_joint"):
            assert p[f"dd.{j}"]["identifiable"] is False
            assert "dd.shoulder_lift_joint" in p[f"dd.{j}"]["why"]


def test_null_poses_report_nothing_and_the_noise_floor_is_measured(tmp_path, ur5):
    ds, truth = _dataset(tmp_path, ur5, "none", seed=2)
    rep = diagnose_arm(ds)
    assert rep["selected"] == [] and not [e for e in rep["effects"] if e["reported"]]
    assert {e["name"] for e in rep["effects"]} == {
        "joint_elasticity",
        "backlash",
        "kinematic_offsets",
    }
    noise = rep["residuals"]["kinematic"]["noise_floor"]
    np.testing.assert_allclose([noise[c] for c in "xyz"], truth["ee_noise_mm"], rtol=0.15)
    np.testing.assert_allclose(
        [noise[c] for c in ("rx", "ry", "rz")], truth["ee_noise_deg"], rtol=0.15
    )
    reasons = {s["name"]: s["reason"] for s in rep["skipped"]}
    assert reasons["joint_friction"] == "needs efforts (not in the data)"


def test_position_only_poses_report_unidentifiable_offsets(tmp_path, ur5):
    """A position-only tracker: the last joint's zero offset turns the tool about an axis
    through it (no position change), and its da acts like the wrist_2 zero offset."""
    ds, truth = _dataset(tmp_path, ur5, "kinematic_offsets", seed=0, orientation=False)
    rep = diagnose_arm(ds)
    assert rep["residuals"]["kinematic"]["orientation"] is False
    assert "orientation not used" in rep["residuals"]["kinematic"]["notes"][-1]
    top = rep["effects"][0]
    assert top["name"] == "kinematic_offsets" and top["reported"]
    p = top["params"]
    assert p["dtheta.wrist_3_joint"]["identifiable"] is False
    assert p["dtheta.wrist_3_joint"]["why"] == "the predictions do not change with it"
    assert p["da.wrist_3_joint"]["identifiable"] is False
    assert "dtheta.wrist_2_joint" in p["da.wrist_3_joint"]["why"]
    assert p["dtheta.wrist_3_joint"]["low"] is None and p["dtheta.wrist_3_joint"]["high"] is None
    # an identifiable one is still recovered
    i = truth["joints"].index("elbow_joint")
    assert abs(p["da.elbow_joint"]["value"] - truth["params"]["da"][i]) < 2.5e-4

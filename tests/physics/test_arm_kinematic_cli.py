"""The kinematic arm loop through the CLI: compare, diagnose, fit --add writes physics.json and
the end-effector error falls; a log without ee_poses skips the kinematic effects with the
reason; a dataset with efforts and poses judges each effect on its own residual."""

from __future__ import annotations

import json

import numpy as np

from robogs.cli.main import main
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.dataset import Dataset
from robogs.format.validate import validate
from robogs.physics.arm import compare_arm, diagnose_arm
from robogs.synth.armlogs import ArmLogSpec, KinLogSpec, generate_armlog, generate_kinematic_dataset

SMALL = {"segments": 3, "duration_s": 4.0, "ee_rate_hz": 40.0}
NOISE_LEN_MM = np.sqrt(3) * 0.2
"""RMS length of pure position noise of 0.2 mm per axis."""


def test_cli_fit_elasticity_writes_compliance_and_the_ee_error_falls(tmp_path, ur5, capsys):
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="joint_elasticity", seed=4, **SMALL)
    )
    assert main(["compare", str(ds)]) == 0
    out = capsys.readouterr().out
    assert "end-effector residuals of tool0" in out and "position rms" in out
    before = compare_arm(ds)["kinematic"]
    assert before["rms_mm"] > 2.5 * NOISE_LEN_MM  # the droop is well above the noise
    assert main(["diagnose", str(ds)]) == 0
    out = capsys.readouterr().out
    assert "missing effect(s): joint_elasticity" in out
    assert "c.shoulder_pan_joint (the predictions do not change with it)" in out
    assert main(["fit", str(ds), "--add", "joint_elasticity", "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert fit["revision"] == 2 and fit["ee"]["rms_after_mm"] < 0.5 * fit["ee"]["rms_before_mm"]
    assert set(fit["unidentifiable"]["joint_elasticity"]) == {
        "c.shoulder_pan_joint",
        "c.wrist_3_joint",
    }
    d = Dataset.open(ds)
    assert d.physics_history() == [1]
    joints = d.physics()["joints"]
    assert "shoulder_pan_joint" not in joints  # unidentifiable: not written
    for j in ("shoulder_lift_joint", "elbow_joint"):
        c = truth["params"]["compliance"][truth["joints"].index(j)]
        assert abs(joints[j]["compliance_rad_per_nm"] - c) < 0.1 * c
    after = compare_arm(ds)
    assert after["physics_revision"] == 2
    k = after["kinematic"]
    assert k["rms_mm"] < 1.15 * NOISE_LEN_MM and k["rms_mm"] < 0.35 * before["rms_mm"]
    assert k["rms_deg"] < 0.6 * before["rms_deg"]
    for c in ("x", "y", "z"):
        assert k["channels"][c]["rms"] < 1.15 * k["channels"][c]["noise"]
    # with the compliance in physics.json nothing is missing any more
    assert diagnose_arm(ds)["selected"] == []
    assert not [f for f in validate(ds).findings if f.code.startswith("S")]


def test_fit_offsets_writes_the_identifiable_ones_and_validates(tmp_path, ur5):
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="kinematic_offsets", seed=5, **SMALL)
    )
    assert main(["fit", str(ds), "--add", "kinematic_offsets"]) == 0
    joints = Dataset.open(ds).physics()["joints"]
    for i, j in enumerate(truth["joints"]):
        off = joints[j]["offsets"]
        assert abs(off["dtheta_rad"] - truth["params"]["dtheta"][i]) < 4e-4
        assert abs(off["da_m"] - truth["params"]["da"][i]) < 2.5e-4
        if j in ("elbow_joint", "wrist_1_joint"):
            assert "dd_m" not in off  # acts only together with dd.shoulder_lift_joint
        else:
            assert abs(off["dd_m"] - truth["params"]["dd"][i]) < 2.5e-4
    after = compare_arm(ds)["kinematic"]
    assert after["rms_mm"] < 1.15 * NOISE_LEN_MM
    assert not [f for f in validate(ds).findings if f.code.startswith("S")]


def test_log_without_ee_poses_skips_the_kinematic_effects_with_the_reason(tmp_path, ur5, capsys):
    generate_armlog(tmp_path / "logs", ur5, ArmLogSpec(segments=2, duration_s=3.0, seed=1))
    ds = tmp_path / "ds"
    convert_path(tmp_path / "logs", ds, fmt="tabular", options=ConvertOptions(urdf=ur5))
    rep = diagnose_arm(ds, candidates=["joint_friction", "backlash", "kinematic_offsets"])
    reasons = {s["name"]: s["reason"] for s in rep["skipped"]}
    assert reasons == {
        "backlash": "needs ee_poses (not in the data)",
        "kinematic_offsets": "needs ee_poses (not in the data)",
    }
    assert [e["name"] for e in rep["effects"]] == ["joint_friction"]
    assert main(["diagnose", str(ds), "--effects", "joint_friction,joint_elasticity"]) == 0
    assert "skipped joint_elasticity: needs ee_poses (not in the data)" in capsys.readouterr().out
    assert main(["fit", str(ds), "--add", "backlash"]) == 2
    err = capsys.readouterr().err
    assert "backlash needs ee_poses, not in the data" in err and "Traceback" not in err


def test_efforts_and_poses_each_effect_judged_on_its_own_residual(tmp_path, ur5):
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="backlash+joint_friction", efforts=True, seed=3, **SMALL)
    )
    rep = diagnose_arm(
        ds, candidates=["joint_friction", "armature", "backlash", "joint_elasticity"]
    )
    assert set(rep["residuals"]) == {"torque", "kinematic"}
    assert sorted(rep["selected"]) == ["backlash", "joint_friction"]
    rows = {e["name"]: e for e in rep["effects"]}
    assert rows["joint_friction"]["residual"] == "torque"
    assert rows["backlash"]["residual"] == "kinematic"
    assert (
        rows["backlash"]["heldout_unit"] == "mm" and rows["joint_friction"]["heldout_unit"] == "N m"
    )
    b = rows["backlash"]["params"]
    for i, j in enumerate(truth["joints"]):
        assert (
            abs(b[f"b.{j}"]["value"] - truth["params"]["backlash"][i])
            < 0.1 * truth["params"]["backlash"][i]
        )
    assert rep["noise_floor_nm"]  # the torque figures stay at the top level

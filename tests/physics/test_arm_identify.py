"""Hidden-effect tests of the arm torque model: detection, recovery, null case, fit --add."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.dataset import Dataset
from robogs.physics.arm import compare_arm, diagnose_arm, fit_arm
from robogs.physics.effects import available_effects, get_effect
from robogs.synth.armlogs import ArmLogSpec, generate_armlog

UR5_REL = "ur5/robots/ur_description/urdf/ur5_robot.urdf"  # inside the real-data folder
REQUIRED = {
    "name",
    "family",
    "reported",
    "delta_bic",
    "heldout_rms_before",
    "heldout_rms_after",
    "params",
}


def _dataset(root: Path, urdf: Path, effect: str, seed: int = 3) -> tuple[Path, dict]:
    logs = root / f"logs_{effect}"
    truth = generate_armlog(
        logs, urdf, ArmLogSpec(effect=effect, seed=seed, segments=4, duration_s=6.0)
    )
    out = root / f"ds_{effect}"
    convert_path(logs, out, fmt="tabular", options=ConvertOptions(urdf=urdf))
    return out, truth


def _relerr(est: dict, truth: dict, effect: str, joints: list[str]) -> dict[str, float]:
    """Relative error of every recovered parameter."""
    p = {k: v["value"] for k, v in est.items()}
    if effect == "joint_friction":
        return {
            f"{n}.{j}": abs(p[f"{n}.{j}"] - truth[n][i]) / truth[n][i]
            for n in ("fc", "fv")
            for i, j in enumerate(joints)
        }
    if effect == "armature":
        return {
            f"ia.{j}": abs(p[f"ia.{j}"] - truth["ia"][i]) / truth["ia"][i]
            for i, j in enumerate(joints)
        }
    if effect == "payload":
        c = np.array(truth["com"])
        c_hat = np.array([p["cx"], p["cy"], p["cz"]])
        return {
            "mass": abs(p["mass"] - truth["mass"]) / truth["mass"],
            "com": float(np.linalg.norm(c_hat - c) / np.linalg.norm(c)),
        }
    if effect == "mass_scale":  # relative to the effect (s - 1), stricter than to s
        return {"s": abs(p["s"] - truth["s"]) / abs(truth["s"] - 1.0)}
    return {"delta": abs(p["delta"] - truth["delta"]) / truth["delta"]}


def test_arm_effects_are_registered():
    names = available_effects(model="arm")
    assert {"joint_friction", "payload", "armature", "mass_scale", "effort_time_offset"} <= set(
        names
    )
    assert get_effect("joint_friction").family == "joint"
    assert get_effect("effort_time_offset").family == "sensor"


@pytest.mark.parametrize(
    "effect", ["joint_friction", "payload", "armature", "mass_scale", "effort_time_offset"]
)
def test_hidden_effect_ranks_first_and_is_recovered(tmp_path, ur5, effect):
    ds, truth = _dataset(tmp_path, ur5, effect)
    report = diagnose_arm(ds)
    json.dumps(report)
    top = report["effects"][0]
    assert REQUIRED <= set(top)
    assert top["name"] == effect and top["reported"], [
        (e["name"], e["delta_bic"]) for e in report["effects"]
    ]
    assert top["delta_bic"] <= -10 and top["heldout_rms_after"] < top["heldout_rms_before"]
    errs = _relerr(top["params"], truth["params"], effect, truth["joints"])
    assert max(errs.values()) < 0.10, errs
    for v in top["params"].values():
        assert v["low"] <= v["value"] <= v["high"]


def test_null_log_reports_nothing_and_noise_floor_is_measured(tmp_path, ur5):
    ds, truth = _dataset(tmp_path, ur5, "none")
    report = diagnose_arm(ds)
    assert not [e["name"] for e in report["effects"] if e["reported"]]
    sigma = np.array(list(report["noise_floor_nm"].values()))
    np.testing.assert_allclose(sigma, truth["effort_noise"], rtol=0.15)
    cmp = compare_arm(ds)
    rms = np.array([cmp["joints"][j]["rms_nm"] for j in truth["joints"]])
    np.testing.assert_allclose(
        rms, truth["effort_noise"], rtol=0.2
    )  # the true model leaves only noise
    assert {e["name"] for e in report["skipped"]} >= {"kinematic_offsets", "backlash"}


def test_fit_add_writes_physics_revision_and_the_error_falls(tmp_path, ur5):
    ds, truth = _dataset(tmp_path, ur5, "joint_friction")
    before = compare_arm(ds)
    worst = before["worst_segments"][0]
    assert worst["rms_sigma"] > 5
    out = fit_arm(ds, ["joint_friction"])
    assert out["revision"] == 2
    d = Dataset.open(ds)
    assert d.physics_history() == [1]
    phys = d.physics()
    assert phys["parent_revision"] == 1
    for i, j in enumerate(truth["joints"]):
        assert (
            abs(phys["joints"][j]["friction"] - truth["params"]["fc"][i])
            < 0.1 * truth["params"]["fc"][i]
        )
        assert (
            abs(phys["joints"][j]["damping"] - truth["params"]["fv"][i])
            < 0.1 * truth["params"]["fv"][i]
        )
    after = compare_arm(ds)
    for j in truth["joints"]:
        assert after["joints"][j]["rms_nm"] < 1.1 * after["joints"][j]["noise_nm"]
        assert after["joints"][j]["rms_nm"] < 0.2 * before["joints"][j]["rms_nm"]
    assert after["physics_revision"] == 2
    # with the friction in physics.json nothing is missing any more
    report = diagnose_arm(ds)
    assert not [e["name"] for e in report["effects"] if e["reported"]]


def test_fit_add_payload_writes_link_mass_and_com(tmp_path, ur5):
    ds, truth = _dataset(tmp_path, ur5, "payload")
    fit_arm(ds, ["payload"])
    pay = Dataset.open(ds).physics()["payload"]
    assert pay["link"] == truth["payload_link"]
    assert abs(pay["mass_kg"] - 1.5) < 0.15
    assert np.linalg.norm(np.array(pay["com_m"]) - truth["params"]["com"]) < 0.1 * np.linalg.norm(
        truth["params"]["com"]
    )


@pytest.mark.realdata
def test_real_ur5_urdf_hidden_payload(tmp_path, real_data: Path):
    ds, truth = _dataset(tmp_path, real_data / UR5_REL, "payload", seed=5)
    report = diagnose_arm(ds)
    top = report["effects"][0]
    assert top["name"] == "payload" and top["reported"]
    errs = _relerr(top["params"], truth["params"], "payload", truth["joints"])
    assert max(errs.values()) < 0.10, errs

"""``robogs diagnose`` lists ``camera_intrinsics`` as a row (table and ``--json``) on a scene whose
declared intrinsics are off, and skips it, with the reason, on a dataset without camera masks."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from physics_scenarios import scenario

from robogs.cli.main import main
from robogs.cli.physics_cmd import _effects_table
from robogs.physics.api import diagnose
from robogs.synth.mutations import perturb_intrinsics


@pytest.fixture(scope="module")
def perturbed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("intr_cli") / "scene"
    synthesize(root, seed=2, size="small", progress=False)
    perturb_intrinsics(root, fx_rel=0.0, cx_px=-5.0, cy_px=3.0)
    return root


def test_diagnose_json_and_table_carry_the_camera_row(perturbed: Path, capsys) -> None:
    argv = ["diagnose", str(perturbed), "--json", "--effects", "camera_intrinsics"]
    assert main([*argv, "--mask-frames", "8"]) == 0
    d = json.loads(capsys.readouterr().out)
    (row,) = [e for e in d["effects"] if e["name"] == "camera_intrinsics"]
    for k in ("family", "reported", "delta_bic", "heldout_rms_before", "heldout_rms_after"):
        assert k in row
    assert row["family"] == "sensor" and row["reported"] and row["unit"] == "px"
    p = {q["name"].split(".")[-1]: q for q in row["params"]}
    assert p["dcx"]["value"] == pytest.approx(-5.0, abs=0.4)
    assert p["dcy"]["value"] == pytest.approx(3.0, abs=0.5)
    assert p["dfx"]["value"] == pytest.approx(0.0, abs=0.01)
    # a pure principal-point shift looks like a camera pan/tilt or translation: named as rival
    assert row["rivals"] and "calibration target" in row["separate_by"]
    assert all(k in p["dcx"] for k in ("value", "low", "high"))
    assert {s["name"] for s in d["skipped"]}.isdisjoint({"camera_intrinsics"})
    _effects_table(d["effects"], "t")
    out = capsys.readouterr().out
    assert "camera_intrinsics" in out and "px" in out and "sensor" in out


def test_dataset_without_masks_skips_the_effect_with_the_reason(tmp_path: Path) -> None:
    from robogs.synth.scenarios import write_scenario

    root = tmp_path / "scn"
    write_scenario(scenario("none"), root)
    d = diagnose(root, effects=["camera_intrinsics"]).to_dict()
    assert all(e["name"] != "camera_intrinsics" for e in d["effects"])
    (why,) = [s["reason"] for s in d["skipped"] if s["name"] == "camera_intrinsics"]
    assert why == "needs camera masks and a binding (no camera stream with panoptic label images)"
    shutil.rmtree(root)

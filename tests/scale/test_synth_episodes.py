"""``robogs synth OUT --episodes N``: N short episodes that the validator (an independent reader:
URDF forward kinematics against the closed-form poses, stamps, hashes) finds clean."""

from __future__ import annotations

import json

import pyarrow.parquet as pq

from robogs.cli.main import main
from robogs.format.validate import validate


def test_synth_episodes_writes_n_clean_episodes(tmp_path, capsys):
    out = tmp_path / "many"
    assert main(["synth", str(out), "--episodes", "12", "--episode-seconds", "0.2"]) == 0
    m = json.loads((out / "manifest.json").read_text())
    assert [e["id"] for e in m["episodes"]] == [f"ep{k:03d}" for k in range(12)]
    rel = m["episodes"][11]["streams"]["joint_states"]["path"]
    assert pq.ParquetFile(out / rel).metadata.num_rows == 100  # 0.2 s at 500 Hz
    assert m["files"][rel]["rows"] == 100
    report = validate(out)
    ran = {r.code for r in report.runs if r.status == "ran"}
    assert {"G008", "T002", "I004"} <= ran and report.findings == []
    assert not list(out.glob(".*.tmp"))  # the manifest was renamed into place
    # refuses to overwrite without --force, and replaces with it
    assert main(["synth", str(out), "--episodes", "3", "--episode-seconds", "0.2"]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["synth", str(out), "--episodes", "3", "--episode-seconds", "0.2", "--force"]) == 0
    assert len(json.loads((out / "manifest.json").read_text())["episodes"]) == 3

"""Noise floor from the data, dataset round trip, physics revisions, HTML report."""

from __future__ import annotations

import numpy as np
import pytest
from physics_scenarios import scenario

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.physics import api
from robogs.physics.prepare import prepare
from robogs.physics.recording import load_recording
from robogs.synth.scenarios import read_truth, truth_path, write_scenario


def test_noise_is_estimated_from_the_data():
    rec = scenario("none", seed=3)
    nz = prepare(rec).noise
    truth = rec.meta["noise_levels"]
    assert nz.source == "rest"
    assert nz.sigma_pos == pytest.approx(truth["pos"], rel=0.15)
    assert nz.sigma_yaw == pytest.approx(truth["rot"], rel=0.2)
    assert nz.sigma_t == pytest.approx(truth["jitter"], rel=0.25)


def test_scenario_truth_is_written_beside_the_dataset_never_inside(tmp_path):
    rec = scenario("table_tilt", seed=4)
    ds = write_scenario(rec, tmp_path / "ds")
    truth = read_truth(tmp_path / "ds")
    assert truth_path(tmp_path / "ds") == tmp_path / "ds.truth.json"
    assert truth["effect"] == "table_tilt" and truth["true_params"] == {"g_x": 0.25, "g_y": -0.15}
    # nothing inside the dataset folder names the hidden effect or its parameters
    inside = [f for f in (tmp_path / "ds").rglob("*") if f.is_file()]
    assert inside and not any("scenario.json" in f.name or "truth" in f.name for f in inside)
    for f in inside:
        data = f.read_bytes()
        assert b"table_tilt" not in data and b"g_x" not in data and b"true_params" not in data, f
    assert not any("truth" in k or "scenario" in k for k in ds.files)
    with pytest.raises(InputError, match="no scenario truth"):
        read_truth(tmp_path / "other")


def test_dataset_round_trip_fit_revision_and_revert(tmp_path):
    rec = scenario("table_tilt", seed=4)
    ds = write_scenario(rec, tmp_path / "ds")
    back = load_recording(ds)
    assert [t.name for t in back.trajectories] == [t.name for t in rec.trajectories]
    for a, b in zip(back.trajectories, rec.trajectories, strict=True):
        assert np.array_equal(a.t_ns, b.t_ns) and np.allclose(a.object_pos, b.object_pos)
        assert np.array_equal(a.grasp, b.grasp) and np.allclose(a.ee_quat, b.ee_quat)
    before = api.compare(ds)
    res = api.fit(ds, add=["table_tilt"])
    assert res.revision == 2 and res.rms_after < before.rms_mm
    ds2 = Dataset.open(tmp_path / "ds")
    assert ds2.physics_history() == [1]
    assert [e["name"] for e in ds2.physics()["effects"]] == ["table_tilt"]
    after = api.compare(ds2)
    assert after.rms_mm < 0.8 * before.rms_mm
    assert api.revert(ds2, 1) == 3
    assert Dataset.open(tmp_path / "ds").physics()["effects"] == []


def test_report_writes_html_with_svg_plots(tmp_path):
    out = api.report(scenario("none", seed=3), tmp_path / "r.html")
    text = out.read_text()
    assert text.count("<svg") == 6 and "noise floor" in text and "sliding" in text

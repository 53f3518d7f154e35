"""``robogs diagnose --auto`` for the object model, and quasi-static recognition.

Oracles: the hidden effect of design B (robogs.synth.scenarios.design_b) must be accepted first
and the loop must stop (no candidate passes once it is in the base model); on slow pushes whose
box stops at once, the dynamics-level effects must be reported unobservable, never ranked.
"""

from __future__ import annotations

import json

import pytest

from robogs.cli.main import main
from robogs.physics.diagnose import DYNAMIC_EFFECTS, diagnose_recording
from robogs.synth.scenarios import write_scenario
from robogs.synth.scenarios.design_b import make_design_b


@pytest.mark.slow
def test_auto_loop_cli_accepts_the_hidden_tilt_then_stops(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    ds = tmp_path / "b_tilt"
    rec = make_design_b("table_tilt", seed=3)
    write_scenario(rec, ds)
    png = tmp_path / "path.png"
    args = ["diagnose", str(ds), "--auto", "--effects", "table_tilt,viscous_damping"]
    assert main([*args, "--plot", str(png), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    path = d["path"]
    assert d["accepted"] == ["table_tilt"]
    assert path[0]["effect"] == "table_tilt" and path[0]["verdict"].startswith("added")
    assert path[0]["heldout_rms_after"] < path[0]["heldout_rms_before"]
    assert path[0]["heldout_gain_sigma2"] > path[0]["null_threshold_sigma2"] > 0
    assert path[-1]["verdict"].startswith("stop: no candidate passes")
    assert len(path) <= 6  # at most 5 accepted steps and the stop
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the second step ran with the tilt in the base model: it is no longer a candidate
    assert "table_tilt" not in {e["name"] for e in d["last"]["effects"]}
    assert d["last"]["gate"]["draws"] >= 100
    # the model at the end is the last step's joint refit of the accepted effects: the same model
    # (base + tilt) as step 1's candidate fit, so the same values to the fitter's precision, and
    # the generator's tilt inside its interval
    model = {p["name"]: p for p in d["model"]["table_tilt"]}
    assert d["model"]["table_tilt"] == d["last"]["present_params"]["table_tilt"]
    step1 = {p["name"]: p["value"] for p in path[0]["params"]}
    truth = rec.meta["true_params"]
    assert set(model) == set(step1) == set(truth)
    for k, v in truth.items():
        assert model[k]["value"] == pytest.approx(step1[k], rel=1e-3, abs=1e-4)
        assert model[k]["low"] < v < model[k]["high"], (k, model[k], v)


@pytest.mark.slow
def test_quasi_static_pushes_make_dynamics_unobservable(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    rec = make_design_b("none", seed=1, quasi_static=True)
    res = diagnose_recording(rec, effects=["viscous_damping", "quadratic_drag", "table_tilt"])
    assert res.design["quasi_static"] is True
    skipped = dict(res.skipped)
    for name in ("viscous_damping", "quadratic_drag"):
        assert name in DYNAMIC_EFFECTS
        assert skipped[name].startswith("unobservable: quasi-static")
        assert "releases the object at speed" in skipped[name]
    assert [r.name for r in res.rows] == ["table_tilt"]  # only the static effect is ranked
    # the converse: design B's normal pushes slide, so viscous damping is ranked there
    res = diagnose_recording(make_design_b("none", seed=1), effects=["viscous_damping"])
    assert res.design["quasi_static"] is False and [r.name for r in res.rows] == ["viscous_damping"]


@pytest.mark.parametrize("backend", ["planar", "mujoco"])
def test_auto_loop_runs_every_step_on_the_engine_asked_for(monkeypatch, backend):
    """``diagnose --auto --engine mujoco`` once ran every step on the planar engine: the loop
    built no engine and the diagnosis fell back to its default."""
    import robogs.physics.diagnose as dg

    seen: list[str] = []

    def fake(rec, *, engine=None, **kw):
        seen.append(engine.backend)
        return dg.DiagnoseResult([], [], [], 1.0, 1.0, {}, 0, {})

    monkeypatch.setattr(dg, "diagnose_recording", fake)
    path = dg.auto_loop(make_design_b("none", seed=1), engine=backend)
    assert seen == [backend]
    assert path.stopped == "no candidate passes the gate on held-out trajectories"


def test_the_path_plot_keeps_the_last_model_where_the_loop_stops():
    """The plotted error after a stop is the last accepted model's, not the base model's (a
    comprehension once read the list before it grew, so the stop fell back to the start)."""
    from robogs.physics.diagnose import AutoPath, AutoStep, path_rms

    def step(i, name, before, after, verdict):
        return AutoStep(i, name, [], before, after, -1.0, 1.0, 1.0, verdict)

    steps = [
        step(1, "viscous_damping", 2.26, 2.12, "added"),
        step(2, "table_tilt", 2.12, 1.72, "added"),
        step(3, "quadratic_drag", 1.72, 1.73, "stop: no candidate passes"),
    ]
    assert path_rms(AutoPath(steps, None, {}, "stop", 0.0)) == [2.26, 2.12, 1.72, 1.72]
    assert path_rms(AutoPath(steps[2:], None, {}, "stop", 0.0)) == [1.72, 1.72]

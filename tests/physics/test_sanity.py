"""No silent failure: a model that cannot reproduce the gross motion says so and names why.

Mutated fixtures that must be caught: the pusher stream moved 150 mm away from the box (it
never touches it), and a physics.json whose pusher offset is 40 mm wrong (the modelled pusher
stops short of the box). The clean scenario must pass unflagged.
"""

from __future__ import annotations

import copy
from dataclasses import replace

import pytest
from physics_scenarios import scenario

from robogs.physics.recording import as_recording
from robogs.physics.sanity import assess
from robogs.synth.scenarios.resets import write_session


@pytest.fixture(scope="module")
def clean():
    s = scenario("none")
    return as_recording(replace(s, trajectories=list(s.trajectories[:3]), meta={}))


def test_clean_scenario_is_unaffected(clean):
    res = assess(clean)
    assert res.ok and res.lines() == []
    assert res.rms_mm < 2 * res.noise_floor_mm


def test_pusher_that_never_touches_the_box_is_named(clean):
    far = replace(
        clean, trajectories=[replace(t, ee_pos=t.ee_pos + [0, 0.15, 0]) for t in clean.trajectories]
    )
    res = assess(far)
    assert not res.ok
    assert [f.cause for f in res.findings] == ["pusher_never_reaches"] * 3
    for f in res.findings:
        assert f.figures["closest_approach_mm"] > 10.0
        assert f.figures["object_moved_mm"] > 10.0
    assert "never reaches" in "\n".join(res.lines())


def test_wrong_pusher_offset_fails_loudly_on_every_command(tmp_path, capsys):
    from robogs.cli.main import main

    s = scenario("none")
    physics = copy.deepcopy(s.physics)
    physics["objects"]["pusher"]["offset_m"] = [-0.04, 0.0, 0.0]  # 40 mm behind the true tip
    ds = write_session(replace(s, physics=physics), s.trajectories[:3], tmp_path / "offset")
    args = [str(ds.root), "--mask-frames", "0"]
    rc = main(["diagnose", *args, "--effects", "time_offset", "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 1, out
    assert "none above the noise" not in out
    assert "the model does not reproduce the data" in out
    assert "pusher never reaches it" in out
    assert main(["compare", *args]) == 0  # compare reports, it does not judge
    out = capsys.readouterr().out
    assert "the model does not reproduce the data" in out and "never reaches" in out

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


def _jump(t, mm: float):
    """The trajectory with its object moved by ``mm`` along world x from its middle sample on: a
    jump no rigid-body model reproduces (a tracking glitch)."""
    p = t.object_pos.copy()
    p[len(p) // 2 :, 0] += 1e-3 * mm
    return replace(t, object_pos=p)


@pytest.fixture(scope="module")
def ten():
    """Ten pushes (2 speeds x 5 directions), nothing hidden."""
    from robogs.synth.scenarios import make_scenario

    s = make_scenario("none", seed=3, kinds=("push",), n_speeds=2, n_dirs=5, check=False)
    return as_recording(replace(s, meta={}))


def test_no_trajectory_is_named_on_clean_data(ten):
    res = assess(ten)
    assert res.ok and res.outliers == [] and res.outlier_lines() == []


@pytest.mark.parametrize(("glitched", "mm"), [((1,), -10.0), ((3,), 6.0), ((1, 6), 6.0)])
def test_a_trajectory_the_model_cannot_follow_is_named(ten, glitched, mm):
    """Mutated fixture: a jump in mid-trajectory (one or two of ten) is named, the clean
    trajectories are not; the exit code is not changed (the run is ok). Measured: the glitched
    ones 10-26 robust sd above the median, the clean ones under 3. On six pushes a glitch on a
    fast push pulls the base fit so far that the other fast pushes rise with it, and the rule
    (robust to about one trajectory in four) did not separate them."""
    trs = [_jump(t, mm) if i in glitched else t for i, t in enumerate(ten.trajectories)]
    res = assess(replace(ten, trajectories=trs))
    assert res.ok  # a note, not a failure
    assert [f.trajectory for f in res.outliers] == [trs[i].name for i in glitched]
    for f in res.outliers:
        assert f.cause == "trajectory_not_reproduced"
        assert f.figures["z"] > 5.0
        assert f.figures["rms_mm"] > 1.5 * f.figures["median_mm"]
    assert all(trs[i].name in "\n".join(res.outlier_lines()) for i in glitched)


def test_the_outlier_rule_against_a_brute_force_count():
    """Closed form: the rule is 'more than 5 x 1.4826 MAD above the median'."""
    import numpy as np

    from robogs.physics.sanity import trajectory_outliers

    rng = np.random.default_rng(0)
    r = 1.0 + 0.05 * rng.standard_normal(12)
    r[[3, 7]] = [1.6, 1.05 + 5.2 * 1.4826 * 0.0]  # the second is placed below
    med = np.median(r)
    mad = 1.4826 * np.median(np.abs(r - med))
    r[7] = med + 4.9 * mad  # just inside
    med = np.median(r)
    mad = 1.4826 * np.median(np.abs(r - med))
    got = [f.trajectory for f in trajectory_outliers({f"t{i}": x for i, x in enumerate(r)})]
    want = [f"t{i}" for i, x in enumerate(r) if (x - med) / mad > 5.0]
    assert got == want == ["t3"]
    assert trajectory_outliers({"a": 1.0, "b": 1.0, "c": 9.0, "d": 1.0}) == []  # < 5 trajectories
    assert trajectory_outliers({k: 1.0 for k in "abcdef"}) == []  # no spread


def test_every_command_prints_the_named_trajectory(tmp_path, capsys):
    from robogs.cli.main import main
    from robogs.synth.scenarios import make_scenario

    s = make_scenario("none", seed=3, kinds=("push",), n_speeds=2, n_dirs=5, check=False)
    trs = [_jump(t, 6.0) if i == 3 else t for i, t in enumerate(s.trajectories)]
    ds = write_session(s, trs, tmp_path / "glitch")
    assert main(["compare", str(ds.root), "--mask-frames", "0"]) == 0
    out = capsys.readouterr().out
    assert "trajectories the model follows far worse than the others:" in out
    assert f"  {trs[3].name}: the base model's residual" in out
    assert sum(t.name in out.split("far worse")[1] for t in trs) == 1

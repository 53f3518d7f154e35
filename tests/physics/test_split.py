"""Cutting a long episode into trajectories: gaps, teleports (hand resets), rest-motion-rest.

The long episode is joined from independently simulated pushes by
``robogs.synth.scenarios.resets`` (which knows nothing of the cut), so the truth is the push
each object sample came from.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from physics_scenarios import scenario

from robogs.format.errors import InputError
from robogs.physics.recording import load_recording
from robogs.physics.split import find_cuts, parse_split, split_recording_trajectory
from robogs.synth.scenarios.resets import join_pushes, write_session

JOINS = ["gap", "teleport", "rest"]


@pytest.fixture(scope="module")
def session():
    s = scenario("none")
    return s, join_pushes(list(s.trajectories[:4]), JOINS)


def test_every_push_boundary_is_found_with_its_cause(session):
    _, js = session
    tr = js.trajectory
    cuts = find_cuts(tr.t_ns, tr.object_pos, tr.object_quat)
    assert [c.why for c in cuts] == JOINS
    for k, c in enumerate(cuts):  # each cut lies between push k's last and push k+1's first
        assert js.push_t_ns[k][-1] < c.t_ns < js.push_t_ns[k + 1][0]
    parts, rows = split_recording_trajectory(tr)
    assert len(parts) == 4 and [r.why_end for r in rows[:-1]] == JOINS
    for k, (part, stamps) in enumerate(zip(parts, js.push_t_ns, strict=True)):
        missing = np.setdiff1d(stamps, part.t_ns)
        assert len(missing) <= 2, f"piece {k} lacks {len(missing)} samples of push {k}"
        others = np.concatenate([s for j, s in enumerate(js.push_t_ns) if j != k])
        assert not np.isin(part.t_ns, others).any(), f"piece {k} holds another push's samples"
        extra = np.setdiff1d(part.t_ns, stamps)
        assert len(extra) * 1 / 30 <= 0.75  # at most the 0.6 s rest pad (30 fps), both sides


def test_single_pushes_are_not_cut():
    for tr in scenario("none").trajectories:
        assert find_cuts(tr.t_ns, tr.object_pos, tr.object_quat) == []


def test_split_modes_and_bad_values(session):
    _, js = session
    tr = js.trajectory
    assert len(split_recording_trajectory(tr, "none")[0]) == 1
    t0 = int(min(tr.t_ns[0], tr.ee_t_ns[0]))
    at = 1e-9 * (js.push_t_ns[2][0] - 100_000_000 - t0)
    parts, rows = split_recording_trajectory(tr, *parse_split(f"at={at}"))
    assert len(parts) == 2 and rows[0].why_end == "at"
    assert parts[0].t_ns[-1] < t0 + at * 1e9 <= parts[1].t_ns[0]
    assert np.isin(js.push_t_ns[2], parts[1].t_ns).all()
    for bad in ("sometimes", "at=", "at=-1", "at=x"):
        with pytest.raises(InputError):
            parse_split(bad)


@pytest.mark.parametrize("method", ["default", "parametric"])
def test_cut_recording_diagnoses_as_separate_episodes(session, tmp_path, monkeypatch, method):
    """A 4-push null recording, cut or given as separate episodes, reports the same (nothing).
    Under the opt-in parametric null the separate episodes reported Stribeck (fall 19.3 vs
    5.8 sigma^2, dBIC -2.3) until few trajectories asked for strong in-sample evidence there too."""
    from robogs.physics import api

    if method == "parametric":
        monkeypatch.setenv("ROBOGS_GATE_METHOD", "parametric")
    else:
        monkeypatch.delenv("ROBOGS_GATE_METHOD", raising=False)
    s, js = session
    sep = write_session(s, js.pushes, tmp_path / "separate")
    one = write_session(s, [js.trajectory], tmp_path / "joined")
    rec = load_recording(one)
    assert [t.name for t in rec.trajectories] == [f"session#{k}" for k in range(4)]
    assert len(load_recording(one, split="none").trajectories) == 1
    effects = ["time_offset", "mass", "stribeck"]
    a = api.diagnose(sep, effects=effects, mask_frames=0)
    b = api.diagnose(one, effects=effects, mask_frames=0)
    assert [r.name for r in a.reported] == [r.name for r in b.reported] == []  # a null
    assert b.rms_base == pytest.approx(a.rms_base, rel=0.1)
    assert b.noise_floor == pytest.approx(a.noise_floor, rel=0.1)
    if [r.name for r in a.reported] == ["stribeck"]:
        pytest.xfail(
            "known gap (issue 17): on this 4-trajectory null session Stribeck passes the "
            "few-trajectory (Webb) gate by a hair (19.3 vs 19.2 sigma^2); its fit is short of its "
            "optimum and its held-out statistic can exceed the null on null data"
        )
    assert [r.name for r in a.reported] == []


def test_compare_cli_shows_the_cut(session, tmp_path, capsys):
    from robogs.cli.main import main

    s, js = session
    one = write_session(s, [js.trajectory], tmp_path / "joined")
    args = ["compare", str(one.root), "--mask-frames", "0"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "trajectories cut from the episodes (--split auto)" in out
    assert "does not reproduce" not in out
    for k, why in enumerate(["episode start / gap", "gap / teleport", "teleport / rest"]):
        line = next(ln for ln in out.splitlines() if ln.startswith(f"session#{k} "))
        assert line.endswith(why)
    assert main([*args, "--split", "at=oops"]) == 2
    # --split none keeps an episode whole: shown on one push with a hand reset inside (1.1 s,
    # which auto cuts in two), since an uncut fit of the 8.7 s session costs 10x the cut one
    tr = s.trajectories[0]
    jumped = replace(tr, object_pos=tr.object_pos + (np.arange(len(tr.t_ns)) >= 20)[:, None] * 0.05)
    reset = write_session(s, [jumped], tmp_path / "reset")
    assert len(load_recording(reset).trajectories) == 2  # what auto would print as a cut
    capsys.readouterr()
    assert main(["compare", str(reset.root), "--mask-frames", "0", "--split", "none"]) == 0
    assert "trajectories cut" not in capsys.readouterr().out


def test_teleport_is_cut_without_a_gap():
    s = scenario("none")
    tr = s.trajectories[0]
    jumped = replace(tr, object_pos=tr.object_pos + (np.arange(len(tr.t_ns)) >= 20)[:, None] * 0.05)
    cuts = find_cuts(jumped.t_ns, jumped.object_pos, jumped.object_quat)
    assert [c.why for c in cuts] == ["teleport"]
    assert tr.t_ns[19] < cuts[0].t_ns < tr.t_ns[20]

"""One "before" and one "after" everywhere: compare, diagnose, fit, report, HTML, JSON, demo.

The oracle is agreement to the printed digit between outputs that used to disagree (the demo
printed 4.69 -> 1.72 mm while its HTML said 1.81 -> 1.72 mm). The memoised baselines (in
memory and on disk) are cleared before each command that computes a number first (compare,
diagnose, fit, report), so agreement holds between numbers computed independently; the JSON
forms then reuse them. Diagnose's candidate fits and held-out rollouts are no "before" or
"after": the two tests that diagnose the demo's scenario (eight pushes, seed 0) compute them
once (``shared_fits``, keyed on every input, so any other input is fitted afresh). The second
oracle is the refit itself: the refitted base model cannot be worse than the stored one
evaluated as is, in the weighted chi^2 the refit minimises.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from physics_scenarios import scenario

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.physics import api, baseline
from robogs.physics import compare as compare_mod
from robogs.physics.compare import compare_recording
from robogs.physics.engine import Engine
from robogs.physics.report import format_span
from robogs.synth.scenarios import make_scenario, write_scenario

_NUM = r"(\d+\.\d+)"


def _html_rms(path: Path) -> tuple[str, str]:
    m = re.search(rf"RMS position error: {_NUM} mm &rarr; {_NUM} mm", path.read_text())
    assert m, "no RMS line in the HTML report"
    return m.group(1), m.group(2)


@pytest.fixture(autouse=True)
def _own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Baselines and gate calibrations cached on disk in this test's folder, not the user's."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))


def _cli(capsys: pytest.CaptureFixture[str], *argv: str, fresh: bool = True) -> str:
    """Run ``robogs ARGV`` in-process; ``fresh``: a fresh process on a fresh machine (memoised
    and disk-cached baselines cleared), so every number is computed again."""
    if fresh:
        baseline._CACHE.clear()
        shutil.rmtree(os.environ["ROBOGS_CACHE_DIR"], ignore_errors=True)
    capsys.readouterr()
    assert main(list(argv)) == 0
    return capsys.readouterr().out


@pytest.mark.slow
def test_commands_agree_on_before_and_after_to_the_printed_digit(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    shared_fits: dict[str, int],
) -> None:
    # eight pushes, as the demo: under 8 trajectories the gate's wild null has too little power
    rec = make_scenario(
        "table_tilt", seed=0, noise="nominal", kinds=("push",), n_speeds=2, n_dirs=4, check=False
    )
    ds = str(tmp_path / "ds")
    write_scenario(rec, ds)
    nomask = ("--mask-frames", "0")

    text = _cli(capsys, "compare", ds, *nomask)
    assert "physics revision 1, refitted" in text
    c_txt = re.search(rf"object position residual: rms {_NUM} mm", text).group(1)
    c_json = json.loads(_cli(capsys, "compare", ds, "--json", *nomask, fresh=False))
    assert c_json["baseline"]["revision"] == 1
    d_json = json.loads(_cli(capsys, "diagnose", ds, "--json", *nomask))
    assert [e["name"] for e in d_json["effects"] if e["reported"]][0] == "table_tilt"

    text = _cli(capsys, "fit", ds, "--add", "table_tilt", *nomask)
    f_before, f_after = re.search(rf"object position RMS: {_NUM} → {_NUM} mm", text).groups()
    assert "before: revision 1, after: revision 1 + table_tilt" in text
    doc = Dataset.open(ds).physics()
    assert doc["revision"] == 2 and doc["fit"] == {"from_revision": 1, "added": ["table_tilt"]}

    def no_diagnose(*a: object, **k: object) -> None:
        raise AssertionError("report of a fitted revision must not re-diagnose")

    monkeypatch.setattr(api, "diagnose", no_diagnose)
    html = tmp_path / "r.html"
    text = _cli(capsys, "report", ds, "--out", str(html))
    r_before, r_after = re.search(rf"object position RMS: {_NUM} → {_NUM} mm", text).groups()
    assert "before: revision 1, refitted" in text and "after: revision 2, refitted" in text
    h_before, h_after = _html_rms(html)
    r_json = json.loads(_cli(capsys, "report", ds, "--out", str(html), "--json", fresh=False))
    assert r_json["before"]["revision"] == 1 and r_json["after"]["revision"] == 2
    text = _cli(capsys, "compare", ds, *nomask, fresh=False)  # the written revision
    c2_txt = re.search(rf"object position residual: rms {_NUM} mm", text).group(1)

    def two(x: float) -> str:
        return f"{x:.2f}"

    befores = {
        "compare text": c_txt,
        "compare json": two(c_json["rms_mm"]),
        "diagnose json": two(d_json["rms_base_mm"]),
        "fit text": two(float(f_before)),
        "report text": r_before,
        "report json": two(r_json["rms_before_mm"]),
        "html": h_before,
    }
    afters = {
        "fit text": two(float(f_after)),
        "report text": r_after,
        "report json": two(r_json["rms_after_mm"]),
        "html": h_after,
        "compare of revision 2": c2_txt,
    }
    assert len(set(befores.values())) == 1, befores
    assert len(set(afters.values())) == 1, afters
    assert f_before == f"{c_json['rms_mm']:.3f}" and f_after == f"{r_json['rms_after_mm']:.3f}"
    # the refit is no worse than the stored model as is (in the weighted chi^2 it minimises;
    # the RMS in mm weighs samples differently), and the hidden tilt is explained
    eng = Engine(rec)
    space = eng.space([])
    stored = eng.evaluate(space, eng.start(space)[None], np.zeros((1, eng.prep.n_traj, 3)))[0]
    bl = baseline.baseline(rec)
    assert bl.outcome.cost <= float(np.sum(stored**2))
    assert r_json["rms_after_mm"] < 0.85 * r_json["rms_before_mm"]


@pytest.mark.slow
def test_demo_terminal_html_and_json_agree(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], shared_fits: dict[str, int]
) -> None:
    from robogs.cli.demo_cmd import physics_demo

    baseline._CACHE.clear()
    capsys.readouterr()
    assert physics_demo(tmp_path, 0, "table_tilt", progress=False) == 0
    err = capsys.readouterr().err
    for k in range(1, 6):  # every step: its number, the time elapsed and the time it took
        assert re.search(rf"^\[{k}/5\] .*\(elapsed \d+ s(, about \d+ s left)?\)$", err, re.M), err
    assert len(re.findall(r": \d+\.\d s$", err, re.M)) == 5, err
    c = re.search(rf"compare.*\n.*object position RMS {_NUM} mm", err).group(1)
    d = re.search(rf"base model {_NUM} mm", err).group(1)
    fit_b, fit_a = re.search(rf"\n {{6}}RMS {_NUM} -> {_NUM} mm \(noise", err).groups()
    rep_b, rep_a = re.search(rf"\n {{6}}RMS {_NUM} -> {_NUM} mm \(before", err).groups()
    h_b, h_a = _html_rms(tmp_path / "physics_report.html")
    js = json.loads((tmp_path / "physics.json").read_text())
    j_b = {
        f"{js['compare']['rms_mm']:.2f}",
        f"{js['diagnose']['rms_base_mm']:.2f}",
        f"{js['fit']['rms_before_mm']:.2f}",
        f"{js['report']['rms_before_mm']:.2f}",
    }
    j_a = {f"{js['fit']['rms_after_mm']:.2f}", f"{js['report']['rms_after_mm']:.2f}"}
    assert {c, d, fit_b, rep_b, h_b} | j_b == {c}, (c, d, fit_b, rep_b, h_b, j_b)
    assert {fit_a, rep_a, h_a} | j_a == {fit_a}, (fit_a, rep_a, h_a, j_a)
    assert js["reported"][:1] == ["table_tilt"] and float(fit_a) < float(fit_b)


@pytest.mark.slow
def test_fit_without_add_refits_the_base(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ds = tmp_path / "ds"
    write_scenario(scenario("none", seed=3), ds)
    text = _cli(capsys, "fit", str(ds), "--mask-frames", "0")
    before, after = (float(x) for x in re.search(rf"RMS: {_NUM} → {_NUM} mm", text).groups())
    doc = Dataset.open(ds).physics()
    assert doc["revision"] == 2 and doc["fit"] == {"from_revision": 1, "added": []}
    assert doc["note"] == "fit: refitted the base model" and doc["effects"] == []
    # refitting a refitted model from its optimum changes nothing visible
    assert after == pytest.approx(before, abs=0.002)
    assert "base.friction_dynamic" in text  # the refitted base parameter is printed


def test_segments_end_where_the_next_sample_starts() -> None:
    rec = scenario("none", seed=3)
    res = compare_recording(rec)
    period = np.median(np.concatenate([np.diff(t.t_ns) for t in rec.trajectories])) * 1e-9
    for s in res.worst:
        tr = next(t for t in rec.trajectories if t.name == s.trajectory)
        t = (tr.t_ns - tr.t_ns[0]) * 1e-9
        i = int(np.flatnonzero(np.isclose(t, s.t_start, rtol=0, atol=1e-12))[0])
        end = t[i + s.n] if i + s.n < len(t) else t[-1] + period  # the last: one period on
        assert s.t_end > s.t_start and s.t_end == pytest.approx(end, abs=1e-12)


def test_single_sample_segments_show_their_sample_period(monkeypatch) -> None:
    """Every phase run cut into single samples: none may print as a zero-length range."""

    def singles(mask: np.ndarray) -> list[tuple[int, int]]:
        return [(int(i), int(i) + 1) for i in np.flatnonzero(mask)]

    monkeypatch.setattr(compare_mod, "runs", singles)
    rec = scenario("none", seed=3)
    res = compare_recording(rec)
    period = np.median(np.concatenate([np.diff(t.t_ns) for t in rec.trajectories])) * 1e-9
    assert res.worst and all(s.n == 1 for s in res.worst)
    for s in res.worst:
        tr = next(t for t in rec.trajectories if t.name == s.trajectory)
        t = (tr.t_ns - tr.t_ns[0]) * 1e-9
        i = int(np.flatnonzero(np.isclose(t, s.t_start, rtol=0, atol=1e-12))[0])
        step = t[i + 1] - t[i] if i + 1 < len(t) else period
        assert s.t_end - s.t_start == pytest.approx(step, abs=1e-12) and step > 0
        a, b = format_span(s.t_start, s.t_end).removesuffix(" s").split("–")
        assert a != b


def test_format_span_keeps_the_ends_apart() -> None:
    assert format_span(0.53, 0.5633) == "0.53–0.56 s"
    assert format_span(0.53, 0.531) == "0.530–0.531 s"  # a 1 kHz sample
    assert format_span(1.0, 1.0000004) == "1.000000–1.000000 s"  # below a microsecond: as is

"""``robogs report --holdout`` / ``--holdout-column`` (issue 17, Deliver 5): the report's held-out
numbers are those of the named split, and the report says which split it used.

Oracles: (1) one baseline everywhere (issue 17, D3): the report's held-out RMS before and after
equal, to 1e-9 mm, ``compare --holdout``'s held-out RMS of the current revision, ``diagnose
--holdout``'s row and ``fit --dry-run --holdout``'s (the report runs first on a fresh cache; the
others reuse its memoised baseline, as they would its disk cache, and compute their held-out
steps and rollouts themselves); (2) a mutated split (another trajectory held out) changes
the reported held-out number and the names in the HTML, so the option is not ignored; the
diagnosis the report embeds (no ``--add``) is ``diagnose --holdout-column``'s for the same split,
null quantiles included; (3) a bad choice exits 2 with diagnose's one-line error, before any fit.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import pytest
from physics_scenarios import scenario

from robogs.cli.main import main
from robogs.physics import baseline

HELD = ["push_d0_v0", "push_d1_v1"]
SPLIT = "held out: push_d0_v0, push_d1_v1 (2 of 6 trajectories)"
NOMASK = ("--mask-frames", "0")


@pytest.fixture(scope="module")
def tilt_ds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The six-push tilt scenario of test_holdout_object.py (and docs/physics.md §5.3)."""
    from robogs.synth.scenarios import write_scenario

    ds = tmp_path_factory.mktemp("report_holdout") / "ds"
    write_scenario(scenario("table_tilt"), ds)
    return ds


@pytest.fixture(autouse=True)
def _own_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))


def _cli(capsys: pytest.CaptureFixture[str], *argv: str, fresh: bool = True):
    """``robogs ARGV`` in-process; ``fresh``: memoised and disk-cached baselines cleared first,
    so every number is computed again."""
    if fresh:
        baseline._CACHE.clear()
        shutil.rmtree(os.environ["ROBOGS_CACHE_DIR"], ignore_errors=True)
    capsys.readouterr()
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


def _json(text: str) -> dict:
    """The command's JSON object (the sanity summary line that follows it left out)."""
    return json.JSONDecoder().raw_decode(text)[0]


def _report(capsys, ds: Path, html: Path, *opts: str, fresh: bool = True) -> tuple[dict, str]:
    rc, out, err = _cli(capsys, "report", str(ds), "--out", str(html), "--json", *opts, fresh=fresh)
    assert rc == 0, err
    return _json(out), html.read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def _held_store() -> dict:
    """The module's one fresh ``report --add table_tilt --holdout HELD --json`` (see
    :func:`_held_report`)."""
    return {}


def _held_report(capsys, ds: Path, html: Path, store: dict) -> tuple[dict, str]:
    """``report --add table_tilt --holdout HELD --json``, run once per module and worker on a
    fresh cache (memoised and disk-cached baselines cleared) by the first test that asks;
    the tests that read it only read it (the same command, the same inputs: computing it again
    would give the same numbers, 1e-9 mm oracles included)."""
    if "rep" not in store:
        store["rep"], store["page"] = _report(
            capsys, ds, html, "--add", "table_tilt", "--holdout", ",".join(HELD)
        )
    return store["rep"], store["page"]


def _held_line(page: str) -> tuple[float, float]:
    m = re.search(r"Held-out RMS position error \([^)]*\): ([\d.]+) mm &rarr; ([\d.]+) mm", page)
    assert m, "no held-out line in the HTML report"
    return float(m.group(1)), float(m.group(2))


def test_report_holdout_is_diagnose_compare_and_fit_holdout(tilt_ds, capsys, tmp_path, _held_store):
    rep, page = _held_report(capsys, tilt_ds, tmp_path / "r.html", _held_store)
    warm = {"fresh": False}  # the memoised baseline of the report (test_one_baseline: fresh)
    rc, out, err = _cli(
        capsys, "compare", str(tilt_ds), "--json", *NOMASK, "--holdout", HELD[0], **warm
    )
    assert rc == 0, err
    one = _json(out)["heldout"]  # another split gives another number (the option is read)
    rc, out, err = _cli(
        capsys, "compare", str(tilt_ds), "--json", *NOMASK, "--holdout", ",".join(HELD), **warm
    )
    assert rc == 0, err
    cmp = _json(out)["heldout"]
    rc, out, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--effects", "table_tilt", "--json", *NOMASK,
        "--holdout", ",".join(HELD), **warm,
    )  # fmt: skip
    assert rc == 0, err
    diag = _json(out)
    (row,) = diag["effects"]
    rc, out, err = _cli(
        capsys, "fit", str(tilt_ds), "--add", "table_tilt", "--dry-run", "--json", *NOMASK,
        "--holdout", ",".join(HELD), **warm,
    )  # fmt: skip
    assert rc == 0, err
    fit = _json(out)

    before, after = rep["heldout_rms_before_mm"], rep["heldout_rms_after_mm"]
    assert before == pytest.approx(cmp["heldout_rms_mm"], rel=0, abs=1e-9)
    assert before == pytest.approx(row["heldout_rms_before"], rel=0, abs=1e-9)
    assert before == pytest.approx(fit["heldout_rms_before_mm"], rel=0, abs=1e-9)
    assert after == pytest.approx(row["heldout_rms_after"], rel=0, abs=1e-9)
    assert after == pytest.approx(fit["heldout_rms_after_mm"], rel=0, abs=1e-9)
    assert abs(one["heldout_rms_mm"] - before) > 0.05  # the split changes the number
    assert rep["heldout_split"] == cmp["split"] == diag["design"]["split"] == SPLIT
    assert rep["holdout"] == cmp["holdout"] == HELD
    # the HTML names the split and prints the same numbers
    assert f"Split of the held-out error and the gate: {SPLIT}." in page
    assert _held_line(page) == (round(before, 3), round(after, 3))


def test_a_mutated_split_changes_the_report(tilt_ds, capsys, tmp_path, _held_store):
    """Split A is the first test's report (:func:`_held_report`); B and D are computed here."""
    rep_a, page_a = _held_report(capsys, tilt_ds, tmp_path / "a.html", _held_store)
    rep_b, page_b = _report(
        capsys, tilt_ds, tmp_path / "b.html", "--add", "table_tilt", "--holdout", "push_d2_v1",
        fresh=False,
    )  # fmt: skip
    rep_d, page_d = _report(
        capsys, tilt_ds, tmp_path / "d.html", "--add", "table_tilt", fresh=False
    )
    for rep, page in ((rep_a, page_a), (rep_b, page_b), (rep_d, page_d)):
        assert _held_line(page) == (
            round(rep["heldout_rms_before_mm"], 3),
            round(rep["heldout_rms_after_mm"], 3),
        )
    assert "held out: push_d2_v1 (1 of 6 trajectories)" in page_b and "push_d0_v0," not in page_b
    assert "push_d2_v1 (1 of 6" not in page_a and SPLIT in page_a
    assert "default folds (5 folds of whole trajectories)" in page_d and "held out:" not in page_d
    assert rep_d["holdout"] == [] and rep_b["holdout"] == ["push_d2_v1"]
    for key in ("heldout_rms_before_mm", "heldout_rms_after_mm"):  # 2.3-3.0 mm, 1.85-1.99 mm
        vals = [rep_a[key], rep_b[key], rep_d[key]]
        assert min(abs(x - y) for i, x in enumerate(vals) for y in vals[i + 1 :]) > 0.01, key
    # the in-sample numbers do not depend on the split
    assert rep_a["rms_after_mm"] == pytest.approx(rep_b["rms_after_mm"], rel=1e-12)


def test_the_embedded_diagnosis_is_diagnose_on_the_same_split(
    tilt_ds, capsys, tmp_path, shared_fits
):
    """No --add: the report diagnoses (on the split) to pick its "after", and shows that
    diagnosis; --holdout-column selects the segment as diagnose's does. ``diagnose`` then
    reuses the report's candidate fits and rollouts where its inputs (the folds among them)
    are the same (fit_memo), and the gate's calibration from the disk cache of that split."""
    effects = "table_tilt,time_offset"
    html = tmp_path / "c.html"
    rc, out, err = _cli(
        capsys, "report", str(tilt_ds), "--out", str(html), "--effects", effects,
        "--holdout-column", "segment=push_d2_v1",
    )  # fmt: skip
    assert rc == 0, err
    assert "--holdout-column segment in {push_d2_v1}: episodes push_d2_v1" in out
    assert "(held out: push_d2_v1 (1 of 6 trajectories), as diagnose)" in out
    page = html.read_text(encoding="utf-8")
    rc, dout, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--effects", effects, "--json", "--holdout",
        "push_d2_v1", fresh=False,
    )  # fmt: skip
    assert rc == 0, err
    diag = _json(dout)
    assert diag["design"]["split"] == "held out: push_d2_v1 (1 of 6 trajectories)"
    table = page[page.index("<h2>Diagnosis on the same split (held out: push_d2_v1") :]
    table = table[: table.index("</table>")]
    for e in diag["effects"]:
        cells = re.search(rf"<tr><td>{e['name']}</td>(.*?)</tr>", table).group(1)
        want = (
            f"<td>{e['heldout_rms_before']:.3f} → {e['heldout_rms_after']:.3f} mm</td>"
            f"<td>{e['heldout_gain_sigma2']:.3g}</td><td>{e['null_threshold_sigma2']:.3g}</td>"
        )
        assert cells.startswith(want), (e["name"], cells, want)
    (top,) = [e for e in diag["effects"] if e["reported"]]
    assert _held_line(page) == (
        round(top["heldout_rms_before"], 3),
        round(top["heldout_rms_after"], 3),
    )


def test_bad_holdout_exits_2_with_diagnose_errors(tilt_ds, capsys, tmp_path, monkeypatch):
    from robogs.physics import api

    def no_fit(*a, **k):  # a bad choice is refused before any fit
        raise AssertionError("fitted before checking --holdout")

    monkeypatch.setattr(api, "_fit_engine", no_fit)
    monkeypatch.setattr(api, "baseline", no_fit)
    # no fit may run, so nothing here needs a fresh cache: the memoised baselines are kept for
    # the next test (clearing them only made it refit the same baseline)
    warm = {"fresh": False}
    html = str(tmp_path / "x.html")
    for opts in (
        ("--holdout", "push_d0_v0,nope"),
        ("--holdout", ",".join(f"push_d{d}_v{v}" for d in range(3) for v in range(2))),
        ("--holdout", " , "),
        ("--holdout-column", "segment=zzz"),
        ("--holdout-column", "colour"),
    ):
        rc, _, err_r = _cli(
            capsys, "report", str(tilt_ds), "--add", "table_tilt", "--out", html, *opts, **warm
        )
        assert rc == 2
        rc, _, err_d = _cli(
            capsys, "diagnose", str(tilt_ds), "--no-progress", *NOMASK, *opts, **warm
        )
        assert rc == 2
        assert err_r.strip().count("\n") == 0 and err_r.startswith("robogs report: error: ")
        assert err_r.replace("robogs report:", "robogs diagnose:") == err_d, opts
    rc, _, err = _cli(
        capsys, "report", str(tilt_ds), "--add", "table_tilt", "--effects", "time_offset",
        "--out", html, **warm,
    )  # fmt: skip
    assert rc == 2 and "--effects picks the candidates" in err
    assert not Path(html).exists()


def test_report_of_a_written_fit_on_the_split(tilt_ds, capsys, tmp_path):
    """No --add on a revision written by ``fit``: before = the revision it was fitted from,
    after = the written one, both held out on the split; each equals ``compare --holdout``'s
    held-out RMS of that revision (the API's ``heldout_error`` for the parent, in memory)."""
    from dataclasses import replace

    from robogs.physics import api

    ds = tmp_path / "ds"
    shutil.copytree(tilt_ds, ds)
    rc, _, err = _cli(capsys, "fit", str(ds), "--add", "table_tilt", *NOMASK, fresh=False)
    assert rc == 0, err
    rep, page = _report(capsys, ds, tmp_path / "w.html", "--holdout", "push_d2_v1", fresh=False)
    assert rep["before"]["revision"] == 1 and rep["after"]["revision"] == 2
    rc, out, err = _cli(
        capsys, "compare", str(ds), "--json", *NOMASK, "--holdout", "push_d2_v1", fresh=False
    )
    assert rc == 0, err
    cmp = _json(out)["heldout"]
    assert rep["heldout_rms_after_mm"] == pytest.approx(cmp["heldout_rms_mm"], rel=0, abs=1e-9)
    rev1 = json.loads((ds / "physics" / "history" / "rev-0001.json").read_text())
    parent = api.heldout_error(replace(api._open(str(ds))[0], physics=rev1), ["push_d2_v1"])
    assert rep["heldout_rms_before_mm"] == pytest.approx(parent["heldout_rms_mm"], abs=1e-9)
    assert rep["heldout_split"] == parent["split"] == "held out: push_d2_v1 (1 of 6 trajectories)"
    assert "Split of the held-out error and the gate: held out: push_d2_v1" in page

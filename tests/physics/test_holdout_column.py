"""``--holdout-column segment[=V1,...]`` (issue 17, Deliver 5): the held-out trajectories chosen by
a tabular log's segment column, mapped to the same machinery as ``--holdout``.

Oracles: the selection by hand from the manifest's (episode, segment) pairs; on a converted
tabular log with a ``segment`` column, ``fit --holdout-column segment=V`` gives the same
held-out RMS to the last digit as ``fit --holdout`` naming that segment's trajectory.
"""

from __future__ import annotations

import csv
import json

import pytest

from robogs.format.errors import InputError
from robogs.physics.heldout import holdout_from_column

EPS = [("a", "log.csv#0"), ("run_b", "run b"), ("run_b_s01", "run b"), ("c", "c")]


def test_segment_values_select_their_episodes():
    ids, what = holdout_from_column(EPS, "segment=run b")
    assert ids == ["run_b", "run_b_s01"]  # a value cut at a time gap holds out every piece
    assert what == "segment in {run b}: episodes run_b, run_b_s01"
    assert holdout_from_column(EPS, "segment=c,log.csv#0")[0] == ["a", "c"]
    assert holdout_from_column(EPS, "segment")[0] == ["c"]  # the last episode's value
    assert holdout_from_column(EPS[:3], "segment")[0] == ["run_b", "run_b_s01"]


def test_bad_columns_and_values_are_refused_with_the_valid_ones():
    with pytest.raises(InputError, match="no per-trajectory column 'task'") as e:
        holdout_from_column(EPS, "task=1")
    assert "segment=V1,V2" in e.value.hint
    with pytest.raises(InputError, match="no episode has segment 'zz'") as e:
        holdout_from_column(EPS, "segment=c,zz")
    assert e.value.hint == "values of segment: log.csv#0, run b, c"
    with pytest.raises(InputError, match="names no value"):
        holdout_from_column(EPS, "segment= ,")


def _segment_log(tmp_path, ur5):
    """Three generated payload segments written as one CSV with a ``segment`` column."""
    from robogs.convert.ingest.convert import ConvertOptions, convert_path
    from robogs.synth.armlogs.generate import ArmLogSpec, generate_armlog

    generate_armlog(
        tmp_path / "gen", ur5, ArmLogSpec(effect="payload", seed=3, segments=3, duration_s=2.0)
    )
    rows, header = [], None
    for k, f in enumerate(sorted((tmp_path / "gen").glob("segment_*.csv"))):
        with f.open() as fh:
            r = list(csv.reader(fh))
        header = r[0] + ["segment"]
        rows += [row + [f"run{k}"] for row in r[1:]]
    (tmp_path / "logs").mkdir()
    with (tmp_path / "logs" / "log.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    convert_path(
        tmp_path / "logs", tmp_path / "ds", fmt="tabular", options=ConvertOptions(urdf=ur5)
    )
    return tmp_path / "ds"


def test_tabular_segment_column_holds_out_that_segment(tmp_path, ur5, capsys):
    from robogs.cli.main import main
    from robogs.format import Dataset

    ds = _segment_log(tmp_path, ur5)
    eps = Dataset.open(ds).episodes
    assert [e.segment for e in eps] == ["run0", "run1", "run2"]
    name = next(e.id if e.segment == e.id else f"{e.id}/{e.segment}" for e in eps[1:2])
    base = ["fit", str(ds), "--model", "arm", "--add", "payload", "--dry-run", "--json"]
    capsys.readouterr()
    assert main([*base, "--holdout-column", "segment=run1"]) == 0
    out = capsys.readouterr()
    by_col = json.loads(out.out)
    assert "segment in {run1}" in out.err  # what was selected, on stderr with --json
    assert main([*base, "--holdout", name]) == 0
    by_name = json.loads(capsys.readouterr().out)
    assert by_col["heldout_split"] == by_name["heldout_split"]
    assert by_col["heldout_split"].endswith(f"held out: {name}")
    assert by_col["heldout_rms_after_nm"] == by_name["heldout_rms_after_nm"]
    assert main([*base, "--holdout-column", "segment=run9"]) == 2
    err = capsys.readouterr().err
    assert "no episode has segment 'run9'" in err and "run0, run1, run2" in err

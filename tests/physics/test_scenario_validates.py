"""A hidden-effect scenario written by ``robogs synth --effect`` passes its own validator (issue 19,
item 11: it used to give S007 for an undeclared object and T005 errors for its designed jitter)."""

from __future__ import annotations

from pathlib import Path

import pytest
from physics_scenarios import scenario

from robogs.format.validate import validate
from robogs.synth.scenarios import write_scenario


@pytest.mark.parametrize(
    ("effect", "noise"), [("none", "nominal"), ("table_tilt", "nominal"), ("table_tilt", "hard")]
)
def test_scenario_dataset_has_no_errors(tmp_path: Path, effect: str, noise: str) -> None:
    """The designed stamp jitter is declared as the dataset's own budget (3 sigma at p99)."""
    ds = write_scenario(scenario(effect, seed=1, noise=noise), tmp_path / "s")
    report = validate(ds.root, ignore=["binding"])
    errors = [f.to_dict() for f in report.findings if f.severity == "error"]
    assert errors == []
    assert "S007" not in report.codes()

"""docs/physics.md "From your bag to a diagnosis: a worked example" runs as written, from an
empty folder with the venv's commands on the PATH, and ends in a fit whose error falls.

The session runs once per test session (the ``push_walkthrough`` fixture of ``conftest.py``);
``test_bag_to_diagnosis`` judges the same run's diagnosis against the scenario given directly.
"""

from __future__ import annotations

import json
import re

import pytest
from bag_walkthrough import walkthrough_lines

pytestmark = pytest.mark.slow


def test_the_bag_walkthrough_runs_and_the_error_falls(push_walkthrough: dict) -> None:
    lines = walkthrough_lines()
    assert lines[-2].startswith("robogs fit") and lines[0].startswith("python -m")
    runs = push_walkthrough["runs"]
    for run in runs:
        assert run["rc"] == 0, f"{run['line']}\n{run['stdout'][-3000:]}\n{run['stderr'][-3000:]}"
        assert "Traceback" not in run["stderr"], run["line"]
    assert [r["line"] for r in runs] == lines
    out = {r["line"].split()[1]: r["stdout"] for r in runs}
    assert "mass" in out["diagnose"] and "add" in out["diagnose"]
    m = re.search(r"object position RMS: ([\d.]+) → ([\d.]+) mm", out["fit"])
    assert m is not None, out["fit"]
    before, after = float(m.group(1)), float(m.group(2))
    assert after < 0.5 * before
    folder = push_walkthrough["dir"]
    doc = json.loads((folder / "ds" / "physics.json").read_text())
    (dm,) = [e["params"]["dm"] for e in doc["effects"] if e["name"] == "mass"]
    assert doc["objects"]["box"]["mass_kg"] * (1.0 + dm) == pytest.approx(0.33, rel=0.06)
    assert (folder / "report.html").is_file()

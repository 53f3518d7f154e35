"""docs/physics.md "From your bag to a diagnosis: a worked example" runs as written, from an
empty folder with the venv's commands on the PATH, and ends in a fit whose error falls."""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "physics.md"

pytestmark = pytest.mark.slow


def _session() -> list[str]:
    text = DOC.read_text(encoding="utf-8")
    part = text[text.index("## From your bag to a diagnosis: a worked example") :]
    block = re.search(r"```bash\n(.*?)```", part, re.S).group(1)
    return [ln.strip() for ln in block.splitlines() if ln.strip()]


def test_the_bag_walkthrough_runs_and_the_error_falls(tmp_path: Path) -> None:
    lines = _session()
    assert lines[-2].startswith("robogs fit") and lines[0].startswith("python -m")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"
    out = {}
    for line in lines:
        args = shlex.split(line)
        if args[0] == "python":
            args[0] = sys.executable
        run = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True,
                             timeout=900)  # fmt: skip
        assert run.returncode == 0, f"{line}\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
        assert "Traceback" not in run.stderr, line
        out[args[1]] = run.stdout
    assert "mass" in out["diagnose"] and "add" in out["diagnose"]
    m = re.search(r"object position RMS: ([\d.]+) → ([\d.]+) mm", out["fit"])
    assert m is not None, out["fit"]
    before, after = float(m.group(1)), float(m.group(2))
    assert after < 0.5 * before
    doc = json.loads((tmp_path / "ds" / "physics.json").read_text())
    (dm,) = [e["params"]["dm"] for e in doc["effects"] if e["name"] == "mass"]
    assert doc["objects"]["box"]["mass_kg"] * (1.0 + dm) == pytest.approx(0.33, rel=0.06)
    assert (tmp_path / "report.html").is_file()

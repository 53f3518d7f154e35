"""docs/physics.md §5.3 (held-out choice) runs as written: the fit prints the held-out RMS of
the two named pushes, diagnose names the segment it held out and judges on it, and the report
prints the figures the docs quote (this check was test_report_holdout's, which ran the same
report line again on its own copy of the scenario)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from bag_walkthrough import DOC_PHYSICS, doc_bash_lines

SECTION = "### 5.3 Held-out choice"


def _doc_lines() -> list[str]:
    return doc_bash_lines(SECTION)


@pytest.mark.slow
def test_docs_holdout_lines(tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1", "ROBOGS_CACHE_DIR": str(tmp_path / "cache")}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"
    lines = _doc_lines()
    assert [shlex.split(ln)[:2] for ln in lines[1:]] == [
        ["robogs", "fit"],
        ["robogs", "diagnose"],
        ["robogs", "report"],
    ]
    assert "--holdout" in shlex.split(lines[3])
    outs = []
    for line in lines:
        args = shlex.split(line)
        if args[0] == "python":
            args[0] = sys.executable
        p = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, f"{line}\n{p.stdout[-2000:]}\n{p.stderr[-2000:]}"
        outs.append(p.stdout)
    m = re.search(
        r"held-out position RMS: ([\d.]+) → ([\d.]+) mm \(held out: push_d0_v0, push_d1_v1 "
        r"\(2 of 6 trajectories\)",
        outs[1],
    )
    assert m is not None, outs[1]
    text = DOC_PHYSICS.read_text(encoding="utf-8")
    assert f"held-out position RMS: {m.group(1)} → {m.group(2)} mm" in text  # the docs' figures
    assert float(m.group(2)) < float(m.group(1))
    assert "--holdout-column segment in {push_d2_v1}: episodes push_d2_v1" in outs[2]
    assert "held-out error and gate: held out: push_d2_v1 (1 of 6 trajectories)" in outs[2]
    # the report line prints the docs' figures (the docs wrap the line: compare unwrapped)
    said = next(ln for ln in outs[3].splitlines() if ln.startswith("held-out position RMS"))
    assert said in " ".join(text.split())
    assert "held out: push_d0_v0, push_d1_v1 (2 of 6 trajectories)" in said

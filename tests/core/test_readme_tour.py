"""The README's tour runs as written (every shell line, then the Python block), from an empty
folder, with the venv's commands on the PATH as after ``source .venv/bin/activate``."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[2] / "README.md"

pytestmark = pytest.mark.slow


def _tour() -> tuple[list[str], str]:
    text = README.read_text(encoding="utf-8")
    tour = text[text.index("## A short tour") :]
    shell = re.search(r"```bash\n(.*?)```", tour, re.S).group(1)
    python = re.search(r"```python\n(.*?)```", tour, re.S).group(1)
    lines = [ln.split("  #")[0].strip() for ln in shell.splitlines()]
    return [ln for ln in lines if ln], python


def test_the_tour_runs_as_written(tmp_path: Path) -> None:
    lines, python = _tour()
    assert any(ln.startswith("robogs synth") for ln in lines)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env["OMP_NUM_THREADS"] = "1"
    for line in lines:
        run = subprocess.run(
            shlex.split(line), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
        )
        assert run.returncode == 0, f"{line}\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}"
        assert "Traceback" not in run.stderr, line
    run = subprocess.run(
        [sys.executable, "-c", python], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    assert (tmp_path / "out" / "scene.json").is_file()
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.endswith(".lock")]

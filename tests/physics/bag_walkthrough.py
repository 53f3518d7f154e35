"""docs/physics.md's bag walkthrough as commands (a uniquely named module: several test folders
have a ``conftest``)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["DOC_PHYSICS", "WALKTHROUGH", "doc_bash_lines", "walkthrough_lines", "run_walkthrough"]


DOC_PHYSICS = Path(__file__).resolve().parents[2] / "docs" / "physics.md"
WALKTHROUGH = "## From your bag to a diagnosis: a worked example"


def doc_bash_lines(heading: str) -> list[str]:
    """The command lines of the first bash block after ``heading`` in docs/physics.md."""
    import re

    text = DOC_PHYSICS.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(.*?)```", text[text.index(heading) :], re.S).group(1)
    return [ln.strip() for ln in block.splitlines() if ln.strip()]


def walkthrough_lines() -> list[str]:
    """The command lines of docs/physics.md's bag walkthrough (its first bash block)."""
    return doc_bash_lines(WALKTHROUGH)


def run_walkthrough(folder: Path) -> list[dict]:
    """Run every walkthrough line in ``folder`` (the venv's commands first on the PATH); stop
    at the first failure. Each run: the line, its exit code, stdout and stderr."""
    import os
    import shlex
    import subprocess
    import sys

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"
    runs = []
    for line in walkthrough_lines():
        args = shlex.split(line)
        if args[0] == "python":
            args[0] = sys.executable
        p = subprocess.run(args, cwd=folder, env=env, capture_output=True, text=True, timeout=900)
        runs.append({"line": line, "rc": p.returncode, "stdout": p.stdout, "stderr": p.stderr})
        if p.returncode != 0:
            break
    return runs

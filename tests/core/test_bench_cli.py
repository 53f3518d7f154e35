"""Every bench script parses its command line: ``--help`` prints the usage and an unknown
option is an error, never a run whose figures are appended to bench/RESULTS.md under a command
line that did not ask for them (``bench/simulate.py --help`` once ran the whole bench and wrote
its section with "Command: bench/simulate.py --help")."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "bench"
SCRIPTS = sorted(BENCH.glob("*.py"))


def _parses_its_arguments(tree: ast.AST) -> bool:
    """The module builds an ``argparse.ArgumentParser`` and calls ``parse_args`` (or
    ``parse_known_args``) on something."""
    names = {
        n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
        for n in ast.walk(tree)
        if isinstance(n, ast.Call)
    }
    return "ArgumentParser" in names and bool(names & {"parse_args", "parse_known_args"})


def test_there_are_bench_scripts():
    assert len(SCRIPTS) >= 20, SCRIPTS


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_each_bench_parses_its_command_line(script: Path):
    tree = ast.parse(script.read_text(encoding="utf-8"), filename=str(script))
    assert _parses_its_arguments(tree), f"{script.name}: no argparse command line"


def test_help_and_an_unknown_option_do_not_run_the_bench(tmp_path):
    """The bench that did (its help is the parser's; a typo fails with exit status 2 before any
    measurement or write)."""
    results = BENCH / "RESULTS.md"
    before = results.stat().st_mtime_ns, results.stat().st_size
    run = [sys.executable, str(BENCH / "simulate.py")]
    h = subprocess.run([*run, "--help"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert h.returncode == 0 and h.stdout.startswith("usage: simulate.py"), h.stdout + h.stderr
    assert "--no-write" in h.stdout
    bad = subprocess.run([*run, "--no-wrte"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "unrecognized arguments: --no-wrte" in bad.stderr
    assert (results.stat().st_mtime_ns, results.stat().st_size) == before

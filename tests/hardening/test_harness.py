"""The hardening harness sees each kind of breach (so a passing fuzz run means something)."""

from __future__ import annotations

import pytest

from robogs.cli import main as cli_main

from .harness import run_inprocess, run_subprocess
from .seeds import Seeds


@pytest.fixture
def fake_verb(monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setitem(cli_main.VERBS, "fake", ("hardening.fake_verb", "misbehaves on purpose"))
    return "fake"


@pytest.mark.parametrize(
    ("how", "problem", "rc"),
    [
        ("ok", None, 0),
        ("finding", None, 1),
        ("user_error", None, 2),
        ("crash", "traceback", None),
        ("exit3", "exit code", 3),
        ("silent2", "unclear error", 2),
    ],
)
def test_inprocess_verdicts(fake_verb: str, how: str, problem: str | None, rc: int | None) -> None:
    v = run_inprocess([fake_verb, how])
    assert (v.problem, v.rc) == (problem, rc), v.describe()
    if how == "user_error":
        assert v.stderr == "robogs fake: error: x.bag: byte 3: bad input (hint: fix it)\n"
    if how == "crash":
        assert "KeyError: 'missing'" in v.detail


def test_inprocess_cpu_alarm_stops_a_spin(fake_verb: str) -> None:
    v = run_inprocess([fake_verb, "spin"], cpu_limit_s=0.5)
    assert v.problem == "hang" and 0.4 < v.cpu_s < 5, v.describe()


def test_inprocess_check_crash_is_a_breach(seeds: Seeds, monkeypatch: pytest.MonkeyPatch) -> None:
    from robogs.format.checks import schema

    def boom(*args, **kwargs):
        raise ZeroDivisionError("planted")

    monkeypatch.setattr(schema, "check_table_schema", boom)
    v = run_inprocess(["validate", seeds.dataset, "--json", "--select", "S003"])
    assert v.problem == "check crash" and "planted" in v.detail, v.describe()


def test_subprocess_limits(seeds: Seeds) -> None:
    ok = run_subprocess(["validate", seeds.dataset, "--json", "--quick"])
    assert ok.ok and ok.rc == 0 and 20e6 < ok.peak_rss < 2e9, ok.describe()
    hang = run_subprocess(["validate", seeds.dataset, "--json"], cpu_limit_s=1)
    assert hang.problem == "hang" and hang.rc is not None and hang.rc < 0, hang.describe()
    mem = run_subprocess(["validate", seeds.dataset, "--json", "--quick"], mem_limit=30 * 2**20)
    assert mem.problem == "memory", mem.describe()


def _in_a_grown_process(seeds: Seeds, run: str) -> tuple[bool, int]:
    """``h.<run>(["validate", DATASET, "--json", "--quick"])`` in a fresh interpreter that first
    holds 1.5 GB resident (then frees it): ``(ok, peak_rss)``. The big process is its own, so
    this pytest worker stays small (in-process runs measure the worker)."""
    import subprocess
    import sys
    import textwrap

    from . import harness

    code = textwrap.dedent(
        f"""
        import importlib.util, sys
        import numpy as np
        spec = importlib.util.spec_from_file_location("harness", {harness.__file__!r})
        h = importlib.util.module_from_spec(spec)
        sys.modules["harness"] = h
        spec.loader.exec_module(h)
        ballast = np.ones(1536 * 2**20 // 8)  # touched: 1.5 GB resident
        assert ballast[-1] == 1.0
        del ballast
        v = h.{run}(["validate", {str(seeds.dataset)!r}, "--json", "--quick"])
        print(v.ok, v.peak_rss)
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    ok, peak = out.stdout.split()[-2:]
    return ok == "True", int(peak)


def test_a_subprocess_peak_is_its_own_not_the_parents(seeds: Seeds) -> None:
    """A parent that held 1.5 GB must not lend its peak to the child it starts (Linux keeps the
    parent's high-water mark across vfork + exec in ``wait4``'s ``ru_maxrss``)."""
    ok, peak = _in_a_grown_process(seeds, "run_subprocess")
    assert ok and 20e6 < peak < 1e9, peak


def test_an_inprocess_peak_is_the_runs_own(seeds: Seeds) -> None:
    """A process that once held 1.5 GB (freed since) must not charge it to a later in-process
    run: the peak is reset at the run's start (``/proc/self/clear_refs``)."""
    ok, peak = _in_a_grown_process(seeds, "run_inprocess")
    assert ok and 20e6 < peak < 1e9, peak

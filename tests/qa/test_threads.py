"""``--threads``: every verb sizes its torch, OpenMP and BLAS pools before they are loaded.

Oracles: a probe verb records, at its own import (before numpy and torch load), the pool
variables, then torch's intra- and inter-op thread counts. It runs in a fresh interpreter
whose CPU affinity the test sets, so the default is known: one core.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from robogs.cli import threads
from robogs.cli.main import main, validate_main

_PROBE = """
import json, sys

def add_arguments(p):
    pass

def run(args):
    import numpy, torch
    print(json.dumps({"env_at_import": getattr(sys.modules["__main__"], "SEEN", None), "args_threads": args.threads,
                      "torch": torch.get_num_threads(),
                      "interop": torch.get_num_interop_threads()}))
    return 0
"""

# records the pool variables at the moment numpy and torch are first imported
_CHILD = """
import os, sys
VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_WAIT_POLICY")
SEEN = {}

class Spy:
    def find_spec(self, name, path=None, target=None):
        if name in ("numpy", "torch") and name not in SEEN:
            SEEN[name] = {k: os.environ.get(k) for k in VARS}
        return None

sys.meta_path.insert(0, Spy())
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
sys.path.insert(0, sys.argv[1])
from robogs.cli import main as m
m.VERBS["probe"] = ("probe_verb", "records the thread settings it sees")
sys.exit(m.main(sys.argv[2:]))
"""


def _probe(tmp_path: Path, argv: list[str], omp: str | None = None) -> dict:
    (tmp_path / "probe_verb.py").write_text(_PROBE)
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in (*threads.ENV_VARS, "OMP_WAIT_POLICY", "PYTHONPATH")
    }
    if omp is not None:
        env["OMP_NUM_THREADS"] = omp
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, str(tmp_path), *argv],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="needs sched_setaffinity")
@pytest.mark.parametrize(
    ("argv", "omp", "want"),
    [
        (["probe"], None, 1),  # default: the cores this process may use (affinity: one)
        (["--threads", "3", "probe"], None, 3),  # global form, before the verb
        (["probe", "--threads=2"], None, 2),  # after the verb
        (["probe"], "2", 2),  # an exported OMP_NUM_THREADS is a deliberate choice too
        (["probe", "--threads", "3"], "2", 3),  # the flag wins
    ],
)
def test_pools_are_sized_before_numpy_and_torch_load(
    tmp_path: Path, argv: list[str], omp: str | None, want: int
) -> None:
    got = _probe(tmp_path, argv, omp)
    pools = {
        "OMP_NUM_THREADS": str(want),
        "OPENBLAS_NUM_THREADS": str(want),
        "MKL_NUM_THREADS": str(want),
        "OMP_WAIT_POLICY": "PASSIVE",
    }
    assert got["env_at_import"] == {"numpy": pools, "torch": pools}
    assert got["torch"] == want and got["interop"] == want


def test_parse_threads() -> None:
    assert threads.parse_threads(["diagnose", "ds", "--threads", "3"]) == 3
    assert threads.parse_threads(["--threads=2", "compare", "ds"]) == 2
    assert threads.parse_threads(["compare", "ds"]) is None
    assert threads.parse_threads(["fit", "--", "--threads", "9"]) is None
    for bad in (["--threads"], ["--threads", "0"], ["--threads=x"]):
        with pytest.raises(ValueError, match="--threads"):
            threads.parse_threads(bad)


def test_default_is_the_affinity_not_the_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert threads.resolve_threads(None) == len(os.sched_getaffinity(0))
    assert threads.resolve_threads(5) == 5
    monkeypatch.setenv("OMP_NUM_THREADS", "junk")
    assert threads.resolve_threads(None) == len(os.sched_getaffinity(0))


def test_bad_value_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--threads", "0", "compare", "x"]) == 2
    assert validate_main(["x", "--threads", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("--threads must be >= 1") == 2 and "Traceback" not in err


def test_robogs_validate_takes_threads(capsys: pytest.CaptureFixture[str]) -> None:
    assert validate_main(["--help"]) == 0
    assert "--threads N" in capsys.readouterr().out


def test_in_process_main_puts_the_settings_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import torch

    from robogs.cli import main as cli_main

    (tmp_path / "probe_verb.py").write_text(_PROBE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(cli_main.VERBS, "probe", ("probe_verb", "probe"))
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    torch.set_num_threads(1)
    assert main(["probe", "--threads", "2"]) == 0
    seen = json.loads(capsys.readouterr().out)
    assert seen["torch"] == 2 and seen["args_threads"] == 2
    assert torch.get_num_threads() == 1 and os.environ["OMP_NUM_THREADS"] == "1"


_NUMBA_CHILD = """
import os
import numpy as np
from robogs.cli import threads

n = threads.available_cores() + 1  # not numba's default, so a restored variable would differ
old = threads.configure_env(n)
import numba

@numba.njit(parallel=True)
def total(x):
    s = 0.0
    for i in numba.prange(x.shape[0]):
        s += x[i]
    return s

assert total(np.ones(8)) == 8.0  # starts numba's pool, sized n
threads.restore_env(old)

@numba.njit
def plus(x):
    return x + 1.0

assert plus(1.0) == 2.0  # numba rereads its variables before this compilation
old = threads.configure_env(1)  # a second verb in the same process, another thread count

@numba.njit
def twice(x):
    return 2.0 * x

assert twice(1.0) == 2.0
threads.restore_env(old)
print(os.environ.get("NUMBA_NUM_THREADS"), numba.config.NUMBA_NUM_THREADS, n)
"""


def test_numba_keeps_its_pool_size_across_verbs_in_one_process() -> None:
    """Two verbs in one process (``main([...])`` in a notebook or a test): numba, loaded during
    the first, must not see ``NUMBA_NUM_THREADS`` change afterwards (it raises "Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched" at the next
    compilation). Fails if restore_env puts the variable back or configure_env sets it again."""
    pytest.importorskip("numba")
    env = {k: v for k, v in os.environ.items() if k not in threads.ENV_VARS}
    out = subprocess.run(
        [sys.executable, "-c", _NUMBA_CHILD], capture_output=True, text=True, env=env, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    var, pool, n = out.stdout.split()
    assert var == pool == n

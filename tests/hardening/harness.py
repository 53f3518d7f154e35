"""Run a robogs CLI command on hostile input and judge it against the hardening contract.

The contract (issue "Hardening", part 1): exit code 0, 1 or 2, with a finding or one clear
error; never a traceback; never a hang over 10 s; never more than 2 GB of memory. For
``validate --json`` a finding ``X001`` (a check crashed) also breaks it: the runner turned an
exception into a finding, but it is still a bug in a reader or a check.

Two ways to run:

* :func:`run_inprocess` calls :func:`robogs.cli.main.main` in this process with
  stdout/stderr captured (fast; what the Hypothesis tests use). A CPU-time alarm
  (``ITIMER_PROF``, so a loaded machine does not trip it) turns a hang into a verdict, and the
  process's peak RSS is read after the call.
* :func:`run_subprocess` runs the same entry point in a fresh interpreter under
  ``RLIMIT_CPU`` (the hang limit, in CPU seconds), a wall-clock timeout (for hangs that sleep)
  and a watchdog that kills it when its resident memory passes the limit; the peak RSS comes
  from ``wait4``. This is the one to trust for memory and hangs that sit in C code.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

__all__ = [
    "CPU_LIMIT_S",
    "MEM_LIMIT_BYTES",
    "Verdict",
    "ContractError",
    "run_inprocess",
    "run_subprocess",
    "assert_contract",
]

CPU_LIMIT_S = 10.0
MEM_LIMIT_BYTES = 2 * 1024**3
REPO = Path(__file__).resolve().parents[2]


class ContractError(AssertionError):
    """A run broke the hardening contract."""


class _CpuAlarm(BaseException):
    """Raised by the CPU-time alarm inside the command (BaseException: nothing swallows it)."""


@dataclass
class Verdict:
    """What one run did.

    Attributes:
        argv: the arguments after ``robogs``.
        rc: exit code (None when killed).
        stdout, stderr: captured text.
        cpu_s: CPU seconds used (user + system).
        wall_s: wall seconds.
        peak_rss: peak resident memory, bytes (subprocess runs: the child's own ``VmHWM``;
            in-process runs: this process's peak during the run, ``VmHWM`` reset at its start
            where Linux allows, else the whole process's).
        problem: None when the contract holds, else what broke it ("traceback", "exit code",
            "hang", "memory", "check crash", "unclear error").
        detail: a short description of the problem (exception text, X001 message ...).
        warnings: Python warnings raised during the run (counted, not a breach).
    """

    argv: list[str]
    rc: int | None
    stdout: str
    stderr: str
    cpu_s: float
    wall_s: float
    peak_rss: int
    problem: str | None = None
    detail: str = ""
    warnings: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.problem is None

    def describe(self) -> str:
        """One paragraph for an assertion message."""
        tail = (self.stderr or self.stdout)[-1500:]
        return (
            f"robogs {' '.join(self.argv)}\n  -> {self.problem}: {self.detail}\n"
            f"  rc={self.rc} cpu={self.cpu_s:.2f}s peak_rss={self.peak_rss / 1e6:.0f} MB\n{tail}"
        )


def _judge(v: Verdict, *, cpu_limit_s: float, mem_limit: int) -> Verdict:
    """Fill ``problem``/``detail`` from the captured facts (keeps a problem already set)."""
    if v.problem is not None:
        return v
    text = v.stdout + v.stderr
    if "Traceback (most recent call last)" in text:
        v.problem, v.detail = "traceback", text[text.index("Traceback") :][-800:]
    elif v.rc not in (0, 1, 2):
        v.problem, v.detail = "exit code", f"exit code {v.rc}"
    elif v.cpu_s > cpu_limit_s:
        v.problem, v.detail = "hang", f"{v.cpu_s:.1f} CPU s over the {cpu_limit_s} s limit"
    elif v.peak_rss > mem_limit:
        v.problem, v.detail = "memory", f"peak RSS {v.peak_rss / 1e9:.2f} GB"
    elif v.rc == 2 and "error" not in v.stderr:
        v.problem, v.detail = "unclear error", "exit code 2 without an error message on stderr"
    else:
        crash = _x001(v)
        if crash:
            v.problem, v.detail = "check crash", crash
    return v


def _x001(v: Verdict) -> str:
    if v.argv[:1] != ["validate"] or "--json" not in v.argv or v.rc not in (0, 1):
        return ""
    try:
        doc = json.loads(v.stdout)
    except ValueError:
        return "validate --json printed no JSON"
    crashed = [f["message"] for f in doc.get("findings", []) if f.get("code") == "X001"]
    return crashed[0] if crashed else ""


def _status_kib(field: str) -> int | None:
    """A ``/proc/self/status`` field in KiB (None off Linux)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            return next(int(ln.split()[1]) for ln in fh if ln.startswith(field + ":"))
    except (OSError, StopIteration, ValueError):
        return None


def _reset_peak_self() -> bool:
    """Reset this process's peak RSS (``VmHWM``) to its current RSS: writing 5 to
    ``/proc/self/clear_refs`` (Linux >= 4.0). False where that is not possible."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as fh:
            fh.write("5")
        return _status_kib("VmHWM") is not None
    except OSError:
        return False


def _peak_rss_self(reset: bool) -> int:
    """Peak RSS [bytes] since :func:`_reset_peak_self` (``reset``), else of the whole process
    (``ru_maxrss``, which a pytest worker's earlier tests may have raised)."""
    kib = _status_kib("VmHWM") if reset else None
    if kib is None:
        kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # Linux: KiB
    return kib * 1024


def run_inprocess(
    argv: Sequence[str],
    *,
    cpu_limit_s: float = CPU_LIMIT_S,
    mem_limit: int = MEM_LIMIT_BYTES,
) -> Verdict:
    """Run ``robogs ARGV`` in this process and judge it (see the module docstring)."""
    from robogs.cli.main import main

    argv = [str(a) for a in argv]
    out, err = io.StringIO(), io.StringIO()
    alarm = threading.current_thread() is threading.main_thread()
    problem, detail, rc = None, "", None

    def _on_alarm(signum, frame):  # noqa: ARG001
        raise _CpuAlarm()

    old = signal.signal(signal.SIGPROF, _on_alarm) if alarm else None
    reset = _reset_peak_self()  # the run's own peak, not the worker's history
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            if alarm:
                signal.setitimer(signal.ITIMER_PROF, cpu_limit_s)
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                rc = main(argv)
        except _CpuAlarm:
            problem, detail = "hang", f"over {cpu_limit_s} CPU s"
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 2
        except BaseException as exc:  # noqa: BLE001 - anything escaping main is a breach
            problem = "traceback"
            detail = "".join(traceback.format_exception(exc))[-4000:]
        finally:
            if alarm:
                signal.setitimer(signal.ITIMER_PROF, 0)
                signal.signal(signal.SIGPROF, old)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    v = Verdict(
        argv,
        rc,
        out.getvalue(),
        err.getvalue(),
        cpu,
        wall,
        _peak_rss_self(reset),
        problem,
        detail,
        [f"{w.category.__name__}: {w.message}" for w in caught],
    )
    return _judge(v, cpu_limit_s=cpu_limit_s, mem_limit=mem_limit)


_BOOT = """
import atexit, resource, sys
cpu, hwm_path = int(sys.argv[1]), sys.argv[2]
def _hwm():
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            kib = next(int(ln.split()[1]) for ln in fh if ln.startswith("VmHWM:"))
        with open(hwm_path, "w", encoding="ascii") as out:
            out.write(str(kib * 1024))
    except Exception:
        pass
atexit.register(_hwm)
resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 2))
from robogs.cli.main import main
sys.exit(main(sys.argv[3:]))
"""
"""The child reports its own peak (``VmHWM``, the high-water mark of its address space) at
exit. ``wait4``'s ``ru_maxrss`` is not the child's: Linux carries the parent's high-water mark
across fork/vfork + exec (``exec_mmap`` keeps the old mm's peak in the process's ``maxrss``),
so a pytest worker grown to 1.4 GB made every child it started read at least 1.4 GB."""


def _rss(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def run_subprocess(
    argv: Sequence[str],
    *,
    cpu_limit_s: float = CPU_LIMIT_S,
    mem_limit: int = MEM_LIMIT_BYTES,
    wall_limit_s: float | None = None,
    cwd: Path | None = None,
) -> Verdict:
    """Run ``robogs ARGV`` in a fresh interpreter under CPU, wall and memory limits.

    The CPU limit covers the interpreter start and imports too; the wall limit defaults to
    ``max(60, 6 * cpu_limit_s)`` so that a busy machine does not count as a hang.
    """
    argv = [str(a) for a in argv]
    wall_limit_s = wall_limit_s or max(60.0, 6 * cpu_limit_s)
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONWARNINGS="ignore")
    fd, hwm_name = tempfile.mkstemp(prefix="robogs-hwm-")
    os.close(fd)
    hwm_file = Path(hwm_name)
    sampled: list[int] = [0]
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", _BOOT, str(int(cpu_limit_s)), hwm_name, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=cwd or REPO,
        env=env,
    )
    killed: list[str] = []
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.02):
            rss = _rss(proc.pid)
            sampled[0] = max(sampled[0], rss)
            if rss > mem_limit:
                killed.append("memory")
                proc.kill()
                return
            if time.perf_counter() - t0 > wall_limit_s:
                killed.append("hang")
                proc.kill()
                return

    w = threading.Thread(target=watch, daemon=True)
    w.start()
    chunks: dict[str, bytes] = {}

    def drain(name: str, stream) -> None:
        chunks[name] = stream.read()

    readers = [
        threading.Thread(target=drain, args=("out", proc.stdout)),
        threading.Thread(target=drain, args=("err", proc.stderr)),
    ]
    for r in readers:
        r.start()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    done.set()
    for r in readers:
        r.join()
    w.join()
    wall = time.perf_counter() - t0
    rc = proc.returncode
    try:  # the child's own peak; killed before exit: the watchdog's largest sample
        peak = int(hwm_file.read_text(encoding="ascii") or 0) or sampled[0]
    except (OSError, ValueError):
        peak = sampled[0]
    hwm_file.unlink(missing_ok=True)
    v = Verdict(
        argv,
        rc,
        chunks.get("out", b"").decode("utf-8", "replace"),
        chunks.get("err", b"").decode("utf-8", "replace"),
        usage.ru_utime + usage.ru_stime,
        wall,
        peak,
    )
    if killed:
        v.problem = killed[0]
        v.detail = f"killed by the {killed[0]} watchdog"
    elif rc == -signal.SIGXCPU or rc == -signal.SIGKILL:
        v.problem, v.detail = "hang", f"killed by signal {-rc} after {v.cpu_s:.1f} CPU s"
    elif rc is not None and rc < 0:
        v.problem, v.detail = "exit code", f"killed by signal {-rc} (crash in native code?)"
    return _judge(v, cpu_limit_s=cpu_limit_s, mem_limit=mem_limit)


def assert_contract(v: Verdict) -> Verdict:
    """Raise :class:`ContractError` describing the breach, or return ``v``."""
    if not v.ok:
        raise ContractError(v.describe())
    return v

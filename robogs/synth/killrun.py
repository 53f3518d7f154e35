"""Kill a robogs command with SIGKILL mid-run and classify what it left on disk.

Used by ``tests/hardening/test_kill.py`` and ``bench/kill_campaign.py``. Everything here reads
the dataset with ``json`` and ``hashlib`` only (no ``robogs.format``), so the verdict does not
depend on the code under test.

A kill leaves the dataset path in one of three states:

* ``previous``: every file (manifest included) is byte-identical to before the run;
* ``new``: a complete new version (the manifest lists exactly the files present, with matching
  sizes and sha256), i.e. the run committed before it was killed;
* ``broken``: anything else (missing, partial, mixed) — a failure of the atomic writer.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from robogs.format.writer import sibling_versions

__all__ = [
    "tree_digest",
    "is_complete_version",
    "leftovers",
    "KillResult",
    "run_and_kill",
    "run_to_end",
    "after_start",
    "when_exists",
    "tmp_appeared",
    "manifest_in_tmp",
]

_CLI = "import sys; from robogs.cli.main import main; sys.exit(main(sys.argv[1:]))"
_POLL_S = 0.001


def tree_digest(root: Path) -> dict[str, str]:
    """sha256 of every file under ``root`` (manifest included), keyed by relative path.

    Symbolic links are recorded by their target text, folders by a marker; a missing root
    gives an empty dict.
    """
    root = Path(root)
    out: dict[str, str] = {}
    if not root.is_dir():
        return out
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_symlink():
            out[rel] = "link:" + os.readlink(p)
        elif p.is_dir():
            out[rel] = "dir"
        else:
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def is_complete_version(root: Path) -> bool:
    """True when ``manifest.json`` lists exactly the files present, with their size and sha256."""
    root = Path(root)
    try:
        manifest = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
        files = manifest["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return False
    present = {
        p.relative_to(root).as_posix()
        for p in root.rglob("*")
        if p.is_file() and p.relative_to(root).as_posix() != "manifest.json"
    }
    if present != set(files):
        return False
    for rel, entry in files.items():
        p = root / rel
        if p.stat().st_size != entry.get("size"):
            return False
        if hashlib.sha256(p.read_bytes()).hexdigest() != entry.get("sha256"):
            return False
    return True


def leftovers(target: Path) -> list[str]:
    """Temp and old-version folders beside ``target`` that a writer left behind."""
    target = Path(target)
    return sorted(p.name for kind in ("tmp", "old") for p in sibling_versions(target, kind))


@dataclass
class KillResult:
    """What one killed run did.

    Attributes:
        argv: the robogs arguments.
        trigger: how the kill time was chosen.
        kill_after_s: seconds from start to the kill (None: the run ended first).
        returncode: exit status (-9 when killed).
        state: ``previous``, ``new`` or ``broken`` (see the module docstring).
        leftovers: temp/old folders beside the dataset after the kill.
    """

    argv: list[str]
    trigger: str
    kill_after_s: float | None
    returncode: int
    state: str
    leftovers: list[str] = field(default_factory=list)

    @property
    def killed(self) -> bool:
        return self.returncode == -signal.SIGKILL


Trigger = Callable[[float], bool]
"""Called every millisecond with the elapsed seconds; True fires the kill."""


def after_start(delay_s: float) -> tuple[str, Trigger]:
    """Kill ``delay_s`` seconds after the process starts."""
    return f"t={delay_s:.3f}s", lambda elapsed: elapsed >= delay_s


def when_exists(label: str, probe: Callable[[], bool], delay_s: float = 0.0) -> tuple[str, Trigger]:
    """Kill ``delay_s`` seconds after ``probe()`` first returns True."""
    seen: list[float] = []

    def fire(elapsed: float) -> bool:
        if not seen and probe():
            seen.append(elapsed)
        return bool(seen) and elapsed - seen[0] >= delay_s

    return f"{label}+{delay_s * 1e3:.1f}ms", fire


def tmp_appeared(target: Path, delay_s: float = 0.0) -> tuple[str, Trigger]:
    """Kill once the writer's temp folder exists (the write phase), after ``delay_s``."""
    target = Path(target)
    return when_exists("tmp", lambda: bool(sibling_versions(target, "tmp")), delay_s)


def manifest_in_tmp(target: Path, delay_s: float = 0.0) -> tuple[str, Trigger]:
    """Kill once the manifest is in the temp folder (commit and swap), after ``delay_s``."""
    target = Path(target)
    return when_exists(
        "manifest",
        lambda: any((p / "manifest.json").exists() for p in sibling_versions(target, "tmp")),
        delay_s,
    )


def _spawn(argv: Sequence[str], log: Path | None, env: dict[str, str] | None):
    out = open(log, "ab") if log is not None else subprocess.DEVNULL
    try:
        return subprocess.Popen(
            [sys.executable, "-c", _CLI, *argv],
            stdout=out,
            stderr=out,
            env={**os.environ, **(env or {})},
        )
    finally:
        if log is not None:
            out.close()


def run_and_kill(
    argv: Sequence[str],
    target: Path,
    trigger: tuple[str, Trigger],
    *,
    before: dict[str, str],
    timeout_s: float = 300.0,
    log: Path | None = None,
    env: dict[str, str] | None = None,
) -> KillResult:
    """Run ``robogs ARGV`` in a fresh interpreter, SIGKILL it when ``trigger`` fires, classify.

    Args:
        argv: robogs arguments, e.g. ``["fit", "ds", "--add", "x"]``.
        target: the dataset the command writes.
        trigger: ``(label, fire)`` from :func:`after_start`, :func:`tmp_appeared`...
        before: :func:`tree_digest` of ``target`` before the run.
        timeout_s: a run still alive after this is killed and reported as a hang.
        log: file collecting the command's stdout and stderr.
        env: extra environment variables.
    """
    label, fire = trigger
    proc = _spawn(argv, log, env)
    t0 = time.perf_counter()
    kill_after = None
    while proc.poll() is None:
        elapsed = time.perf_counter() - t0
        if fire(elapsed) or elapsed > timeout_s:
            proc.send_signal(signal.SIGKILL)
            kill_after = elapsed
            break
        time.sleep(_POLL_S)
    rc = proc.wait()
    if rc != -signal.SIGKILL:
        kill_after = None
    after = tree_digest(target)
    if after == before:
        state = "previous"
    elif is_complete_version(target):
        state = "new"
    else:
        state = "broken"
    return KillResult(list(argv), label, kill_after, rc, state, leftovers(target))


def run_to_end(
    argv: Sequence[str],
    *,
    timeout_s: float = 600.0,
    log: Path | None = None,
    env: dict[str, str] | None = None,
) -> tuple[int, float]:
    """Run ``robogs ARGV`` to completion; returns (exit status, seconds)."""
    proc = _spawn(argv, log, env)
    t0 = time.perf_counter()
    try:
        rc = proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        rc = proc.wait()
    return rc, time.perf_counter() - t0

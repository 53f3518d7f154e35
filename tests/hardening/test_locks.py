"""Concurrent writers, killed lock holders and the two-rename swap fallback of the writer."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from robogs.format import Dataset, LockError
from robogs.format import writer as writer_mod
from robogs.synth.killrun import is_complete_version, leftovers, tree_digest

# A second process: opens the writer, says so on stdout, waits for "go" on stdin, then writes.
_HOLDER = """
import sys
import numpy as np, pyarrow as pa
from robogs.format import Dataset
w = Dataset.create(sys.argv[1], overwrite=True)
print("locked", flush=True)
if sys.stdin.readline().strip() != "go":
    sys.exit(3)
t = np.arange(10, dtype=np.int64) * 2_000_000
w.write_table("episodes/e/joint_states.parquet", pa.table({"t_ns": t, "position.j": np.zeros(10)}),
              kind="joint_states")
w.add_episode("e", start_ns=0, end_ns=int(t[-1]), streams={"joint_states": {
    "kind": "joint_states", "path": "episodes/e/joint_states.parquet",
    "stamp_source": "synthetic", "offset_ns": 0}})
w.commit()
print("committed", flush=True)
"""


def _holder(target: Path) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(target)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "locked", proc.stderr
    return proc


def _small(path: Path, value: float) -> Dataset:
    with Dataset.create(path, overwrite=True) as w:
        t = np.arange(5, dtype=np.int64) * 2_000_000
        tab = pa.table({"t_ns": t, "position.j": np.full(5, value)})
        w.write_table("episodes/e/joint_states.parquet", tab, kind="joint_states")
        w.add_episode("e", start_ns=0, end_ns=int(t[-1]), streams={"joint_states": {
            "kind": "joint_states", "path": "episodes/e/joint_states.parquet",
            "stamp_source": "synthetic", "offset_ns": 0}})  # fmt: skip
        return w.commit()


def test_second_writer_names_lock_file_and_holder_and_first_completes(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    proc = _holder(target)
    try:
        for attempt in (lambda: Dataset.create(target, overwrite=True), Dataset.open(target).edit):
            with pytest.raises(LockError) as exc:
                attempt()
            msg = str(exc.value)
            assert f"PID {proc.pid}" in msg and str(tmp_path / ".ds.lock") in msg
        out, err = proc.communicate("go\n", timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and out.strip() == "committed", err
    ds = Dataset.open(target)
    assert ds.episode("e").table("joint_states").num_rows == 10  # the holder's version
    assert is_complete_version(target)


def test_the_cli_reports_a_held_lock_in_one_line(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    urdf, log = tmp_path / "r.urdf", tmp_path / "log.csv"
    urdf.write_text(
        '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
    )
    log.write_text("t_ns,position.j\n" + "".join(f"{i * 2_000_000},0.0\n" for i in range(20)))
    proc = _holder(target)
    try:
        res = subprocess.run(
            [sys.executable, "-c", "import sys; from robogs.cli.main import main; "
             "sys.exit(main(sys.argv[1:]))", "convert", str(log), str(target), "--urdf", str(urdf),
             "--force"],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
    finally:
        proc.kill()
        proc.wait()
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert f"PID {proc.pid}" in lines[0] and ".ds.lock" in lines[0]


def test_a_killed_holder_never_blocks_the_next_writer(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    before = tree_digest(target)
    proc = _holder(target)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    lock = tmp_path / ".ds.lock"
    assert lock.read_text().strip() == str(proc.pid)  # the dead holder's PID stays in the file
    assert leftovers(target)  # and its temp folder
    assert tree_digest(target) == before
    ds = _small(target, 2.0)  # not blocked; removes the dead writer's temp folder
    assert leftovers(target) == []
    assert ds.episode("e").table("joint_states").column("position.j").to_pylist() == [2.0] * 5
    assert lock.read_text().strip() == str(os.getpid())


def test_swap_without_rename_exchange_keeps_the_dataset(tmp_path: Path, monkeypatch) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    monkeypatch.setattr(writer_mod, "_exchange", lambda a, b: False)
    ds = _small(target, 3.0)
    assert ds.episode("e").table("joint_states").column("position.j").to_pylist() == [3.0] * 5
    assert leftovers(target) == [] and is_complete_version(target)


def test_an_interrupted_two_rename_swap_is_named_then_restored(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    expect = json.loads((target / "manifest.json").read_text())
    os.rename(target, tmp_path / ".ds.old-0123abcd")  # killed between the two renames
    with pytest.raises(Exception, match=r"\.ds\.old-0123abcd.*next robogs write restores it"):
        Dataset.open(target)
    Dataset.create(target, overwrite=True).abort()  # any writer recovers on lock acquisition
    assert json.loads((target / "manifest.json").read_text()) == expect
    assert leftovers(target) == []


def test_writing_through_path_never_changes_the_previous_version(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    ds = _small(target, 1.0)
    before = tree_digest(target)
    with ds.edit() as w:
        p = w.path("episodes/e/joint_states.parquet")  # hard-linked to the previous version
        p.write_bytes(b"overwritten in place")
        w.abort()
    assert tree_digest(target) == before

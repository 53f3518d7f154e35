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

from robogs.format import Dataset, DatasetExistsError, FormatError, LockError
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
    assert not lock.exists()  # and the lock file goes with the commit


def test_swap_without_rename_exchange_keeps_the_dataset(tmp_path: Path, monkeypatch) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    monkeypatch.setattr(writer_mod, "exchange", lambda a, b: False)
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


# -- lock file lifetime, stale locks, planted links, literal names (issue 19 items 6 and 7) --

_CLI = [sys.executable, "-c", "import sys; from robogs.cli.main import main; sys.exit(main())"]


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120
    )


def test_the_lock_file_is_removed_on_commit_abort_exception_refusal_and_exit(
    tmp_path: Path,
) -> None:
    target = tmp_path / "ds"
    lock = tmp_path / ".ds.lock"
    w = Dataset.create(target)
    assert lock.read_text().strip() == str(os.getpid())  # held while writing
    w.abort()
    assert not lock.exists()
    _small(target, 1.0)  # commit
    assert not lock.exists()
    with pytest.raises(RuntimeError, match="boom"), Dataset.open(target).edit():
        assert lock.exists()
        raise RuntimeError("boom")
    assert not lock.exists() and leftovers(target) == []
    with pytest.raises(DatasetExistsError):
        Dataset.create(target)  # refused after taking the lock
    assert not lock.exists()
    # a process that leaves a writer open and exits normally, or by an uncaught exception
    for tail in ("", "raise SystemExit(5)", "raise ValueError('x')"):
        head = "import sys\nfrom robogs.format import Dataset\n"
        res = _run(f"{head}w = Dataset.create(sys.argv[1], overwrite=True)\n{tail}", str(target))
        assert res.returncode == {"": 0, "raise SystemExit(5)": 5}.get(tail, 1), res.stderr
        assert not lock.exists() and leftovers(target) == [], (tail, res.stderr)
    assert Dataset.open(target).episode("e").table("joint_states").num_rows == 5  # untouched


def test_a_stale_lock_of_a_killed_writer_is_taken_over_with_a_note(tmp_path: Path) -> None:
    target = tmp_path / "ds"
    _small(target, 1.0)
    proc = _holder(target)
    os.kill(proc.pid, signal.SIGKILL)  # kill -9: no exit handler runs
    proc.wait()
    lock = tmp_path / ".ds.lock"
    assert lock.read_text().strip() == str(proc.pid)  # the stale file, with the dead PID
    res = _run(
        "import sys\nfrom robogs.format import Dataset\n"
        "Dataset.open(sys.argv[1]).edit().abort()\nprint('ok')",
        str(target),
    )
    assert res.returncode == 0 and res.stdout.strip() == "ok", res.stderr
    notes = [ln for ln in res.stderr.splitlines() if "stale lock" in ln]
    assert len(notes) == 1, res.stderr
    assert f"PID {proc.pid}" in notes[0] and "no longer running" in notes[0]
    assert str(lock) in notes[0] and "Traceback" not in res.stderr
    assert not lock.exists() and leftovers(target) == []
    # a lock released normally leaves no file, so the next writer has nothing to note
    res = _run("import sys\nfrom robogs.format import Dataset\nDataset.open(sys.argv[1]).edit().abort()",
               str(target))  # fmt: skip
    assert res.returncode == 0 and res.stderr == "", res.stderr


def test_a_lock_released_while_another_process_waits_is_never_split(tmp_path: Path) -> None:
    """The holder unlinks before it unlocks; an acquirer that locked the unlinked file retries."""
    target = tmp_path / "ds"
    lock_path = tmp_path / ".ds.lock"
    first = writer_mod._DatasetLock(lock_path, target)
    fd = os.open(lock_path, os.O_RDWR)  # a racer opened the same file before the release
    first.release()
    assert not lock_path.exists()
    writer_mod.fcntl.flock(fd, writer_mod.fcntl.LOCK_EX | writer_mod.fcntl.LOCK_NB)  # succeeds
    second = writer_mod._DatasetLock(lock_path, target)  # must still get the *linked* file
    try:
        assert lock_path.exists() and os.fstat(second.fd).st_ino != os.fstat(fd).st_ino
        with pytest.raises(LockError):  # and a third writer is refused on that linked file
            writer_mod._DatasetLock(lock_path, target)
    finally:
        os.close(fd)
        second.release()


def test_a_planted_symlink_lock_is_refused_and_its_victim_untouched(tmp_path: Path) -> None:
    d = tmp_path / "D"
    d.mkdir()
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    os.utime(victim, ns=(1_000_000_000, 1_000_000_000))
    (d / ".lk.lock").symlink_to(victim)
    res = subprocess.run(
        [*_CLI, "synth", str(d / "lk"), "--size", "small"], capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert "symbolic link" in lines[0] and ".lk.lock" in lines[0]
    assert victim.read_text() == "precious\n" and victim.stat().st_mtime_ns == 1_000_000_000
    assert (d / ".lk.lock").is_symlink() and not (d / "lk").exists()
    assert sorted(p.name for p in d.iterdir()) == [".lk.lock"]


@pytest.mark.parametrize("kind", ["hardlink", "fifo", "folder"])
def test_a_lock_path_that_is_not_a_plain_file_of_its_own_is_refused(tmp_path: Path, kind) -> None:
    victim = tmp_path / "victim"
    victim.write_text("precious\n")
    lock = tmp_path / ".ds.lock"
    {"hardlink": lambda: os.link(victim, lock), "fifo": lambda: os.mkfifo(lock),
     "folder": lambda: lock.mkdir()}[kind]()  # fmt: skip
    with pytest.raises(FormatError, match=r"\.ds\.lock") as exc:
        Dataset.create(tmp_path / "ds")
    assert exc.value.hint and "remove" in exc.value.hint
    assert victim.read_text() == "precious\n"
    assert not (tmp_path / "ds").exists() and leftovers(tmp_path / "ds") == []


def test_sibling_versions_match_the_name_literally(tmp_path: Path) -> None:
    names = [".run1.tmp-0123abcd", ".run1.old-89abcdef", ".runX.tmp-00000000",
             ".run[1].tmp-deadbeef", ".*.tmp-feedf00d", ".run1.tmp-0123abcd.tmp-11111111",
             ".run[1].tmp-notahexid"]  # fmt: skip
    for n in names:
        (tmp_path / n).mkdir()
    assert [p.name for p in writer_mod.sibling_versions(tmp_path / "run[1]", "tmp")] == [
        ".run[1].tmp-deadbeef"
    ]
    assert [p.name for p in writer_mod.sibling_versions(tmp_path / "*", "tmp")] == [
        ".*.tmp-feedf00d"
    ]
    assert [p.name for p in writer_mod.sibling_versions(tmp_path / "run1", "tmp")] == [
        ".run1.tmp-0123abcd"
    ]
    assert writer_mod.sibling_versions(tmp_path / "run?", "tmp") == []
    assert [p.name for p in writer_mod.sibling_versions(tmp_path / "run1", "old")] == [
        ".run1.old-89abcdef"
    ]
    assert leftovers(tmp_path / "run[1]") == [".run[1].tmp-deadbeef"]


@pytest.mark.parametrize("name", ["run[1]", "*", "run?"])
def test_a_name_with_glob_characters_never_touches_another_dataset(tmp_path: Path, name) -> None:
    d = tmp_path / "D"
    d.mkdir()
    run1 = d / "run1"
    _small(run1, 1.0)
    proc = _holder(run1)  # a live writer of run1, its temp folder in place
    try:
        stale_old = d / ".run1.old-89abcdef"  # left over from run1; only run1's writers clean it
        stale_old.mkdir()
        live_tmp = [p for p in d.iterdir() if p.name.startswith(".run1.tmp-")]
        assert len(live_tmp) == 1
        res = subprocess.run(
            [*_CLI, "synth", str(d / name), "--size", "small"], capture_output=True, text=True,
            timeout=300,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        assert live_tmp[0].is_dir() and stale_old.is_dir()  # neither was removed
        assert (d / ".run1.lock").read_text().strip() == str(proc.pid)
        out, err = proc.communicate("go\n", timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0 and out.strip() == "committed", err
    assert Dataset.open(run1).episode("e").table("joint_states").num_rows == 10
    assert is_complete_version(d / name)
    assert not (d / f".{name}.lock").exists() and not (d / ".run1.lock").exists()

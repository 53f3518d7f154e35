"""``manifest.json`` follows the same path policy as every other file (issue 19, item 5):
a regular file inside the root, size-capped; FIFOs, devices, folders, symlinks out of the root
and duplicate keys are one clear line and exit 2, never a hang, a traceback or a read of the
target."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from robogs.format import Dataset
from robogs.format.errors import FormatError, PathEscapeError


def _victim(seeds, tmp_path: Path, kind: str) -> Path:
    ds = tmp_path / "ds"
    shutil.copytree(seeds.dataset, ds)
    m = ds / "manifest.json"
    text = m.read_text()
    m.unlink()
    if kind == "dev_zero":
        m.symlink_to("/dev/zero")
    elif kind == "fifo":
        os.mkfifo(m)
    elif kind == "folder":
        m.mkdir()
    elif kind == "outside":
        secret = tmp_path / "secret.json"
        secret.write_text(text)  # a valid manifest, but outside the root: must not be read
        m.symlink_to(secret)
    elif kind == "duplicate_key":
        m.write_text(text.replace("{", '{"format": "other", ', 1))
    return ds


CASES = {
    "dev_zero": (PathEscapeError, "outside the dataset root"),
    "fifo": (FormatError, "is a FIFO, not a regular file"),
    "folder": (FormatError, "is a folder, not a regular file"),
    "outside": (PathEscapeError, "outside the dataset root"),
    "duplicate_key": (FormatError, "duplicate key 'format'"),
}


@pytest.mark.parametrize("kind", sorted(CASES))
def test_open_refuses_the_manifest(seeds, tmp_path: Path, kind: str) -> None:
    exc_type, text = CASES[kind]
    ds = _victim(seeds, tmp_path, kind)
    with pytest.raises(exc_type, match=text):
        Dataset.open(ds)


@pytest.mark.parametrize("kind", sorted(CASES))
@pytest.mark.parametrize("quick", [False, True])
def test_validate_exits_2_with_one_line(seeds, tmp_path: Path, kind: str, quick: bool) -> None:
    ds = _victim(seeds, tmp_path, kind)
    exe = Path(sys.executable).with_name("robogs-validate")
    cmd = [str(exe), str(ds)] + (["--quick"] if quick else [])
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2, run.stdout + run.stderr
    assert "Traceback" not in run.stderr
    assert CASES[kind][1] in run.stderr
    assert len([ln for ln in run.stderr.splitlines() if ln.strip()]) == 1, run.stderr

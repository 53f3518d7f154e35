"""Output failures (disk full, read-only, name too long, busy) are one clear line that blames
the output, never the input, and lose nothing (issue 19, item 9).

The failures are injected where the bytes are written (``os.open`` of the temp folder's files,
and parquet writers), as a full or read-only disk would raise them.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from robogs.format import Dataset
from robogs.format.errors import OutputError


def _tree(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def _table() -> pa.Table:
    t = np.arange(5, dtype=np.int64) * 10_000_000
    return pa.table({"t_ns": t, "position.j": np.zeros(5)})


@pytest.mark.parametrize(
    ("err", "text"),
    [
        (errno.ENOSPC, "the disk is full"),
        (errno.EROFS, "read-only"),
        (errno.ENAMETOOLONG, "name is too long"),
        (errno.EBUSY, "busy"),
    ],
)
def test_writer_oserror_is_an_output_error_and_the_old_version_survives(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, err: int, text: str
) -> None:
    w = Dataset.create(tmp_path / "ds")
    w.write_table("episodes/e/joint_states.parquet", _table(), kind="joint_states")
    w.commit()
    before = _tree(tmp_path / "ds")

    import robogs.format.writer as writer_mod

    def failing(*a, **k):
        raise OSError(err, os.strerror(err), str(tmp_path / "ds" / "x.parquet"))

    monkeypatch.setattr(writer_mod.pq, "write_table", failing)
    ds = Dataset.open(tmp_path / "ds")
    with pytest.raises(OutputError, match=text) as info, ds.edit() as w2:
        w2.write_table("episodes/e/joint_states.parquet", _table(), kind="joint_states")
        w2.commit()
    assert "nothing was changed" in str(info.value)
    assert _tree(tmp_path / "ds") == before
    assert [p.name for p in tmp_path.iterdir()] == ["ds"]  # no temp folder or lock left


def test_read_only_parent_fails_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The temp folder is made when the writer starts, so a read-only parent fails at once
    (it used to fail only at the end, after 8 s of conversion)."""
    real_mkdir = Path.mkdir

    def ro_mkdir(self, *a, **k):
        if ".tmp-" in self.name:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real_mkdir(self, *a, **k)

    monkeypatch.setattr(Path, "mkdir", ro_mkdir)
    with pytest.raises(OutputError, match="read-only"):
        Dataset.create(tmp_path / "ds")
    assert list(tmp_path.iterdir()) == []  # and the lock file is gone


CONVERT_FULL_DISK = """
import errno, os, sys
import pyarrow.parquet as pq
real = pq.ParquetWriter.write_table
def full(self, *a, **k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
pq.ParquetWriter.write_table = full
from robogs.cli.main import main
sys.exit(main(["convert", sys.argv[1], sys.argv[2]]))
"""


def test_convert_on_a_full_disk_does_not_call_the_input_corrupt(seeds, tmp_path: Path) -> None:
    src = seeds.mcaps[0]
    before = hashlib.sha256(src.read_bytes()).hexdigest()
    run = subprocess.run(
        [sys.executable, "-c", CONVERT_FULL_DISK, str(src), str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 2, run.stdout + run.stderr
    assert "the disk is full" in run.stderr
    assert "corrupt" not in run.stderr and "Traceback" not in run.stderr
    assert hashlib.sha256(src.read_bytes()).hexdigest() == before
    assert not (tmp_path / "out").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    shutil.rmtree(tmp_path, ignore_errors=True)


def test_export_to_a_read_only_folder_fails_before_the_work(
    seeds, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from robogs.convert.export import export

    real_touch = Path.touch
    calls = []

    def ro_touch(self, *a, **k):
        if ".tmp-" in self.name:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real_touch(self, *a, **k)

    monkeypatch.setattr(Path, "touch", ro_touch)
    import robogs.convert.export.splat_ply as ply_mod

    monkeypatch.setattr(ply_mod, "export_ply", lambda *a, **k: calls.append(1))
    with pytest.raises(OutputError, match="read-only"):
        export("ply", Dataset.open(seeds.dataset), tmp_path / "scene.ply")
    assert calls == [] and list(tmp_path.iterdir()) == []

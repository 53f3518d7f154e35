"""``--force`` replaces only what robogs wrote, never an input (issue 19, item 2), and an export
swap interrupted between its two renames is recovered by the next run (item 10)."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from robogs.convert.export import export
from robogs.convert.export.atomic import atomic_output
from robogs.format import Dataset
from robogs.format.errors import DatasetExistsError, InputError
from robogs.format.replace import EXPORT_MARKER


def _tree(root: Path) -> dict[str, str]:
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


@pytest.fixture
def ds(seeds, tmp_path: Path) -> Dataset:
    import shutil

    shutil.copytree(seeds.dataset, tmp_path / "data" / "ds")
    return Dataset.open(tmp_path / "data" / "ds")


@pytest.mark.parametrize("where", ["itself", "parent", "inside"])
def test_export_force_never_replaces_the_source(ds: Dataset, where: str) -> None:
    out = {"itself": ds.root, "parent": ds.root.parent, "inside": ds.root / "exp"}[where]
    before = _tree(ds.root.parent)
    with pytest.raises((DatasetExistsError, InputError), match="source|inside the dataset"):
        export("urdf", ds, out, force=True)
    assert _tree(ds.root.parent) == before


def test_export_force_never_replaces_a_foreign_folder(ds: Dataset, tmp_path: Path) -> None:
    foreign = tmp_path / "photos"
    foreign.mkdir()
    (foreign / "holiday.jpg").write_bytes(b"\xff\xd8 not robogs")
    with pytest.raises(DatasetExistsError, match="robogs did not write"):
        export("urdf", ds, foreign, force=True)
    assert (foreign / "holiday.jpg").read_bytes() == b"\xff\xd8 not robogs"


def test_export_force_replaces_its_own_export(ds: Dataset, tmp_path: Path) -> None:
    out = tmp_path / "urdf_out"
    export("urdf", ds, out)
    assert (out / EXPORT_MARKER).is_file()
    (out / "stale.txt").write_text("from the previous run")
    export("urdf", ds, out, force=True)
    assert not (out / "stale.txt").exists() and (out / EXPORT_MARKER).is_file()


def test_dataset_force_replaces_only_a_robogs_dataset(ds: Dataset, tmp_path: Path) -> None:
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "manifest.json").write_text('{"name": "my web app"}')  # not a robogs manifest
    with pytest.raises(DatasetExistsError, match="robogs did not write"):
        Dataset.create(foreign, overwrite=True)
    assert (foreign / "manifest.json").read_text() == '{"name": "my web app"}'
    with pytest.raises(DatasetExistsError, match="source"):
        Dataset.create(ds.root, overwrite=True, protect=[ds.root / "episodes"])
    w = Dataset.create(ds.root, overwrite=True)  # a robogs dataset that is not an input
    w.abort()


def test_synth_force_refuses_a_foreign_folder(tmp_path: Path) -> None:
    foreign = tmp_path / "thesis"
    foreign.mkdir()
    (foreign / "chapter1.tex").write_text("\\\\section{Intro}")
    exe = Path(sys.executable).with_name("robogs")
    run = subprocess.run(
        [str(exe), "synth", str(foreign), "--size", "small", "--force"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 2, run.stderr
    assert "robogs did not write" in run.stderr and "Traceback" not in run.stderr
    assert (foreign / "chapter1.tex").exists()


KILLED_EXPORT = """
import os, signal, sys
import robogs.convert.export.atomic as atomic_mod
atomic_mod.exchange = lambda a, b: False  # the two-rename path (no RENAME_EXCHANGE)
real_rename = os.rename
def dying_rename(src, dst):
    real_rename(src, dst)
    if ".old-" in str(dst):
        os.kill(os.getpid(), signal.SIGKILL)  # killed between the two renames
atomic_mod.os.rename = dying_rename
with atomic_mod.atomic_output(sys.argv[1], folder=False, force=True) as tmp:
    open(tmp, "w").write("new export")
"""


def test_a_kill_between_the_two_renames_is_recovered(tmp_path: Path) -> None:
    out = tmp_path / "scene.usda"
    out.write_text("old export")
    run = subprocess.run([sys.executable, "-c", KILLED_EXPORT, str(out)], timeout=120)
    assert run.returncode == -9
    assert not out.exists()  # the crash window: OUT is missing, the old version is hidden
    assert any(".old-" in p.name for p in tmp_path.iterdir())
    with pytest.raises(DatasetExistsError):  # the next run restores OUT first, then refuses
        with atomic_output(out, folder=False):
            pass
    assert out.read_text() == "old export"
    assert not [p for p in tmp_path.iterdir() if ".old-" in p.name]


def test_a_killed_exports_temp_output_is_cleaned_once_stale(tmp_path: Path) -> None:
    out = tmp_path / "scene.usda"
    young = tmp_path / ".scene.tmp-0123abcd.usda"
    old = tmp_path / ".scene.tmp-4567cdef.usda"
    for p in (young, old):
        p.write_text("half an export")
    os.utime(old, (os.path.getmtime(old) - 7200,) * 2)  # two hours old: a killed run's
    with atomic_output(out, folder=False) as tmp:
        tmp.write_text("export")
    assert out.read_text() == "export"
    assert young.exists() and not old.exists()  # a young one may belong to a running export


def test_an_export_on_a_full_disk_is_an_output_error(ds: Dataset, tmp_path: Path) -> None:
    import errno

    from robogs.format.errors import OutputError

    out = tmp_path / "x.ply"
    with pytest.raises(OutputError, match="the disk is full"):
        with atomic_output(out, folder=False) as tmp:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
    assert list(tmp_path.iterdir()) == [tmp_path / "data"]

"""``robogs export`` / ``robogs view``: atomic writes, --force, clear errors, the exporter registry."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from plugin_dist import write_dist

import robogs.convert.export as export_pkg
from robogs.cli.main import main
from robogs.convert.export import ExportReport, available_exporters, export, register_exporter
from robogs.format import Dataset, DatasetExistsError
from robogs.format.replace import EXPORT_MARKER

try:
    from .test_export_data import build_tiny_dataset
except ImportError:
    from test_export_data import build_tiny_dataset


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return build_tiny_dataset(tmp_path_factory.mktemp("cli") / "tiny")


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


def test_cli_writes_then_refuses_then_forces(
    tiny: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "robot"
    assert main(["export", "urdf", str(tiny.root), str(out)]) == 0
    capsys.readouterr()  # the first export's notes
    first = (out / "tiny_arm.urdf").read_bytes()
    (out / "marker").write_text("kept unless --force")
    assert main(["export", "urdf", str(tiny.root), str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already exists" in err[0] and "--force" in err[0]
    assert (out / "marker").exists()
    assert main(["export", "urdf", str(tiny.root), str(out), "--force", "--no-objects"]) == 0
    assert not (out / "marker").exists() and not (out / "objects").exists()
    assert (out / "tiny_arm.urdf").read_bytes() == first
    assert _leftovers(tmp_path) == []


def test_every_format_through_the_cli(tiny: Dataset, tmp_path: Path) -> None:
    for fmt, name in (("usd", "s.usdc"), ("mcap", "s.mcap"), ("ply", "s.ply"), ("rerun", "s.rrd")):
        assert main(["export", fmt, str(tiny.root), str(tmp_path / name)]) == 0, fmt
        assert (tmp_path / name).stat().st_size > 0
    assert (
        main(
            [
                "view",
                str(tiny.root),
                "--out",
                str(tmp_path / "v.rrd"),
                "--no-spawn",
                "--max-hz",
                "10",
            ]
        )
        == 0
    )
    assert (tmp_path / "v.rrd").stat().st_size > 0
    assert _leftovers(tmp_path) == []


def test_option_that_does_not_apply_is_a_usage_error(
    tiny: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["export", "urdf", str(tiny.root), str(tmp_path / "o"), "--t-ns", "5"]) == 2
    assert "--t-ns does not apply to the urdf export" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_no_robot_is_one_clear_line(
    tiny: Dataset, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    shutil.copytree(tiny.root, tmp_path / "copy")
    with Dataset.open(tmp_path / "copy").edit() as w:
        w.manifest.pop("robot")
        bare = w.commit()
    for fmt, out in (("urdf", "u"), ("usd", "u.usda")):
        assert main(["export", fmt, str(bare.root), str(tmp_path / out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "no robot" in err[0] and "robot.urdf" in err[0], err
        assert not (tmp_path / out).exists()
    assert _leftovers(tmp_path) == []


def test_failing_exporter_leaves_nothing_behind(tiny: Dataset, tmp_path: Path) -> None:
    def broken(ds: Dataset, out: Path) -> ExportReport:
        (out / "half.txt").write_text("partial")
        raise RuntimeError("disk full")

    register_exporter("test_broken", broken, output="folder", replace=True)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "old.txt").write_text("previous export")
    (tmp_path / "out" / EXPORT_MARKER).write_text("{}")  # written by robogs: --force may replace
    with pytest.raises(RuntimeError):
        export("test_broken", tiny, tmp_path / "out", force=True)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [EXPORT_MARKER, "old.txt"]
    assert _leftovers(tmp_path) == []
    with pytest.raises(DatasetExistsError):
        export("test_broken", tiny, tmp_path / "out")


def test_entry_point_exporters_are_listed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_dist(
        tmp_path,
        "robogs-labexport",
        "labexport",
        "from robogs.convert.export.splat_ply import export_ply\n",
        "[robogs.exporters]\ntest_plugin_ply = labexport:export_ply\n",
    )
    with monkeypatch.context() as mp, export_pkg.REGISTRY.sandbox():
        mp.syspath_prepend(str(tmp_path))
        names = available_exporters()
        assert {"urdf", "usd", "mcap", "ply", "rerun", "test_plugin_ply"} <= set(names)
        assert names["test_plugin_ply"].fn is names["ply"].fn
        sources = {e.name: e.source for e in export_pkg.exporter_entries()}
        assert (sources["test_plugin_ply"], sources["ply"]) == ("robogs-labexport", "builtin")
    assert "test_plugin_ply" not in available_exporters()

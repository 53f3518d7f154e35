"""``robogs convert 'SRC_GLOB' OUT [--ray]``: many bags into one dataset, one episode per bag;
a corrupt bag is named and the others land; the merged dataset validates clean."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robogs.cli.main import main
from robogs.format.validate import validate
from robogs.synth.bulk import planar_urdf, write_bulk_bags


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    root = tmp_path_factory.mktemp("bags")
    write_bulk_bags(root / "bags", n_bags=8, duration_s=0.3, corrupt=(5,))
    (root / "planar.urdf").write_text(planar_urdf(), encoding="utf-8")
    return root


def _convert(bags, out, *extra) -> int:
    glob = str(bags / "bags" / "*.mcap")
    return main(["convert", glob, str(out), "--urdf", str(bags / "planar.urdf"), "--no-progress", *extra])  # fmt: skip


def _check_merged(out) -> dict:
    m = json.loads((out / "manifest.json").read_text())
    ids = [e["id"] for e in m["episodes"]]
    assert ids == [f"ep{k:04d}" for k in range(8) if k != 5]
    assert [f["source"].endswith("bag_0005.mcap") for f in m["provenance"]["failed"]] == [True]
    assert sorted(m["provenance"]["bags"]) == ids
    assert not out.with_name(out.name + ".partial").exists()
    assert not list(out.rglob("*.tmp"))
    report = validate(out)
    assert report.findings == [], [f.message for f in report.findings]
    assert {"I004", "T002", "S007"} <= {r.code for r in report.runs if r.status == "ran"}
    return m


def test_glob_converts_every_bag_but_the_corrupt_one(bags, tmp_path, capsys):
    out = tmp_path / "many"
    assert _convert(bags, out) == 1  # some bag failed
    assert "bag_0005.mcap" in capsys.readouterr().err
    _check_merged(out)
    assert _convert(bags, out) == 2  # exists, no --force
    assert "--force" in capsys.readouterr().err


@pytest.mark.slow
def test_ray_glob_equals_the_local_merge(ray_cluster, bags, tmp_path, capsys):
    local, ray = tmp_path / "local", tmp_path / "ray"
    assert _convert(bags, local) == 1
    assert _convert(bags, ray, "--ray") == 1
    assert "2 worker processes" in capsys.readouterr().out
    a, b = _check_merged(local), _check_merged(ray)
    assert a["files"] == b["files"] and a["episodes"] == b["episodes"]


def test_many_bags_into_the_sharded_layout(bags, tmp_path):
    from robogs.convert.distributed import convert_many
    from robogs.convert.ingest.context import ConvertOptions
    from robogs.format.dataset import Dataset

    out = tmp_path / "sharded"
    srcs = sorted((bags / "bags").glob("*.mcap"))
    opts = ConvertOptions(urdf=bags / "planar.urdf", progress=False)
    res = convert_many(srcs, out, opts, chunk_size=3)
    assert [Path(f["source"]).name for f in res.failed] == ["bag_0005.mcap"]
    m = json.loads((out / "manifest.json").read_text())
    assert [c["episodes"] for c in m["shards"]["chunks"]] == [3, 3, 1]
    assert m["episodes"] == [] and not any(r.startswith("episodes/ep") for r in m["files"])
    ds = Dataset.open(out)
    ids = [f"ep{k:04d}" for k in range(8) if k != 5]
    assert [e.id for e in ds.episodes] == ids
    # the 4th converted episode (ep0003) is the first of chunk 1
    assert ds.episode("ep0003").table_path("joint_states").parent.parent.name == "chunk-001"
    report = validate(out)
    assert report.findings == [], [f.message for f in report.findings]
    assert {"I004", "I011", "T002"} <= {r.code for r in report.runs if r.status == "ran"}


@pytest.fixture(scope="module")
def paused(tmp_path_factory):
    """4 bags of 0.3 s at 200 Hz with a 0.5 s pause after sample 30; bag 2 cut short."""
    root = tmp_path_factory.mktemp("paused")
    write_bulk_bags(root / "bags", n_bags=4, duration_s=0.3, corrupt=(2,), pause_s=0.5)
    (root / "planar.urdf").write_text(planar_urdf(), encoding="utf-8")
    return root


def _pieces(root: Path) -> list[tuple]:
    """(id, start_ns, end_ns, joint_states rows) of every episode of a dataset."""
    from robogs.format.dataset import Dataset

    ds = Dataset.open(root)
    return [(e.id, e.start_ns, e.end_ns, e.table("joint_states").num_rows) for e in ds.episodes]


def test_glob_with_split_at_gaps_cuts_each_bag_in_its_task(paused, tmp_path, capsys):
    out = tmp_path / "split"
    assert _convert(paused, out, "--split-at-gaps") == 1  # bag 2 failed, the rest landed
    text = capsys.readouterr()
    assert "bag_0002.mcap" in text.err
    assert "3 of 4 bags, 6 episodes" in text.out
    assert text.out.count("(derived): ") == 3
    got = _pieces(out)
    # oracle 1: each bag converted alone with --split-at-gaps and the same episode id
    alone = []
    for k in (0, 1, 3):
        one = tmp_path / f"alone{k}"
        bag = str(paused / "bags" / f"bag_{k:04d}.mcap")
        args = ["convert", bag, str(one), "--urdf", str(paused / "planar.urdf")]
        assert main([*args, "--episode", f"ep{k:04d}", "--split-at-gaps", "--no-progress"]) == 0
        alone += _pieces(one)
    assert got == alone
    # oracle 2: the generator's grid: 60 samples at 5 ms, the pause before sample 30
    assert [g[0] for g in got] == [f"ep{k:04d}_{j:03d}" for k in (0, 1, 3) for j in (0, 1)]
    assert [g[3] for g in got] == [30] * 6
    for a, b in zip(got[::2], got[1::2], strict=True):
        assert b[1] - a[2] == 5_000_000 + 500_000_000  # one period plus the pause, ns
    report = validate(out)
    assert report.findings == [], [f.message for f in report.findings]


@pytest.mark.slow
def test_ray_glob_with_split_at_gaps_equals_local(ray_cluster, paused, tmp_path, capsys):
    local, ray = tmp_path / "local", tmp_path / "ray"
    assert _convert(paused, local, "--split-at-gaps") == 1
    assert _convert(paused, ray, "--split-at-gaps", "--ray") == 1
    a = json.loads((local / "manifest.json").read_text())
    b = json.loads((ray / "manifest.json").read_text())
    assert a["files"] == b["files"] and a["episodes"] == b["episodes"]
    assert len(a["episodes"]) == 6

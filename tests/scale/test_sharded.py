"""The sharded (chunked) layout of spec 1.1.0: reading, validating, migrating, writing.

Oracles: the flat dataset written from the same seed (the sharded one must give the same
findings once the chunk folder is taken out of each path), the closed-form row counts of the
bulk generator, hashes recorded before a migration, and mutated indexes that must be caught.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import pytest

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.format.distributed import Stats, validate_distributed
from robogs.format.errors import FormatError
from robogs.format.validate import validate
from robogs.synth.bulk import write_bulk_dataset

from ._data import EXPECTED_CODES, mutated_bulk, to_flat_path


def _facts(report, *, flat: bool = False) -> tuple:
    fix = to_flat_path if flat else (lambda s: s)
    return (
        [fix(json.dumps(f.to_dict(), sort_keys=True)) for f in report.findings],
        dict(report.dropped),
        [(r.code, r.status, r.findings) for r in report.runs if r.code != "I011"],
    )


@pytest.fixture(scope="module")
def pair(tmp_path_factory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("sharded")
    flat = mutated_bulk(base / "flat", 40, duration_s=0.3)
    sharded = mutated_bulk(base / "sharded", 40, duration_s=0.3, chunk_size=16)
    return flat, sharded


def test_open_reads_only_the_manifest_and_finds_episodes_lazily(tmp_path):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=30, duration_s=0.1, chunk_size=8)
    m = json.loads((root / "manifest.json").read_text())
    assert [c["episodes"] for c in m["shards"]["chunks"]] == [8, 8, 8, 6]
    assert sorted(m["files"]) == [f"episodes/chunk-{k:03d}/index.json" for k in range(4)] + [
        "robot/robot.urdf"
    ]
    assert [c["rows"] for c in m["shards"]["chunks"]] == [8 * 2 * 50, 8 * 2 * 50, 800, 6 * 2 * 50]
    (root / "episodes/chunk-003/index.json").write_text("{broken")  # never read below
    ds = Dataset.open(root)
    assert ds.sharded and ds.num_episodes == 30
    ep = ds.episode("ep010")  # chunk 1: chunks 0 and 1 read, chunk 3 not
    assert (
        ep.table_path("joint_states")
        == root.resolve() / "episodes/chunk-001/ep010/joint_states.parquet"
    )
    assert ep.table("joint_states").num_rows == 50
    with pytest.raises(FormatError, match="chunk index is not valid JSON"):
        ds.episodes  # noqa: B018 - merging every chunk reads the broken one


def test_sharded_findings_equal_flat_findings(pair):
    flat, sharded = pair
    one_flat, one_sharded = validate(flat), validate(sharded)
    assert EXPECTED_CODES <= one_flat.codes()
    assert "I011" not in one_sharded.codes()
    assert _facts(one_sharded, flat=True) == _facts(one_flat, flat=True)


def test_split_run_equals_single_run_on_sharded(pair):
    _flat, sharded = pair
    stats = Stats()
    split = validate_distributed(sharded, episodes_per_task=6, files_per_task=17, stats=stats)
    assert stats.reason is None and stats.units > 2
    # chunks of 16, 16, 8 episodes in tasks of 6: 3 + 3 + 2 episode units read their index;
    # 32 + 32 + 16 files in tasks of 17: 2 + 2 + 1; the 3 indexes and the URDF travel as rows
    assert stats.chunk_units == 8 + 5 and stats.units == 8 + 5 + 3
    single = validate(sharded)
    assert [f.to_dict() for f in split.findings] == [f.to_dict() for f in single.findings]
    assert dict(split.dropped) == dict(single.dropped)


def test_each_chunk_task_reads_only_its_own_index(tmp_path):
    """Units of chunk 1 give the same outcomes with the other chunks' indexes gone; the plan's
    chunk units carry no rows."""
    from robogs.format import distributed as d
    from robogs.format.checks.context import CheckContext
    from robogs.format.checks.registry import available_checks

    root = mutated_bulk(tmp_path / "ds", 40, duration_s=0.3, chunk_size=16)
    ctx = CheckContext(root)
    plan = d.plan_units(ctx, list(available_checks().values()), episodes_per_task=5)
    ours = [u for u in plan.units if u.chunk == "episodes/chunk-001/index.json"]
    assert [(u.kind, u.lo, u.hi) for u in ours] == [
        *[("episodes", lo, min(lo + 5, 16)) for lo in range(0, 16, 5)],
        ("files", 0, 32),
    ]
    assert all(u.episodes == () and u.files == () for u in plan.units if u.chunk)
    base = {k: v for k, v in ctx.manifest.items() if k not in ("episodes", "files", "shards")}
    settings = {"quick": False, "budgets": {}, "options": {}, "max_per_code": 50}

    def outcomes() -> list:
        d._INDEX_CACHE.clear()
        return [
            {
                c: (o.findings, o.end, dict(o.over))
                for c, o in d.run_unit(str(root), base, u, settings).outcomes.items()
            }  # fmt: skip
            for u in ours
        ]

    before = outcomes()
    # chunk 1 holds the mutated ep019 (row count off by one, I005) and ep023 (missing, I001)
    codes = {f.code for per in before for (fs, _e, _o) in per.values() for f in fs}
    assert {"I005", "I001"} <= codes
    for k in (0, 2):
        (root / f"episodes/chunk-{k:03d}/index.json").rename(root / f"gone-{k}.json")
    assert outcomes() == before


def test_manifest_rows_between_chunk_rows_keep_the_order(tmp_path):
    """An episode and files the manifest lists itself, sorting before, inside and after chunk
    1's files: the chunk's run is cut around them, and the split equals the single run."""
    import hashlib

    from robogs.format.checks.context import CheckContext
    from robogs.format.checks.registry import available_checks
    from robogs.format.distributed import plan_units

    root = mutated_bulk(tmp_path / "ds", 40, duration_s=0.3, chunk_size=16)
    m = json.loads((root / "manifest.json").read_text())
    for rel in ("episodes/chunk-001/aaa.txt", "episodes/chunk-001/ep020/zz.txt", "zzz.txt"):
        (root / rel).write_text(rel)
        digest = hashlib.sha256(rel.encode()).hexdigest()
        m["files"][rel] = {"sha256": digest if rel != "zzz.txt" else "0" * 64, "size": len(rel)}
    start = 1_700_000_000_000_000_000
    m["episodes"] = [{"id": "top", "start_ns": start, "end_ns": start + 10, "streams": {}}]
    (root / "manifest.json").write_text(json.dumps(m))
    single = validate(root)
    assert "I004" in single.codes() and "I011" not in single.codes()
    stats = Stats()
    split = validate_distributed(root, episodes_per_task=5, files_per_task=9, stats=stats)
    assert [f.to_dict() for f in split.findings] == [f.to_dict() for f in single.findings]
    assert [(r.code, r.status, r.findings) for r in split.runs] == [
        (r.code, r.status, r.findings) for r in single.runs
    ]
    assert stats.chunk_units > 0 and stats.reason is None
    plan = plan_units(CheckContext(root), list(available_checks().values()), files_per_task=9)
    ours = [(u.lo, u.hi) for u in plan.units if u.chunk == "episodes/chunk-001/index.json"]
    # files 0-9 are ep016..ep020's tables, then ep020/zz.txt (a manifest row), then 10-31
    assert ours[-5:] == [(0, 9), (9, 10), (10, 19), (19, 28), (28, 32)]


def test_inconsistent_index_falls_back_to_rows_with_identical_findings(tmp_path):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=16, duration_s=0.1, chunk_size=8)
    m = json.loads((root / "manifest.json").read_text())
    m["shards"]["chunks"][1]["episodes"] = 7  # the index holds 8: I011, merged view still 16
    (root / "manifest.json").write_text(json.dumps(m))
    stats = Stats()
    split = validate_distributed(root, episodes_per_task=3, files_per_task=5, stats=stats)
    assert stats.reason is None and stats.units > 2 and stats.chunk_units == 0
    single = validate(root)
    assert "I011" in single.codes()
    assert [f.to_dict() for f in split.findings] == [f.to_dict() for f in single.findings]


@pytest.mark.parametrize(
    ("mutate", "expect"),
    [
        (lambda d: d["episodes"].pop(), "index holds 7 episodes, the manifest says 8"),
        (
            lambda d: d["files"].update({"robot/x.bin": {"sha256": "0" * 64, "size": 1}}),
            "lies outside the chunk folder",
        ),
        (lambda d: d.update(format="other"), "not a chunk index"),
    ],
)
def test_inconsistent_index_is_i011(tmp_path, mutate, expect):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=16, duration_s=0.1, chunk_size=8)
    idx = root / "episodes/chunk-001/index.json"
    doc = json.loads(idx.read_text())
    mutate(doc)
    idx.write_text(json.dumps(doc))
    report = validate(root, quick=True)
    i011 = [f.message for f in report.findings if f.code == "I011"]
    assert any(expect in m for m in i011), i011
    assert "I004" in report.codes() or "I003" in report.codes()  # the index hash is listed


def test_unlisted_index_is_i011(tmp_path):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=10, duration_s=0.1, chunk_size=5)
    m = json.loads((root / "manifest.json").read_text())
    del m["files"]["episodes/chunk-000/index.json"]
    (root / "manifest.json").write_text(json.dumps(m))
    msgs = [f.message for f in validate(root, quick=True).findings if f.code == "I011"]
    assert msgs == ["chunk index is not listed in the manifest's files (its hash is not checked)"]


def test_migrate_flat_to_sharded_and_back(tmp_path, capsys):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=23, duration_s=0.1, seed=5)
    before = json.loads((root / "manifest.json").read_text())
    assert main(["migrate", str(root), "--chunk-size", "10", "--quiet"]) == 0
    assert "3 chunk(s)" in capsys.readouterr().out
    ds = Dataset.open(root)
    assert ds.spec_version == "1.1.0" and ds.num_episodes == 23
    assert sorted(p.name for p in (root / "episodes").iterdir()) == [
        "chunk-000",
        "chunk-001",
        "chunk-002",
    ]
    after = ds.files
    for rel, e in before["files"].items():  # every file, moved or not, with its old hash
        assert after[to_new(rel, 10)]["sha256"] == e["sha256"], rel
    assert [e.id for e in ds.episodes] == [e["id"] for e in before["episodes"]]
    assert validate(root).findings == []
    assert not list(tmp_path.glob(".ds.*"))  # no temp folder or lock left
    assert main(["migrate", str(root), "--to", "flat", "--quiet"]) == 0
    flat = json.loads((root / "manifest.json").read_text())
    assert "shards" not in flat and len(flat["episodes"]) == 23
    assert not list(root.rglob("index.json"))
    assert validate(root).findings == []


def to_new(rel: str, k: int) -> str:
    if not rel.startswith("episodes/ep"):
        return rel
    ep = rel.split("/")[1]
    return f"episodes/chunk-{int(ep[2:]) // k:03d}/{rel[len('episodes/') :]}"


def test_migrate_refuses_a_damaged_dataset_and_changes_nothing(tmp_path, capsys):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=5, duration_s=0.1)
    p = root / "episodes/ep003/ee_poses.parquet"
    p.write_bytes(p.read_bytes()[:-5] + b"xxxxx")
    snapshot = sorted(q.relative_to(root).as_posix() for q in root.rglob("*"))
    manifest = (root / "manifest.json").read_bytes()
    assert main(["migrate", str(root)]) == 2
    err = capsys.readouterr().err
    assert "do not match their sha256" in err and "Traceback" not in err
    assert sorted(q.relative_to(root).as_posix() for q in root.rglob("*")) == snapshot
    assert (root / "manifest.json").read_bytes() == manifest


def test_writer_keeps_the_sharded_layout_on_edit(tmp_path):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=12, duration_s=0.1, chunk_size=5)
    ds = Dataset.open(root)
    with ds.edit() as w:
        w.write_text("episodes/chunk-002/ep011/note.txt", "hello\n")
        w.manifest["budgets"] = {}
        new = w.commit()
    assert new.sharded and new.num_episodes == 12
    idx = json.loads((root / "episodes/chunk-002/index.json").read_text())
    assert "episodes/chunk-002/ep011/note.txt" in idx["files"]
    assert "episodes/chunk-002/ep011/note.txt" not in new.manifest["files"]
    assert validate(root).findings == []


def test_synth_episodes_shards_large_n(tmp_path, capsys):
    out = tmp_path / "many"
    args = ["synth", str(out), "--episodes", "120", "--episode-seconds", "0.02", "--quiet"]
    assert main([*args, "--chunk-size", "50"]) == 0
    m = json.loads((out / "manifest.json").read_text())
    assert m["shards"]["episodes"] == 120 and [c["episodes"] for c in m["shards"]["chunks"]] == [
        50,
        50,
        20,
    ]
    assert main([*args, "--force"]) == 0  # default: 120 > 100 episodes, chunks of 1000
    assert len(json.loads((out / "manifest.json").read_text())["shards"]["chunks"]) == 1
    t = time.perf_counter()
    report = validate(out, quick=True)
    assert report.findings == [] and time.perf_counter() - t < 60
    shutil.rmtree(out)


def test_reader_schema_checks_chunk_episodes(tmp_path):
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=10, duration_s=0.1, chunk_size=5)
    idx = root / "episodes/chunk-001/index.json"
    doc = json.loads(idx.read_text())
    del doc["episodes"][2]["start_ns"]  # ep007
    idx.write_text(json.dumps(doc))
    ds = Dataset.open(root)  # the manifest alone is fine
    assert ds.episode("ep001").id == "ep001"
    with pytest.raises(FormatError, match="start_ns") as err:
        ds.episode("ep007")
    assert "chunk-001/index.json" in str(err.value)
    with pytest.raises(FormatError, match="start_ns"):
        ds.episodes  # noqa: B018
    s001 = [f for f in validate(root, quick=True).findings if f.code == "S001"]
    assert any("start_ns" in f.message for f in s001), [f.message for f in s001]

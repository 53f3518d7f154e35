"""Malformed input yields findings, never a crashed check (X001) or an exception."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from .scope import validate


def _edit_manifest(root: Path, fn: Callable[[dict], None]) -> None:
    m = json.loads((root / "manifest.json").read_text())
    fn(m)
    (root / "manifest.json").write_text(json.dumps(m))


def _ep(m: dict) -> dict:
    return m["episodes"][0]


MANIFEST_EDITS: dict[str, Callable[[dict], None]] = {
    "no_episodes": lambda m: m.pop("episodes"),
    "episodes_not_a_list": lambda m: m.__setitem__("episodes", {"a": 1}),
    "episode_not_a_dict": lambda m: m["episodes"].append(7),
    "stream_not_a_dict": lambda m: _ep(m)["streams"].__setitem__("joint_states", "x"),
    "stream_path_not_a_string": lambda m: _ep(m)["streams"]["joint_states"].__setitem__("path", 3),
    "start_ns_string": lambda m: _ep(m).__setitem__("start_ns", "soon"),
    "files_not_a_dict": lambda m: m.__setitem__("files", []),
    "file_entry_not_a_dict": lambda m: m["files"].__setitem__(next(iter(m["files"])), "x"),
    "file_size_string": lambda m: m["files"][next(iter(m["files"]))].__setitem__("size", "big"),
    "robot_not_a_dict": lambda m: m.__setitem__("robot", "ur5"),
    "assets_not_a_dict": lambda m: m.__setitem__("assets", ["box"]),
    "cameras_value_not_a_string": lambda m: m.__setitem__("cameras", {"cam0": 5}),
    "budgets_wrong": lambda m: m.__setitem__("budgets", {"time.sync_ms": "fast"}),
    "unknown_kind": lambda m: _ep(m)["streams"]["joint_states"].__setitem__("kind", "telepathy"),
    "format_wrong": lambda m: m.__setitem__("format", "lerobot"),
    "spec_version_garbage": lambda m: m.__setitem__("spec_version", "one"),
    "empty_manifest": lambda m: m.clear(),
}


@pytest.mark.parametrize("name", sorted(MANIFEST_EDITS))
def test_malformed_manifest_gives_findings_not_crashes(tiny_copy: Path, name: str) -> None:
    _edit_manifest(tiny_copy, MANIFEST_EDITS[name])
    report = validate(tiny_copy)
    assert not report.codes() & {"X001"}, [f.to_dict() for f in report.findings]
    assert report.codes(min_severity="error"), name


def _rewrite(root: Path, rel: str, table: pa.Table) -> None:
    pq.write_table(table, root / rel)


TABLE_EDITS: dict[str, tuple[str, Callable[[pa.Table], pa.Table]]] = {
    "t_ns_as_string": (
        "joint_states",
        lambda t: t.set_column(0, "t_ns", pa.array([str(v) for v in t.column(0).to_pylist()])),
    ),
    "t_ns_missing": ("ee_poses", lambda t: t.drop_columns(["t_ns"])),
    "empty_table": ("object_poses", lambda t: t.slice(0, 0)),
    "nan_positions": (
        "joint_states",
        lambda t: t.set_column(1, t.schema.field(1), pa.array(np.full(t.num_rows, np.nan))),
    ),
    "nulls_in_link": (
        "ee_poses",
        lambda t: t.set_column(1, "link", pa.array([None] * t.num_rows, pa.string())),
    ),
    "one_row": ("joint_states", lambda t: t.slice(0, 1)),
    "boxes_unknown_camera": (
        "boxes2d",
        lambda t: t.set_column(1, "camera", pa.array(["camX"] * t.num_rows)),
    ),
}


@pytest.mark.parametrize("name", sorted(TABLE_EDITS))
def test_malformed_tables_give_findings_not_crashes(tiny_copy: Path, name: str) -> None:
    stream, edit = TABLE_EDITS[name]
    m = json.loads((tiny_copy / "manifest.json").read_text())
    rel = m["episodes"][0]["streams"][stream]["path"]
    _rewrite(tiny_copy, rel, edit(pq.read_table(tiny_copy / rel)))
    report = validate(tiny_copy)
    assert "X001" not in report.codes(), [f.to_dict() for f in report.findings]
    assert report.codes(min_severity="error")


def test_garbage_files_give_findings_not_crashes(tiny_copy: Path) -> None:
    for rel in (
        "robot/meshes/link1.stl",
        "assets/box/mesh.ply",
        "cameras/cam0.json",
        "episodes/ep000/cameras/cam0/rgb.mp4",
        "episodes/ep000/cameras/cam0/labels.parquet",
    ):
        (tiny_copy / rel).write_bytes(b"\x00garbage\xff" * 10)
    report = validate(tiny_copy)
    assert "X001" not in report.codes(), [f.to_dict() for f in report.findings]
    assert {"I003", "S002", "G001", "G006", "I006"} <= report.codes()


def test_corrupt_label_image_is_reported_once(tiny_copy: Path) -> None:
    rel = "episodes/ep000/cameras/cam0/labels.parquet"
    t = pq.read_table(tiny_copy / rel)
    blobs = t.column("png").to_pylist()
    blobs[3] = b"not a png"
    pq.write_table(t.set_column(1, "png", pa.array(blobs, pa.binary())), tiny_copy / rel)
    _edit_manifest(
        tiny_copy,
        lambda m: m["files"][rel].update(
            sha256=hashlib.sha256((tiny_copy / rel).read_bytes()).hexdigest(),
            size=(tiny_copy / rel).stat().st_size,
        ),
    )
    report = validate(tiny_copy)
    assert "X001" not in report.codes()
    x002 = [f for f in report.findings if f.code == "X002"]
    assert len(x002) == 1 and "frame_index 3" in (x002[0].location.where or "")

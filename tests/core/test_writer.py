"""Round trips and atomicity of the dataset writer."""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from robogs.format import Dataset, DatasetExistsError, FormatError, LockError
from robogs.format.cameras import CameraModel
from robogs.format.images import decode_label_png, encode_label_png
from robogs.format.writer import sha256_file


def _joint_table(n: int = 50, seed: int = 0) -> pa.Table:
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.integers(1_900_000, 2_100_000, n)).astype(np.int64)
    return pa.table(
        {
            "t_ns": t,
            "position.j1": rng.normal(size=n),
            "position.j2": rng.normal(size=n),
            "velocity.j1": rng.normal(size=n),
            "velocity.j2": rng.normal(size=n),
        }
    )


def _make(path: Path, table: pa.Table) -> Dataset:
    with Dataset.create(path) as w:
        w.write_table("episodes/ep0/joint_states.parquet", table, kind="joint_states")
        labels = pa.table(
            {
                "frame_index": pa.array([0, 1], pa.int64()),
                "png": pa.array(
                    [
                        encode_label_png(np.full((4, 5), 7, np.uint16)),
                        encode_label_png(np.arange(20, dtype=np.uint16).reshape(4, 5) * 3000),
                    ],
                    pa.binary(),
                ),
            }
        )
        w.write_table("episodes/ep0/cameras/cam0/labels.parquet", labels, kind="camera_labels")
        w.set_camera(CameraModel("cam0", 5, 4, 10.0, 10.0, 2.5, 2.0, T_world_cam=np.eye(4)))
        w.set_physics({"objects": {"box": {"equation": "rigid", "mass_kg": 0.5}}})
        t = table.column("t_ns").to_numpy()
        w.add_episode(
            "ep0",
            start_ns=int(t[0]),
            end_ns=int(t[-1]),
            streams={
                "joint_states": {
                    "kind": "joint_states",
                    "path": "episodes/ep0/joint_states.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                    "nominal_rate_hz": 500.0,
                },
                "camera/cam0": {
                    "kind": "camera",
                    "camera": "cam0",
                    "labels": "episodes/ep0/cameras/cam0/labels.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                },
            },
        )
        return w.commit()


def test_round_trip_is_lossless(tmp_path: Path) -> None:
    table = _joint_table()
    ds = _make(tmp_path / "ds", table)
    back = Dataset.open(tmp_path / "ds").episode("ep0").table("joint_states")
    assert back.equals(table)
    assert back.schema.field("t_ns").type == pa.int64()
    labels = list(ds.episode().iter_labels("cam0"))
    assert labels[1][1].dtype == np.uint16 and int(labels[1][1].max()) == 19 * 3000
    assert ds.camera("cam0").K[0, 2] == 2.5


def test_manifest_lists_every_file_with_hash_size_rows(tmp_path: Path) -> None:
    ds = _make(tmp_path / "ds", _joint_table(n=37))
    on_disk = {p.relative_to(ds.root).as_posix() for p in ds.root.rglob("*") if p.is_file()}
    assert set(ds.files) == on_disk - {"manifest.json"}
    for rel, entry in ds.files.items():
        p = ds.root / rel
        assert entry["sha256"] == hashlib.sha256(p.read_bytes()).hexdigest()
        assert entry["size"] == p.stat().st_size
    assert ds.files["episodes/ep0/joint_states.parquet"]["rows"] == 37


def test_existing_output_is_not_clobbered(tmp_path: Path) -> None:
    _make(tmp_path / "ds", _joint_table())
    with pytest.raises(DatasetExistsError, match="--force"):
        Dataset.create(tmp_path / "ds")


def test_failed_write_leaves_previous_version_intact(tmp_path: Path) -> None:
    ds = _make(tmp_path / "ds", _joint_table())
    before = {p: sha256_file(p) for p in ds.root.rglob("*") if p.is_file()}
    with pytest.raises(RuntimeError), ds.edit() as w:
        w.write_table(
            "episodes/ep0/joint_states.parquet", _joint_table(seed=1), kind="joint_states"
        )
        raise RuntimeError("simulated crash")
    after = {p: sha256_file(p) for p in ds.root.rglob("*") if p.is_file()}
    assert before == after
    assert not list(tmp_path.glob(".ds.tmp-*"))


def test_edit_never_modifies_original_files_in_place(tmp_path: Path) -> None:
    ds = _make(tmp_path / "ds", _joint_table())
    src = ds.root / "episodes/ep0/joint_states.parquet"
    held = os.open(src, os.O_RDONLY)  # the old inode stays readable
    old_hash = sha256_file(src)
    with ds.edit() as w:
        w.write_table(
            "episodes/ep0/joint_states.parquet", _joint_table(seed=2), kind="joint_states"
        )
        new = w.commit()
    data = b""
    while chunk := os.read(held, 1 << 16):
        data += chunk
    os.close(held)
    assert hashlib.sha256(data).hexdigest() == old_hash
    assert new.files["episodes/ep0/joint_states.parquet"]["sha256"] != old_hash


def _hold_lock(path: str, started, release) -> None:
    w = Dataset.create(path)
    started.set()
    release.wait(10)
    w.abort()


def test_second_writer_is_refused(tmp_path: Path) -> None:
    ctx = mp.get_context("fork")
    started, release = ctx.Event(), ctx.Event()
    proc = ctx.Process(target=_hold_lock, args=(str(tmp_path / "ds"), started, release))
    proc.start()
    try:
        assert started.wait(10)
        with pytest.raises(LockError, match="another robogs process"):
            Dataset.create(tmp_path / "ds")
    finally:
        release.set()
        proc.join(10)


def test_interrupted_swap_is_recovered(tmp_path: Path) -> None:
    ds = _make(tmp_path / "ds", _joint_table())
    expect = json.loads((ds.root / "manifest.json").read_text())
    os.rename(ds.root, tmp_path / ".ds.old-deadbeef")  # crash between the two renames
    with Dataset.create(tmp_path / "other"):
        pass
    w = Dataset.create(tmp_path / "ds", overwrite=True)  # recovery runs on lock acquisition
    w.abort()
    assert json.loads((tmp_path / "ds" / "manifest.json").read_text()) == expect


def test_writer_refuses_wrong_table_kind(tmp_path: Path) -> None:
    with (
        Dataset.create(tmp_path / "ds") as w,
        pytest.raises(FormatError, match="missing column 't_ns'"),
    ):
        w.write_table("x.parquet", pa.table({"position.a": [1.0]}), kind="joint_states")


def test_physics_revisions_keep_history(tmp_path: Path) -> None:
    ds = _make(tmp_path / "ds", _joint_table())
    for mass in (0.6, 0.7):
        with ds.edit() as w:
            w.set_physics(
                {"objects": {"box": {"equation": "rigid", "mass_kg": mass}}}, note=f"m={mass}"
            )
            ds = w.commit()
    assert ds.physics()["revision"] == 3 and ds.physics()["parent_revision"] == 2
    assert ds.physics_history() == [1, 2]
    assert (
        json.loads((ds.root / "physics/history/rev-0001.json").read_text())["objects"]["box"][
            "mass_kg"
        ]
        == 0.5
    )


def test_label_png_round_trip_exact() -> None:
    rng = np.random.default_rng(3)
    img = rng.integers(0, 65536, (31, 17)).astype(np.uint16)
    assert np.array_equal(decode_label_png(encode_label_png(img)), img)

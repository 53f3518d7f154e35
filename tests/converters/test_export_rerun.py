"""Rerun export: the .rrd is read back by rerun's own reader; entities, rows and values checked."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr
from rerun.chunk import RrdReader

from robogs.convert.export import export
from robogs.format import Dataset
from robogs.format.qa import rerun_log
from robogs.format.qa.rerun_log import downsample_indices

try:
    from .test_export_data import N_FRAMES, N_JS, N_POSE, build_tiny_dataset
except ImportError:
    from test_export_data import N_FRAMES, N_JS, N_POSE, build_tiny_dataset


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return build_tiny_dataset(tmp_path_factory.mktemp("rrd") / "tiny")


@pytest.fixture(scope="module")
def chunks(
    tiny: Dataset, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, list[pa.RecordBatch]]:
    out = tmp_path_factory.mktemp("rrd_out") / "t.rrd"
    export("rerun", tiny, out)
    reader = RrdReader(out)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    by_entity: dict[str, list[pa.RecordBatch]] = {}
    for chunk in reader.stream().collect().stream():
        by_entity.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return by_entity


def _rows(chunks: dict[str, list[pa.RecordBatch]], entity: str, component: str) -> pa.Table:
    batches = [b for b in chunks.get(entity, []) if component in b.schema.names]
    assert batches, f"{entity} has no {component}"
    return pa.Table.from_batches(batches)


def _t(table: pa.Table) -> np.ndarray:
    return table.column("time").cast(pa.int64()).to_numpy()


def test_downsample_matches_brute_force() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.integers(1_000_000, 9_000_000, 500)).astype(np.int64)
    for hz in (10.0, 60.0, 333.0):
        period = round(1e9 / hz)
        keep, last_bin = [], None
        for i, ti in enumerate(t):
            b = (ti - t[0]) // period
            if b != last_bin:
                keep.append(i)
                last_bin = b
        if keep[-1] != len(t) - 1:
            keep.append(len(t) - 1)
        assert downsample_indices(t, hz).tolist() == keep
    assert downsample_indices(t, 0).tolist() == list(range(len(t)))


def test_robot_animated_by_joint_states(tiny: Dataset, chunks: dict) -> None:
    js = tiny.episode().table("joint_states")
    t = js.column("t_ns").to_numpy()
    kept = downsample_indices(t, 60.0)
    urdf = tiny.urdf(load_meshes=False)
    for link in ("base_link", "link1", "link2", "tool"):
        tab = _rows(chunks, f"/world/robot/{link}", "Transform3D:translation")
        assert np.array_equal(_t(tab), t[kept])  # stamps kept exactly, ns
        trans = np.array([row[0] for row in tab.column("Transform3D:translation").to_pylist()])
        for k, i in enumerate(kept[::7]):
            urdf.update_cfg(
                {j: float(js.column(f"position.{j}")[int(i)].as_py()) for j in ("j1", "j2")}
            )
            want = np.asarray(urdf.get_transform(link, "base_link"))[:3, 3]
            np.testing.assert_allclose(trans[7 * k], want, atol=1e-6)
        assert f"/world/robot/{link}/splats" in chunks
    assert "/world/robot/link1/visual" in chunks


def test_streams_rows_and_stamps(tiny: Dataset, chunks: dict) -> None:
    ep = tiny.episode()
    t_js = ep.table("joint_states").column("t_ns").to_numpy()
    for kind in ("position", "velocity", "effort"):
        tab = _rows(chunks, f"/plots/joints/{kind}/j2", "Scalars:scalars")
        assert np.array_equal(_t(tab), t_js) and tab.num_rows == N_JS
    t_frames = ep.frames("cam0").column("t_ns").to_numpy()
    for entity, comp in (
        ("rgb", "EncodedImage:blob"),
        ("segmentation", "SegmentationImage:buffer"),
        ("boxes", "Boxes2D:centers"),
    ):
        tab = _rows(chunks, f"/world/cameras/cam0/image/{entity}", comp)
        assert tab.num_rows == N_FRAMES and np.array_equal(_t(tab), t_frames)
    boxes = _rows(chunks, "/world/cameras/cam0/image/boxes", "Boxes2D:centers")
    assert boxes.column("Boxes2D:class_ids").to_pylist()[0] == [3]
    np.testing.assert_allclose(boxes.column("Boxes2D:centers").to_pylist()[0], [[10.0, 8.0]])
    assert _rows(chunks, "/world/cameras/cam0/image", "Pinhole:image_from_camera").num_rows == 1
    assert _rows(chunks, "/world/boxes3d", "Boxes3D:centers").num_rows == N_POSE
    assert _rows(chunks, "/world/objects/box", "Transform3D:translation").num_rows == N_POSE
    assert _rows(chunks, "/world", "AnnotationContext:context").num_rows == 1
    assert _rows(chunks, "/plots/wrench/tool/fz", "Scalars:scalars").num_rows == N_POSE


def test_findings_logged_at_their_stamps(tiny: Dataset, chunks: dict) -> None:
    from robogs.format.validate import validate

    findings = validate(
        tiny.root, ignore=["binding"]
    ).findings  # the layer leaves out re-render checks
    if not findings:
        assert "/logs/findings" not in chunks
        return
    tab = _rows(chunks, "/logs/findings", "TextLog:text")
    assert tab.num_rows == len(findings)
    stamped = sorted(f.location.t_ns for f in findings if f.location.t_ns is not None)
    got = _t(tab).tolist()
    assert all(s in got for s in stamped)


def test_extra_layer_plugs_in(tiny: Dataset, tmp_path: Path) -> None:
    def marker(ctx: rerun_log.RerunContext) -> None:
        ctx.rec.log("extra/marker", rr.Points3D([[1.0, 2.0, 3.0]]), static=True)

    with rerun_log.REGISTRY.sandbox():  # the layer is undone after the block (no leak to
        rerun_log.register_layer("test_marker", marker)  # other tests in this worker)
        rerun_log.write_rrd(tiny, tmp_path / "m.rrd", layers=["robot", "test_marker"])
    entities = {c.entity_path for c in RrdReader(tmp_path / "m.rrd").stream().collect().stream()}
    assert "/extra/marker" in entities and "/world/robot/link2" in entities
    assert not any(e.startswith("/plots") for e in entities)

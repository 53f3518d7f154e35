"""Bad captures are refused with clear RobogsErrors (mutated copies of the tiny capture)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError, RobogsError
from robogs.format.images import encode_label_png
from robogs.reconstruct.views import load_capture

EP = "static"
CAM = "orbit"
BASE = f"episodes/{EP}/cameras/{CAM}"


def _stream(w) -> dict:
    ep = next(e for e in w.manifest["episodes"] if e["id"] == EP)
    return ep["streams"][f"camera/{CAM}"]


def test_the_clean_capture_loads(capture_copy: Path):
    cap = load_capture(Dataset.open(capture_copy))
    assert len(cap.views) == 8 and cap.joint_positions and "box" in cap.object_poses
    assert all(v.labels is not None and v.rgb.shape == (36, 48, 3) for v in cap.views)


def test_views_without_poses(capture_copy: Path):
    from robogs.format.dataset import read_parquet

    ds = Dataset.open(capture_copy)
    ext = read_parquet(ds.resolve(f"{BASE}/extrinsics.parquet"))
    with ds.edit() as w:
        w.write_table(f"{BASE}/extrinsics.parquet", ext.slice(0, 4), kind="camera_extrinsics")
        w.commit()
    with pytest.raises(InputError, match=r"4 of 8 frames of camera 'orbit' have no pose"):
        load_capture(Dataset.open(capture_copy))


def test_static_camera_without_extrinsics(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    with ds.edit() as w:
        w.set_camera(replace(ds.camera(CAM), extrinsics="static", T_world_cam=None))
        _stream(w).pop("extrinsics")
        w.commit()
    with pytest.raises(InputError, match="has no T_world_cam: the views have no poses"):
        load_capture(Dataset.open(capture_copy))


def test_intrinsics_that_disagree_with_the_images(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    cam = ds.camera(CAM)
    with ds.edit() as w:
        w.set_camera(replace(cam, width=64, height=48, cx=32.0, cy=24.0))
        w.commit()
    with pytest.raises(InputError, match=r"is 48x36 px but its intrinsics are for 64x48"):
        load_capture(Dataset.open(capture_copy))


def test_principal_point_outside_the_image(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    with ds.edit() as w:
        w.set_camera(replace(ds.camera(CAM), cx=480.0))
        w.commit()
    with pytest.raises(InputError, match="principal point"):
        load_capture(Dataset.open(capture_copy))


def test_empty_masks(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    empty = encode_label_png(np.zeros((36, 48), np.uint16))
    table = pa.table(
        {
            "frame_index": pa.array(np.arange(8, dtype=np.int64)),
            "png": pa.array([empty] * 8, pa.binary()),
        }
    )
    with ds.edit() as w:
        w.write_table(f"{BASE}/labels.parquet", table, kind="camera_labels")
        w.commit()
    with pytest.raises(InputError, match="every label image is empty"):
        load_capture(Dataset.open(capture_copy))


def test_one_empty_mask_is_named(capture_copy: Path):
    # an empty mask would carve the whole visual hull in its view: it is refused, not ignored
    ds = Dataset.open(capture_copy)
    from robogs.format.dataset import read_parquet

    tab = read_parquet(ds.resolve(f"{BASE}/labels.parquet"))
    png = tab.column("png").to_pylist()
    png[3] = encode_label_png(np.zeros((36, 48), np.uint16))
    table = pa.table({"frame_index": tab.column("frame_index"), "png": pa.array(png, pa.binary())})
    with ds.edit() as w:
        w.write_table(f"{BASE}/labels.parquet", table, kind="camera_labels")
        w.commit()
    with pytest.raises(InputError, match=r"1 of 8 label images are empty .*: orbit/3") as exc:
        load_capture(Dataset.open(capture_copy))
    assert exc.value.where == "frame_index 3" and "--cameras" in exc.value.hint


def test_no_labels_at_all(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    with ds.edit() as w:
        _stream(w).pop("labels")
        w.remove(f"{BASE}/labels.parquet")
        w.commit()
    with pytest.raises(InputError, match="has panoptic labels"):
        load_capture(Dataset.open(capture_copy))
    assert len(load_capture(Dataset.open(capture_copy), require_labels=False).views) == 8


def test_a_moving_robot_is_not_a_static_capture(capture_copy: Path):
    ds = Dataset.open(capture_copy)
    js = ds.episode().table("joint_states")
    q = js.column("position.joint1").to_numpy() + np.arange(8) * 0.1  # moves between every view
    js = js.set_column(js.column_names.index("position.joint1"), "position.joint1", pa.array(q))
    with ds.edit() as w:
        w.write_table(f"episodes/{EP}/joint_states.parquet", js, kind="joint_states")
        w.commit()
    with pytest.raises(InputError, match=r"only 1 static view"):
        load_capture(Dataset.open(capture_copy))


def test_cli_reports_bad_input_in_one_line(capture_copy: Path, capsys: pytest.CaptureFixture[str]):
    ds = Dataset.open(capture_copy)
    with ds.edit() as w:
        w.set_camera(replace(ds.camera(CAM), cx=480.0))
        w.commit()
    before = (capture_copy / "manifest.json").read_bytes()
    code = main(["reconstruct", str(capture_copy), "--iterations", "2", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "principal point" in err and "Traceback" not in err
    assert (capture_copy / "manifest.json").read_bytes() == before


def test_evaluate_without_splats_is_refused(capture_copy: Path):
    from robogs.reconstruct.evaluate import evaluate

    with pytest.raises(RobogsError, match="no splats"):
        evaluate(capture_copy, heldout_every=4)

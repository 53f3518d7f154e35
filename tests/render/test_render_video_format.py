"""``robogs render --format video`` and ``--normals``.

Oracles: the robogs-dataset output of the same trajectory (labels bit-exact, depth within 1 mm,
boxes, stamps), OpenCV's own frame count of the mp4, the table plane's closed-form normal in
camera axes (``R_world_cam^T · (0, 0, 1)``, the synthetic table top is ``z = 0``), and OUT
folders that must be refused.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.cli.main import main
from robogs.format import Dataset
from robogs.format.images import decode_label_png
from robogs.format.render_trajectory import decode_normals_png, encode_normals_png
from robogs.synth.scene import synthesize

START_NS, SPAN_NS = 2_000_000_000, 200_000_000
TABLE, BOX = 200, 100


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("video") / "s"
    synthesize(out, seed=1, size="small", progress=False)
    return out


@pytest.fixture(scope="module")
def traj(scene: Path) -> Path:
    """0.2 s of the recorded joints with a pan sweep and an elbow ramp never recorded."""
    js = Dataset.open(scene).episode().table("joint_states")
    t = js.column("t_ns").to_numpy()
    rows = np.flatnonzero((t >= START_NS) & (t <= START_NS + SPAN_NS))[::4]
    names = [c for c in js.column_names if c.startswith("position.")]
    q = np.stack([js.column(c).to_numpy()[rows] for c in names], -1)
    s = (t[rows] - START_NS) / SPAN_NS
    q[:, 0] += 0.3 * np.sin(np.pi * s)
    q[:, 2] += 0.15 * s
    path = scene.parent / "traj.csv"
    lines = [",".join(["t_ns", *names])]
    lines += [
        ",".join([str(int(a)), *map(repr, map(float, b))]) for a, b in zip(t[rows], q, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def _render(scene: Path, traj: Path, out: Path, *extra: str) -> int:
    return main(["render", str(scene), str(out), "--joints", str(traj), "--quiet", *extra])


@pytest.fixture(scope="module")
def dataset_out(scene: Path, traj: Path) -> Path:
    out = scene.parent / "ds"
    assert _render(scene, traj, out, "--normals") == 0
    return out


@pytest.fixture(scope="module")
def video_out(scene: Path, traj: Path) -> Path:
    out = scene.parent / "vid"
    assert _render(scene, traj, out, "--format", "video", "--normals") == 0
    return out


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_video_folder_matches_the_dataset_output(dataset_out: Path, video_out: Path) -> None:
    ds = Dataset.open(dataset_out)
    ep = ds.episode()
    assert sorted(p.name for p in video_out.iterdir()) == [
        "boxes.csv",
        "cam0",
        "labels.json",
        "video.json",
    ]
    assert not list(video_out.parent.glob(".vid.render-*"))  # the temp folder is gone
    cam = video_out / "cam0"
    rows = _csv(cam / "frames.csv")
    frames = ep.frames("cam0")
    assert [int(r["t_ns"]) for r in rows] == frames.column("t_ns").to_pylist()
    assert [int(r["frame_index"]) for r in rows] == list(range(len(rows)))
    # the mp4 opens with plain OpenCV and holds one frame per frames.csv row
    cap = cv2.VideoCapture(str(cam / "rgb.mp4"))
    n = 0
    while cap.grab():
        n += 1
    cap.release()
    assert n == len(rows) >= 5
    # labels: the dataset's PNGs, bit-exact; depth within 1 mm
    lab = pq.read_table(ep.labels_path("cam0"))
    dep = ep.table("depth/cam0")
    assert len(list((cam / "labels").iterdir())) == len(rows)
    for k, blob in zip(
        lab.column("frame_index").to_pylist(), lab.column("png").to_pylist(), strict=True
    ):
        img = cv2.imread(str(cam / "labels" / f"{k:06d}.png"), cv2.IMREAD_UNCHANGED)
        assert img.dtype == np.uint16 and np.array_equal(img, decode_label_png(blob))
        assert (cam / "labels" / f"{k:06d}.png").read_bytes() == blob
    for k, blob in zip(
        dep.column("frame_index").to_pylist(), dep.column("png").to_pylist(), strict=True
    ):
        img = cv2.imread(str(cam / "depth" / f"{k:06d}.png"), cv2.IMREAD_UNCHANGED)
        want = decode_label_png(blob).astype(np.int64)
        assert img.dtype == np.uint16 and np.abs(img.astype(np.int64) - want).max() <= 1
        assert img.max() > 500  # millimetres, not metres
    # boxes.csv is the dataset's boxes2d stream
    got = {
        tuple(int(r[c]) for c in ("frame_index", "label_id", "x_min", "y_min", "x_max", "y_max"))
        for r in _csv(video_out / "boxes.csv")
    }
    want_b = {
        tuple(int(r[c]) for c in ("frame_index", "label_id", "x_min", "y_min", "x_max", "y_max"))
        for r in ep.table("boxes2d").to_pylist()
    }
    assert got == want_b and len(got) > len(rows)
    labels = json.loads((video_out / "labels.json").read_text())
    segs = {str(s["label_id"]): s["target"] for s in ep.table("segments").to_pylist()}
    assert {k: v["name"] for k, v in labels.items() if v} == segs
    assert labels[str(BOX)]["name"] == "box" and labels["3"]["kind"] == "robot_link"
    doc = json.loads((video_out / "video.json").read_text())
    assert "millimetres" in doc["depth"] and "0 = no hit" in doc["depth"]
    assert doc["cameras"]["cam0"]["frames"] == len(rows)


def test_normals_of_the_table_plane(dataset_out: Path, video_out: Path) -> None:
    ds = Dataset.open(dataset_out)
    ep = ds.episode()
    R = np.asarray(ds.camera("cam0").T_world_cam)[:3, :3]
    want = R.T @ np.array([0.0, 0.0, 1.0])  # table top z = 0, normal up, in camera axes
    assert want[2] < 0  # faces the camera
    nt = ep.table("normals/cam0")
    labels = dict(ep.iter_labels("cam0"))
    assert nt.num_rows == len(labels)
    for k, blob in zip(
        nt.column("frame_index").to_pylist(), nt.column("png").to_pylist(), strict=True
    ):
        assert (video_out / "cam0" / "normals" / f"{k:06d}.png").read_bytes() == blob
        n = decode_normals_png(blob)
        table = labels[k] == TABLE
        assert table.sum() > 1000
        ang = np.degrees(np.arccos(np.clip(n[table] @ want, -1.0, 1.0)))
        assert np.median(ang) < 3.0 and np.mean(ang < 3.0) > 0.9, np.percentile(ang, [50, 90])
        assert np.all(n[labels[k] == 0] == 0)  # nothing drawn: no normal
    # the box's top face is parallel to the table, its side faces are not
    box = labels[0] == BOX
    a = np.degrees(
        np.arccos(np.clip(decode_normals_png(nt.column("png")[0].as_py())[box] @ want, -1, 1))
    )
    assert np.mean(a < 3.0) > 0.2 and np.mean(a > 45.0) > 0.1


def test_normals_png_round_trip() -> None:
    rng = np.random.default_rng(0)
    n = rng.normal(size=(7, 9, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[0, 0] = 0.0
    back = decode_normals_png(encode_normals_png(n))
    assert np.all(back[0, 0] == 0)
    cos = np.clip(np.sum(back * n, -1)[np.any(n != 0, -1)], -1, 1)
    assert np.degrees(np.arccos(cos)).max() < 0.7  # 8 bits per axis


def test_dataset_with_normals_validates(
    dataset_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    rc = main(["validate", str(dataset_out), "--json", "--no-progress"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0 and rep["summary"]["counts"]["error"] == 0, rep["findings"][:3]


def test_bad_out_is_one_line(
    scene: Path, traj: Path, video_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    for args, msg in [
        ((), "output exists"),
        (("--force",), "not a robogs render video folder"),
    ]:
        capsys.readouterr()
        assert _render(scene, traj, other, "--format", "video", *args) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and msg in err[0] and "Traceback" not in err[0], err
        assert (other / "notes.txt").read_text() == "keep me"
    capsys.readouterr()
    assert _render(scene, traj, tmp_path / "x", "--format", "lerobot", "--normals") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--normals applies to --format robogs or video" in err[0]
    # a folder of ours is replaced with --force
    mine = tmp_path / "v"
    assert _render(scene, traj, mine, "--format", "video") == 0
    (mine / "stale.txt").write_text("old")
    assert _render(scene, traj, mine, "--format", "video", "--force") == 0
    assert not (mine / "stale.txt").exists() and (mine / "cam0" / "rgb.mp4").is_file()
    assert not (mine / "cam0" / "normals").exists()  # not asked for
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "v"]

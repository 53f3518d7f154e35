"""``robogs export lerobot``: the LeRobot v3.0 layout read back with pyarrow and OpenCV.

Oracles: the regular grid and the nearest frames by brute force over the recorded stamps,
joint values by ``numpy.interp`` of the recorded tables, EE poses by the synthetic scene's own
forward kinematics (``robogs.synth``, independent of ``robogs.format.kinematics``), video frames
by decoding the source MP4. ``lerobot`` itself is an optional reader (see
``test_lerobot_package_loads``).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.convert.export import export
from robogs.format import Dataset
from robogs.format.errors import DatasetExistsError, InputError
from robogs.format.images import decode_label_png, iter_video_frames
from robogs.synth.scene import synthesize


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("lerobot") / "s"
    synthesize(out, seed=3, size="small", progress=False)
    return out


@pytest.fixture(scope="module")
def exported(scene: Path) -> Path:
    out = scene.parent / "lr"
    export("lerobot", scene, out, labels=True)
    return out


def _info(out: Path) -> dict:
    return json.loads((out / "meta" / "info.json").read_text())


def _frames(out: Path) -> dict[str, np.ndarray]:
    tab = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet")
    cols = {}
    for name in tab.column_names:
        col = tab.column(name)
        if name.endswith(".panoptic") or name.endswith(".depth"):
            cols[name] = [r["bytes"] for r in col.to_pylist()]
        elif name in ("observation.state", "action"):
            cols[name] = np.asarray(col.to_pylist(), np.float64)
        else:
            cols[name] = col.to_numpy()
    return cols


def _grid(scene: Path, fps: int) -> tuple[np.ndarray, np.ndarray]:
    """The expected grid and, per grid stamp, the nearest recorded frame (brute force)."""
    ep = Dataset.open(scene).episode()
    t = ep.frames("cam0").column("t_ns").to_numpy()
    k = np.arange(int((t[-1] - t[0]) * fps // 1_000_000_000) + 1)
    grid = t[0] + np.round(k * 1e9 / fps).astype(np.int64)
    nearest = np.array([int(np.argmin(np.abs(t - g))) for g in grid])
    return grid, nearest


def test_layout_and_info(exported: Path, scene: Path) -> None:
    info = _info(exported)
    assert info["codebase_version"] == "v3.0"
    assert info["fps"] == 30 and isinstance(info["fps"], int)
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] == (
        "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    )
    grid, _ = _grid(scene, 30)
    assert info["total_frames"] == len(grid) and info["total_episodes"] == 1
    feats = info["features"]
    names = Dataset.open(scene).episode().table("joint_states").column_names
    joints = [n[len("position.") :] for n in names if n.startswith("position.")]
    assert feats["observation.state"] == {"dtype": "float32", "shape": [6], "names": joints}
    assert feats["action"]["names"] == joints
    video = feats["observation.images.cam0"]
    assert video["dtype"] == "video" and video["shape"] == [120, 160, 3]
    for k in ("timestamp", "frame_index", "episode_index", "index", "task_index"):
        assert feats[k]["shape"] == [1]
    cam = info["robogs"]["cameras"]["cam0"]
    model = Dataset.open(scene).camera("cam0")
    assert cam["fx"] == model.fx and np.allclose(cam["T_world_cam"], model.T_world_cam)
    for rel in (
        "meta/stats.json",
        "meta/tasks.parquet",
        "meta/episodes/chunk-000/file-000.parquet",
        "videos/observation.images.cam0/chunk-000/file-000.mp4",
    ):
        assert (exported / rel).is_file(), rel
    tasks = pq.read_table(exported / "meta" / "tasks.parquet")
    assert tasks.column("task_index").to_pylist() == [0]
    assert b"pandas" in tasks.schema.metadata  # the task string is the pandas index
    assert tasks.column("__index_level_0__").to_pylist() == ["push"]
    eps = pq.read_table(exported / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert eps[0]["length"] == len(grid) and eps[0]["dataset_to_index"] == len(grid)
    assert eps[0]["robogs/source"] == "recorded"
    stats = json.loads((exported / "meta" / "stats.json").read_text())
    assert stats["observation.state"]["count"] == [len(grid)]
    assert np.array(stats["observation.images.cam0"]["mean"]).shape == (3, 1, 1)


def test_frames_resampled_on_the_grid(exported: Path, scene: Path) -> None:
    rows = _frames(exported)
    grid, nearest = _grid(scene, 30)
    n = len(grid)
    assert np.array_equal(rows["frame_index"], np.arange(n))
    assert np.array_equal(rows["index"], np.arange(n))
    assert np.all(rows["episode_index"] == 0) and np.all(rows["task_index"] == 0)
    # the format's timestamp is k / fps, and it is true: the stamp of the grid it was sampled at
    assert np.array_equal(rows["timestamp"], (np.arange(n) / 30).astype(np.float32))
    assert np.array_equal(rows["observation.stamp_ns"], grid)
    ep = Dataset.open(scene).episode()
    t_cam = ep.frames("cam0").column("t_ns").to_numpy()
    assert np.array_equal(rows["observation.images.cam0.stamp_ns"], t_cam[nearest])
    js = ep.table("joint_states")
    act = ep.table("actions")
    t_j, t_a = js.column("t_ns").to_numpy(), act.column("t_ns").to_numpy()
    joints = [n[len("position.") :] for n in js.column_names if n.startswith("position.")]
    for i, j in enumerate(joints):
        want = np.interp(grid, t_j, js.column(f"position.{j}").to_numpy())
        assert np.abs(rows["observation.state"][:, i] - want).max() < 1e-6
        want_a = np.interp(grid, t_a, act.column(f"command.{j}").to_numpy())
        assert np.abs(rows["action"][:, i] - want_a).max() < 1e-6
    labels = dict(ep.iter_labels("cam0"))
    for k in (0, n // 2, n - 1):
        got = decode_label_png(rows["observation.images.cam0.panoptic"][k])
        assert np.array_equal(got, labels[int(nearest[k])])


def test_video_frames_are_the_nearest_recorded(exported: Path, scene: Path) -> None:
    _, nearest = _grid(scene, 30)
    src = list(iter_video_frames(Dataset.open(scene).episode().video_path("cam0")))
    path = exported / "videos/observation.images.cam0/chunk-000/file-000.mp4"
    cap = cv2.VideoCapture(str(path))
    assert int(round(cap.get(cv2.CAP_PROP_FPS))) == 30
    cap.release()
    got = list(iter_video_frames(path))
    assert len(got) == len(nearest)
    assert got[0].shape == (120, 160, 3)
    for k in range(0, len(got), 17):
        own = float(np.mean((got[k].astype(float) - src[nearest[k]]) ** 2))
        psnr = 10 * np.log10(255.0**2 / max(own, 1e-9))
        assert psnr > 30.0, (k, psnr)


def test_ee_state_matches_independent_fk(scene: Path) -> None:
    from robogs.synth.scene.robot_source import generated_ur5

    out = scene.parent / "lr_ee"
    rep = export("lerobot", scene, out, state="ee")
    assert rep.facts["state"] == "ee"
    info = _info(out)
    assert info["features"]["observation.state"]["names"] == ["x", "y", "z", "qw", "qx", "qy", "qz"]
    rows = _frames(out)
    robot = generated_ur5()
    ds = Dataset.open(scene)
    act = ds.episode().table("actions")
    jn = robot.model.joint_names
    grid = rows["observation.stamp_ns"]
    q_cmd = np.stack(
        [
            np.interp(grid, act.column("t_ns").to_numpy(), act.column(f"command.{j}").to_numpy())
            for j in jn
        ],
        -1,
    )
    T = robot.model.fk(q_cmd)[robot.tool_link]
    assert np.abs(rows["action"][:, :3] - T[:, :3, 3]).max() < 1e-5  # m (float32 storage)
    # the state is the recorded ee_poses stream at the grid stamps (w >= 0 hemisphere)
    ee = ds.episode().table("ee_poses")
    want = np.interp(grid, ee.column("t_ns").to_numpy(), ee.column("x").to_numpy())
    assert np.abs(rows["observation.state"][:, 0] - want).max() < 1e-5
    assert np.all(rows["observation.state"][:, 3] >= 0)
    assert np.allclose(np.linalg.norm(rows["observation.state"][:, 3:], axis=1), 1, atol=1e-5)


def test_bad_options_and_existing_output(scene: Path, exported: Path) -> None:
    with pytest.raises(InputError, match="unknown state"):
        export("lerobot", scene, scene.parent / "bad", state="cartesian")
    with pytest.raises(InputError, match="fps"):
        export("lerobot", scene, scene.parent / "bad", fps=0)
    with pytest.raises(DatasetExistsError):
        export("lerobot", scene, exported)
    assert not (scene.parent / "bad").exists()


def test_cli_prints_resampling(scene: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from robogs.cli.main import main

    out = scene.parent / "lr_cli"
    assert main(["export", "lerobot", str(scene), str(out), "--fps", "15"]) == 0
    err = capsys.readouterr().err
    assert "resampled to a regular 15 fps grid" in err
    assert _info(out)["fps"] == 15
    grid, _ = _grid(scene, 15)
    assert _info(out)["total_frames"] == len(grid)
    assert main(["export", "ply", str(scene), str(scene.parent / "x.ply"), "--state", "ee"]) == 2


def test_lerobot_package_loads(exported: Path) -> None:
    pytest.importorskip(
        "lerobot.datasets.lerobot_dataset",
        reason="optional reader: lerobot 0.4.4 (the newest for Python 3.11; 0.5+ needs Python "
        ">= 3.12) pins torch < 2.11 and torchvision < 0.26, this venv has torch 2.13 (checked "
        "2026-11-26; the layout tests above and test_lerobot_roundtrip read the same files)",
    )
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("robogs/export", root=exported)
    info = _info(exported)
    assert len(ds) == info["total_frames"] and ds.fps == info["fps"]
    item = ds[3]
    assert tuple(item["observation.state"].shape) == (6,)
    assert tuple(item["observation.images.cam0"].shape) == (3, 120, 160)
    assert abs(float(item["timestamp"]) - 3 / info["fps"]) < 1e-6

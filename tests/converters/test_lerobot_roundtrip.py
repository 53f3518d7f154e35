"""synth -> ``robogs export lerobot`` -> ``robogs convert`` (LeRobot v3 ingest) round trip.

Oracles: the source dataset's own tables. Camera stamps come back *exactly* (the export keeps
the recorded stamp of every picked frame); joint and action stamps come back as the export's
regular grid (resampled, within half a grid period of a recorded camera frame), and their values
equal ``numpy.interp`` of the recorded tables at the grid within 1e-6 (float32 storage).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.export import export
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.registry import detect_format
from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.images import iter_video_frames
from robogs.synth.scene import synthesize


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("lr_rt") / "s"
    synthesize(out, seed=5, size="small", progress=False)
    return out


def _round_trip(scene: Path, fps: int, tag: str) -> tuple[Dataset, Path]:
    lr = scene.parent / f"lr{tag}"
    export("lerobot", scene, lr, labels=True, fps=fps)
    back = convert_path(
        lr, scene.parent / f"back{tag}", options=ConvertOptions(urdf=scene / "robot/robot.urdf")
    )
    return back, lr


def _picks(grid: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Brute force: index of the recorded frame nearest each grid stamp (ties: earlier)."""
    return np.array([int(np.argmin(np.abs(t - g))) for g in grid])


@pytest.mark.parametrize("fps", [30, 15, 60])
def test_round_trip_stamps_and_values(scene: Path, fps: int) -> None:
    src = Dataset.open(scene)
    sep = src.episode()
    back, lr = _round_trip(scene, fps, str(fps))
    assert detect_format(lr).name == "lerobot"
    ep = back.episode(sep.id)
    # -- joints: the export's grid (resampled), values = interp of the recorded table ----------
    t_cam = sep.frames("cam0").column("t_ns").to_numpy()
    k = np.arange(int((t_cam[-1] - t_cam[0]) * fps // 1_000_000_000) + 1)
    grid = t_cam[0] + np.round(k * 1e9 / fps).astype(np.int64)
    js, js0 = ep.table("joint_states"), sep.table("joint_states")
    assert js.column("t_ns").type.bit_width == 64
    assert np.array_equal(js.column("t_ns").to_numpy(), grid)
    assert ep.streams["joint_states"]["stamp_source"] == "derived"  # resampled, and said so
    joints = [c for c in js0.column_names if c.startswith("position.")]
    assert sorted(c for c in js.column_names if c.startswith("position.")) == sorted(joints)
    for c in joints:
        want = np.interp(grid, js0.column("t_ns").to_numpy(), js0.column(c).to_numpy())
        assert np.abs(js.column(c).to_numpy() - want).max() < 1e-6, c
    act, act0 = ep.table("actions"), sep.table("actions")
    for c in (c for c in act0.column_names if c.startswith("command.")):
        want = np.interp(grid, act0.column("t_ns").to_numpy(), act0.column(c).to_numpy())
        assert np.abs(act.column(c).to_numpy() - want).max() < 1e-6, c
    # -- camera: the recorded stamps, exactly; a frame picked twice comes back once -----------
    picks = _picks(grid, t_cam)
    distinct = np.unique(picks)
    got = ep.frames("cam0").column("t_ns").to_numpy()
    assert np.array_equal(got, t_cam[distinct])
    assert ep.streams["camera/cam0"]["stamp_source"] == "sidecar"
    # each grid stamp is within half a recorded frame gap of the frame it shows
    gap = np.diff(t_cam)[np.clip(np.searchsorted(t_cam, grid) - 1, 0, len(t_cam) - 2)]
    assert np.all(np.abs(t_cam[picks] - grid) <= gap / 2)
    if fps == 60:
        assert len(distinct) < len(grid)  # the 60 fps grid repeats frames of a 30 fps camera
    if fps == 30:
        assert len(got) == len(grid)
    # labels come back bit-exact, images through two MPEG-4 encodes
    labels0 = dict(sep.iter_labels("cam0"))
    labels = dict(ep.iter_labels("cam0"))
    assert len(labels) == len(got)
    for j in (0, len(got) // 2, len(got) - 1):
        assert np.array_equal(labels[j], labels0[int(distinct[j])])
    img0 = list(iter_video_frames(sep.video_path("cam0")))
    img = list(iter_video_frames(ep.video_path("cam0")))
    assert len(img) == len(got)
    for j in range(0, len(img), 11):
        mse = float(np.mean((img[j].astype(float) - img0[int(distinct[j])]) ** 2))
        assert 10 * np.log10(255.0**2 / max(mse, 1e-9)) > 27.0, j
    # -- camera model, robot, notes --------------------------------------------------------------
    m0, m = src.camera("cam0"), back.camera("cam0")
    assert (m.width, m.height, m.fx, m.fy, m.cx, m.cy) == (
        m0.width,
        m0.height,
        m0.fx,
        m0.fy,
        m0.cx,
        m0.cy,
    )
    assert np.allclose(m.T_world_cam, m0.T_world_cam, atol=0, rtol=0)
    assert back.manifest["robot"]
    notes = " ".join(back.manifest["provenance"]["notes"])
    assert f"resampled every stream to {fps} fps" in notes
    assert ep.segment == sep.segment


def test_foreign_dataset_without_our_columns(scene: Path, tmp_path: Path) -> None:
    """A v3 dataset without ``*.stamp_ns`` or ``robogs`` metadata: stamps from ``timestamp``."""
    import pyarrow.parquet as pq

    _, lr = _round_trip(scene, 30, "_f")
    data = lr / "data/chunk-000/file-000.parquet"
    tab = pq.read_table(data)
    keep = [c for c in tab.column_names if not c.endswith("stamp_ns")]
    pq.write_table(tab.select(keep), data)
    info = json.loads((lr / "meta/info.json").read_text())
    info.pop("robogs")
    info["features"] = {k: v for k, v in info["features"].items() if not k.endswith("stamp_ns")}
    (lr / "meta/info.json").write_text(json.dumps(info))
    back = convert_path(lr, tmp_path / "f")
    ep = back.episode("ep000")
    t = ep.table("joint_states").column("t_ns").to_numpy()
    n = info["total_frames"]
    ts = pq.read_table(data).column("timestamp").to_numpy()  # float32 s
    assert np.array_equal(t, np.round(ts.astype(np.float64) * 1e9).astype(np.int64))
    assert np.abs(t - np.arange(n) * 1e9 / 30).max() < 1e-6 * 1e9  # float32 precision, < 1 us
    assert np.array_equal(ep.frames("cam0").column("t_ns").to_numpy(), t)
    assert "no intrinsics" in " ".join(back.manifest["provenance"]["notes"])


def test_not_v3_is_refused(tmp_path: Path) -> None:
    (tmp_path / "lr" / "meta").mkdir(parents=True)
    (tmp_path / "lr" / "meta" / "info.json").write_text('{"codebase_version": "v2.1", "fps": 30}')
    with pytest.raises(InputError, match="not v3"):
        convert_path(tmp_path / "lr", tmp_path / "out", fmt="lerobot")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("column", "shift", "message"),
    [
        ("videos/observation.images.cam0/from_timestamp", 100.0, "video has no frame"),
        ("length", 1, "data rows"),
    ],
)
def test_inconsistent_metadata_is_one_clear_error(
    scene: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    column: str,
    shift: float,
    message: str,
) -> None:
    """meta/episodes pointing past the video or the data rows: a one-line error, no output."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from robogs.cli.main import main
    from robogs.format.errors import FormatError

    _, lr = _round_trip(scene, 30, f"_bad{column[:3]}")
    path = lr / "meta/episodes/chunk-000/file-000.parquet"
    tab = pq.read_table(path)
    i = tab.column_names.index(column)
    col = tab.column(column)
    pq.write_table(tab.set_column(i, column, pa.compute.add(col, pa.scalar(shift, col.type))), path)
    with pytest.raises(FormatError, match=message):
        convert_path(lr, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    capsys.readouterr()
    assert main(["convert", str(lr), str(tmp_path / "out2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and "Traceback" not in err[0]


def test_ee_state_round_trip(scene: Path, tmp_path: Path) -> None:
    """``--state ee``: the EE pose comes back as ``ee_poses`` of ``robot.ee_link``; the export's
    state is the recorded ee_poses stream at the grid (the oracle here), float32 storage."""
    lr = tmp_path / "lr_ee"
    export("lerobot", scene, lr, state="ee")
    back = convert_path(lr, tmp_path / "back_ee")
    sep = Dataset.open(scene).episode()
    ep = back.episode(sep.id)
    assert not ep.has("joint_states") and not ep.has("actions")  # an EE action has no table
    ee, ee0 = ep.table("ee_poses"), sep.table("ee_poses")
    link = Dataset.open(scene).manifest["robot"]["ee_link"]
    assert set(ee.column("link").to_pylist()) == {link}
    t = ee.column("t_ns").to_numpy()
    for c in ("x", "y", "z"):
        want = np.interp(t, ee0.column("t_ns").to_numpy(), ee0.column(c).to_numpy())
        assert np.abs(ee.column(c).to_numpy() - want).max() < 1e-6, c
    q = np.stack([ee.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-6)
    assert "no EE command table" in " ".join(back.manifest["provenance"]["notes"])

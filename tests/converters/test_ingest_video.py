"""Videos and image folders: stamps from the container, a sidecar, or an explicit assumed rate."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from robogs.convert.ingest import ConvertOptions, convert_path
from robogs.format.errors import InputError
from robogs.format.validate import validate

CALIB = "camera_info/image_common/camera_info_manager/tests/test_calibration.yaml"  # 640x480


def _video(
    path: Path, synth, n: int = 12, fps: float = 25.0, size: tuple[int, int] = (64, 48)
) -> None:
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    for i in range(n):
        vw.write(cv2.cvtColor(cv2.resize(synth.frame_image(i), size), cv2.COLOR_RGB2BGR))
    vw.release()


def test_video_container_pts(tmp_path: Path, synth) -> None:
    _video(tmp_path / "v.mp4", synth)
    ds = convert_path(tmp_path / "v.mp4", tmp_path / "out", options=ConvertOptions(offset_ns=1_000))
    st = ds.episode().stream("camera/v")
    assert st["stamp_source"] == "container_pts" and st["offset_ns"] == 1_000
    # 25 fps mp4: PTS of frame i is i * 40 ms; the offset is added
    assert ds.episode().frames("v").column("t_ns").to_pylist() == [
        i * 40_000_000 + 1_000 for i in range(12)
    ]
    frames = list(ds.episode().iter_video("v"))
    assert np.abs(frames[7].astype(float) - synth.frame_image(7).astype(float)).mean() < 8.0


@pytest.mark.realdata
def test_video_sidecar_and_calibration(tmp_path: Path, synth, real: Path) -> None:
    _video(tmp_path / "v.mp4", synth, size=(640, 480))
    stamps = [1_000_000_000 + i * 33_000_000 + (i % 3) * 1_000 for i in range(12)]
    (tmp_path / "s.csv").write_text(
        "frame_index,t_ns\n" + "".join(f"{i},{t}\n" for i, t in enumerate(stamps))
    )
    joints = "t_ns,position.j1,velocity.j1,note\n" + "".join(
        f"{1_000_000_000 + k * 2_000_000},{0.001 * k},{0.5},x\n" for k in range(200)
    )
    (tmp_path / "j.csv").write_text(joints)
    opts = ConvertOptions(
        stamps_csv=tmp_path / "s.csv", camera_file=real / CALIB, joints_csv=tmp_path / "j.csv"
    )
    ds = convert_path(tmp_path / "v.mp4", tmp_path / "out", options=opts)
    ep = ds.episode()
    cam = ds.camera_names[0]
    assert cam == "08144361026320a0"
    assert ep.frames(cam).column("t_ns").to_pylist() == stamps
    assert ep.stream(f"camera/{cam}")["stamp_source"] == "sidecar"
    js = ep.table("joint_states").to_pydict()
    assert js["t_ns"] == [1_000_000_000 + k * 2_000_000 for k in range(200)]
    np.testing.assert_allclose(
        js["position.j1"], [0.001 * k for k in range(200)], rtol=0, atol=1e-12
    )
    assert ep.stream("joint_states")["nominal_rate_hz"] == pytest.approx(500.0)
    assert any("['note']" in n for n in ds.manifest["provenance"]["notes"])
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def test_video_assume_fps_is_declared_derived(tmp_path: Path, synth) -> None:
    _video(tmp_path / "v.mp4", synth, n=5)
    ds = convert_path(tmp_path / "v.mp4", tmp_path / "out", options=ConvertOptions(assume_fps=10.0))
    assert ds.episode().stream("camera/v")["stamp_source"] == "derived"
    assert ds.episode().frames("v").column("t_ns").to_pylist() == [
        i * 100_000_000 for i in range(5)
    ]


@pytest.mark.realdata
def test_calibration_of_another_resolution_is_refused(tmp_path: Path, synth, real: Path) -> None:
    _video(tmp_path / "v.mp4", synth, n=3)
    with pytest.raises(
        InputError, match="calibration is for 640x480 images but the frames are 64x48"
    ):
        convert_path(
            tmp_path / "v.mp4", tmp_path / "out", options=ConvertOptions(camera_file=real / CALIB)
        )
    assert not (tmp_path / "out").exists()


def test_image_folder_needs_stamps(tmp_path: Path, synth) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in (1, 2, 10):  # natural order: 1, 2, 10
        cv2.imwrite(
            str(folder / f"f{i}.png"), cv2.cvtColor(synth.frame_image(i), cv2.COLOR_RGB2BGR)
        )
    with pytest.raises(InputError, match="no frame stamps"):
        convert_path(folder, tmp_path / "out")
    (folder / "stamps.csv").write_text("frame_index,t_ns\n0,100\n1,200\n2,350\n")
    ds = convert_path(folder, tmp_path / "out")
    ep = ds.episode()
    assert ep.frames("imgs").column("t_ns").to_pylist() == [100, 200, 350]
    frames = list(ep.iter_video("imgs"))
    assert np.abs(frames[2].astype(float) - synth.frame_image(10).astype(float)).mean() < 8.0
    (folder / "stamps.csv").write_text("frame_index,t_ns\n0,100\n1,200\n")
    with pytest.raises(InputError, match="no stamp for frame 2"):
        convert_path(folder, tmp_path / "out2")


def test_joint_log_must_increase(tmp_path: Path, synth) -> None:
    _video(tmp_path / "v.mp4", synth, n=3)
    (tmp_path / "j.csv").write_text("t_ns,position.a\n10,0.1\n30,0.2\n20,0.3\n")
    with pytest.raises(InputError, match="t_ns does not increase") as ei:
        convert_path(
            tmp_path / "v.mp4",
            tmp_path / "out",
            options=ConvertOptions(joints_csv=tmp_path / "j.csv"),
        )
    assert "data row 3" in str(ei.value)
    assert not (tmp_path / "out").exists()

"""``robogs convert --split-at-gaps``: a recording of pushes with hand resets becomes one
episode per push, for bags/MCAP and tabular logs alike.

The bag is written here with rosbags' ROS 2 writer (MCAP storage), sharing no code with the
converter: three pushes of joint states (100 Hz), object mocap (50 Hz), a wrench (200 Hz) and
camera images (10 Hz), separated by hand-made pauses of 2.0 s and 1.5 s in which nothing is
recorded. Inside the second push the mocap alone drops out for 0.3 s (a marker occlusion): one
stream pausing is not a cut. The oracle is the generator's own push windows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.cli.main import main
from robogs.convert.ingest import convert_path
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.gaps import GAP_FACTOR, plan_split
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.format.images import video_frame_count
from robogs.format.validate import validate

T0 = 1_700_000_000_000_000_000
S = 1_000_000_000
#: push k spans [start, start + 1 s); the pauses between pushes are 2.0 s and 1.5 s
PUSHES = [(T0, T0 + S), (T0 + 3 * S, T0 + 4 * S), (T0 + int(5.5 * S), T0 + int(6.5 * S))]
RATES = {"/joint_states": 100, "/mocap/box/pose": 50, "/ft/wrench": 200, "/cam/image_raw": 10}
DROPOUT = (T0 + int(3.4 * S), T0 + int(3.7 * S))  # mocap only, inside push 2


def _stamps(topic: str) -> list[int]:
    step = S // RATES[topic]
    out = []
    for a, b in PUSHES:
        for t in range(a, b, step):
            if topic == "/mocap/box/pose" and DROPOUT[0] <= t < DROPOUT[1]:
                continue
            out.append(t)
    return out


def _pauses() -> list[tuple[int, int]]:
    """(last stamp of push k, first stamp of push k+1) over every topic."""
    every = sorted({t for topic in RATES for t in _stamps(topic)})
    ends = [max(t for t in every if t < b) for _, b in PUSHES]
    return [(ends[k], PUSHES[k + 1][0]) for k in range(len(PUSHES) - 1)]


def _write_bag(path: Path) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    M = ts.types

    def header(t: int, frame: str) -> Any:
        stamp = M["builtin_interfaces/msg/Time"](sec=t // S, nanosec=t % S)
        return M["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def vec(x: float, y: float, z: float) -> Any:
        return M["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    events: list[tuple[int, str, str, Any]] = []
    for t in _stamps("/joint_states"):
        s = (t - T0) / S
        msg = M["sensor_msgs/msg/JointState"](
            header=header(t, ""),
            name=["j1", "j2"],
            position=np.array([0.1 * s, -0.2 * s]),
            velocity=np.array([0.1, -0.2]),
            effort=np.zeros(2),
        )
        events.append((t, "/joint_states", "sensor_msgs/msg/JointState", msg))
    for t in _stamps("/mocap/box/pose"):
        s = (t - T0) / S
        pose = M["geometry_msgs/msg/Pose"](
            position=M["geometry_msgs/msg/Point"](x=0.5 + 0.01 * s, y=0.0, z=0.05),
            orientation=M["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        msg = M["geometry_msgs/msg/PoseStamped"](header=header(t, "world"), pose=pose)
        events.append((t, "/mocap/box/pose", "geometry_msgs/msg/PoseStamped", msg))
    for t in _stamps("/ft/wrench"):
        w = M["geometry_msgs/msg/Wrench"](force=vec(1.0, 0.0, -2.0), torque=vec(0.0, 0.1, 0.0))
        msg = M["geometry_msgs/msg/WrenchStamped"](header=header(t, "ft_sensor"), wrench=w)
        events.append((t, "/ft/wrench", "geometry_msgs/msg/WrenchStamped", msg))
    for t in _stamps("/cam/image_raw"):
        img = np.full((24, 32, 3), 60, np.uint8)
        img[:, : 1 + (t // 10**8) % 30] = 220
        msg = M["sensor_msgs/msg/Image"](
            header=header(t, "cam_optical"), height=24, width=32, encoding="rgb8",
            is_bigendian=0, step=96, data=img.reshape(-1).copy(),
        )  # fmt: skip
        events.append((t + 1_000_000, "/cam/image_raw", "sensor_msgs/msg/Image", msg))
        roi = M["sensor_msgs/msg/RegionOfInterest"](
            x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
        )
        info = M["sensor_msgs/msg/CameraInfo"](
            header=header(t, "cam_optical"), height=24, width=32, distortion_model="plumb_bob",
            d=np.zeros(5), k=np.array([40.0, 0, 15.5, 0, 40.0, 11.5, 0, 0, 1]),
            r=np.eye(3).ravel(), p=np.zeros(12), binning_x=0, binning_y=0, roi=roi,
        )  # fmt: skip
        events.append((t + 1_000_000, "/cam/camera_info", "sensor_msgs/msg/CameraInfo", info))
    events.sort(key=lambda e: e[0])
    types = {topic: typ for _, topic, typ, _ in events}
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {tp: w.add_connection(tp, ty, typestore=ts) for tp, ty in types.items()}
        for log, topic, typ, msg in events:
            w.write(conns[topic], log, ts.serialize_cdr(msg, typ))
    return path


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _write_bag(tmp_path_factory.mktemp("gaps") / "pushes")


def _rows(ds: Dataset, ep: Any, stream: str, field: str = "path") -> np.ndarray:
    return pq.read_table(ds.root / ep.streams[stream][field]).column("t_ns").to_numpy()


def test_derived_gap_cuts_inside_every_pause_and_nowhere_else(bag: Path, tmp_path: Path) -> None:
    opts = ConvertOptions(split_gaps=True, episode="run")
    ds = convert_path(bag, tmp_path / "out", options=opts)
    (rec,) = ds.manifest["provenance"]["split_at_gaps"]
    # the densest stream is the 200 Hz wrench: 10 x 5 ms
    assert rec["derived"] and rec["densest"] == "wrenches"
    assert rec["gap_s"] == pytest.approx(GAP_FACTOR / RATES["/ft/wrench"])
    assert [e.id for e in ds.episodes] == ["run_000", "run_001", "run_002"]
    pauses = _pauses()
    assert len(rec["cuts"]) == len(pauses)  # the 0.3 s mocap dropout is not a cut
    for cut, (before, after) in zip(rec["cuts"], pauses, strict=True):
        assert before < cut["cut_ns"] < after
        assert (cut["before_ns"], cut["after_ns"]) == (before, after)
    for ep, (a, b) in zip(ds.episodes, PUSHES, strict=True):
        for topic, stream in (
            ("/joint_states", "joint_states"),
            ("/mocap/box/pose", "object_poses"),
            ("/ft/wrench", "wrenches"),
        ):
            want = [t for t in _stamps(topic) if a <= t < b]
            assert _rows(ds, ep, stream).tolist() == want, (ep.id, stream)
        (cam,) = [n for n, st in ep.streams.items() if st["kind"] == "camera"]
        frames = pq.read_table(ds.root / ep.streams[cam]["frames"])
        want = [t for t in _stamps("/cam/image_raw") if a <= t < b]
        assert frames.column("t_ns").to_numpy().tolist() == want
        assert frames.column("frame_index").to_numpy().tolist() == list(range(len(want)))
        assert video_frame_count(ds.root / ep.streams[cam]["video"], exact=True) == len(want)
        assert ep.start_ns == a and ep.end_ns == max(
            t for topic in RATES for t in _stamps(topic) if a <= t < b
        )
    assert not (ds.root / "episodes" / "run").exists()
    # the one error left is the mocap's own dropout, inside run_001 (a real gap, not a cut)
    errors = [f for f in validate(ds.root).findings if f.severity == "error"]
    assert [(f.code, f.location.episode, f.location.stream) for f in errors] == [
        ("T003", "run_001", "object_poses")
    ]


@pytest.mark.parametrize(("gap_s", "n"), [(1.7, 2), (1.2, 3), (2.5, 1), (0.2, 3)])
def test_given_gap_cuts_only_longer_pauses(bag: Path, tmp_path: Path, gap_s: float, n: int) -> None:
    """Silences of ~2.0 s and ~1.5 s between pushes: 1.7 s cuts one, 1.2 s both, 2.5 s none;
    0.2 s does not cut at the mocap's 0.3 s dropout, the other streams go on through it."""
    opts = ConvertOptions(split_gaps=True, split_gap_s=gap_s, video=False)
    ds = convert_path(bag, tmp_path / "out", options=opts)
    assert len(ds.episodes) == n
    (rec,) = ds.manifest["provenance"]["split_at_gaps"]
    assert not rec["derived"] and rec["gap_s"] == pytest.approx(gap_s)
    assert all(c["pause_s"] > gap_s for c in rec["cuts"])


def test_without_the_flag_one_episode(bag: Path, tmp_path: Path) -> None:
    ds = convert_path(bag, tmp_path / "out", options=ConvertOptions(video=False))
    assert [e.id for e in ds.episodes] == ["ep000"]
    assert "split_at_gaps" not in ds.manifest["provenance"]
    # unsplit, the validator sees each hand reset as a stream gap (T003)
    found = validate(ds.root, select=["T003"]).findings
    for stream in ("joint_states", "wrenches"):
        assert len([f for f in found if f.location.stream == stream]) == len(_pauses())


def test_plan_split_oracle() -> None:
    """Closed form: two streams, 10 ms and 25 ms, one common 0.4 s silence."""
    a = np.concatenate([np.arange(0, 1_000, 10), np.arange(1_400, 2_000, 10)]) * 1_000_000
    b = np.concatenate([np.arange(0, 1_000, 25), np.arange(1_400, 2_000, 25)]) * 1_000_000
    plan = plan_split({"a": a, "b": b}, None)
    assert plan.densest == "a" and plan.median_period_ns == 10_000_000
    assert plan.gap_ns == 100_000_000
    (cut,) = plan.cuts
    assert (cut.before_ns, cut.after_ns) == (990_000_000, 1_400_000_000)
    assert cut.cut_ns == 1_195_000_000
    # stream b alone pausing longer than the gap is not a cut: a goes on
    b2 = b[(b < 500_000_000) | (b > 800_000_000)]
    assert len(plan_split({"a": a, "b": b2}, None).cuts) == 1
    with pytest.raises(InputError, match="cannot derive a gap"):
        plan_split({"a": np.array([5, 5])}, None)


def test_cli_prints_the_cut_table(bag: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    assert main(["convert", str(bag), str(out), "--split-at-gaps", "--no-video"]) == 0
    text = capsys.readouterr().out
    assert "derived: 10 x the median period 5 ms of wrenches" in text
    for k in range(3):
        assert f"ep000_{k:03d}" in text
    assert text.count("then pause") == 2
    assert main(["convert", str(bag), str(out), "--force", "--split-at-gaps", "x"]) == 2
    assert "--split-at-gaps expects a positive number" in capsys.readouterr().err
    glob = str(bag.parent / "push*")  # a glob: one task per bag, each cut on its own
    assert main(["convert", glob, str(tmp_path / "many"), "--split-at-gaps", "--no-video"]) == 0
    assert "split ep0000 at pauses > 0.05 s (derived): ep0000_000, ep0000_001, ep0000_002" in (
        capsys.readouterr().out
    )


URDF = """<robot name="arm">
  <link name="base"/><link name="l1"/><link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-5" upper="5" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-5" upper="5" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_tabular_log_is_cut_too(tmp_path: Path) -> None:
    """A joint log at 50 Hz with 0.5 s pauses (shorter than tabular's own 1 s segment gap):
    the generic split cuts it as well."""
    rows = ["t_ns,position.j1,position.j2"]
    windows = [(0.0, 1.0), (1.5, 2.5), (3.0, 4.0)]
    for a, b in windows:
        for t in np.arange(a, b, 0.02):
            rows.append(f"{T0 + round(t * 1e9)},{t:.3f},{-t:.3f}")
    (tmp_path / "log.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "arm.urdf").write_text(URDF)
    ds = convert_path(
        tmp_path / "log.csv",
        tmp_path / "out",
        fmt="tabular",
        options=ConvertOptions(split_gaps=True, split_gap_s=0.3, urdf=tmp_path / "arm.urdf"),
    )
    assert len(ds.episodes) == 3
    assert ds.manifest["provenance"]["split_at_gaps"][0]["episode"] == "log"
    for ep, (a, b) in zip(ds.episodes, windows, strict=True):
        t = _rows(ds, ep, "joint_states")
        assert t.min() >= T0 + a * 1e9 - 1 and t.max() < T0 + b * 1e9
    # tabular's own segment gap (max(1 s, 50 steps)) leaves the 0.5 s pauses in one episode
    one = convert_path(
        tmp_path / "log.csv",
        tmp_path / "one",
        fmt="tabular",
        options=ConvertOptions(urdf=tmp_path / "arm.urdf"),
    )
    assert len(one.episodes) == 1


def test_boxes_follow_their_frames_and_a_silent_camera_has_no_stream(tmp_path: Path) -> None:
    """Hand-built episode: a generic stream in three windows, a camera (no video) in the first
    two, 2-D boxes on some frames. After the cut each piece's boxes name its own renumbered
    frames (same stamps), and the third piece has no camera stream."""
    import pyarrow as pa

    from robogs.convert.ingest.gaps import split_episodes

    ms = 1_000_000
    windows = [(0, 1000), (2000, 3000), (4000, 5000)]  # ms
    t_all = np.concatenate([np.arange(a, b, 10) for a, b in windows]) * ms + T0
    t_cam = np.concatenate([np.arange(a, b, 100) for a, b in windows[:2]]) * ms + T0
    frames = pa.table({"t_ns": t_cam, "frame_index": np.arange(t_cam.size, dtype=np.int64)})
    pick = np.array([1, 4, 12, 17])  # frames with a box: two in each window
    boxes = pa.table(
        {
            "t_ns": t_cam[pick],
            "camera": ["cam"] * pick.size,
            "frame_index": pick.astype(np.int64),
            "label_id": pa.array(np.arange(pick.size), pa.int32()),
            **{c: np.ones(pick.size) for c in ("x_min", "y_min", "x_max", "y_max")},
        }
    )
    w = Dataset.create(tmp_path / "ds")
    try:
        ep = "episodes/e"
        w.write_table(f"{ep}/g.parquet", pa.table({"t_ns": t_all}), kind="generic")
        w.write_table(f"{ep}/cam/frames.parquet", frames, kind="camera_frames")
        w.write_table(f"{ep}/boxes.parquet", boxes, kind="boxes2d")
        base = {"stamp_source": "log_time", "offset_ns": 0}
        w.add_episode(
            "e",
            start_ns=int(t_all[0]),
            end_ns=int(t_all[-1]),
            streams={
                "streams/g": {"kind": "generic", "path": f"{ep}/g.parquet", **base},
                "camera/cam": {
                    "kind": "camera",
                    "camera": "cam",
                    "frames": f"{ep}/cam/frames.parquet",
                    **base,
                },
                "boxes2d": {"kind": "boxes2d", "path": f"{ep}/boxes.parquet", **base},
            },
        )
        (rec,) = split_episodes(w, 0.5)
        assert [e["id"] for e in rec["episodes"]] == ["e_000", "e_001", "e_002"]
        eps = {e["id"]: e["streams"] for e in w.manifest["episodes"]}
        assert sorted(eps["e_002"]) == ["streams/g"]
        for k in range(2):
            st = eps[f"e_{k:03d}"]
            f = pq.read_table(w.tmp / st["camera/cam"]["frames"]).to_pydict()
            b = pq.read_table(w.tmp / st["boxes2d"]["path"]).to_pydict()
            assert f["frame_index"] == list(range(10))
            assert len(b["t_ns"]) == 2
            for t, i in zip(b["t_ns"], b["frame_index"], strict=True):
                assert f["t_ns"][i] == t  # the box's frame is the frame of its stamp
    finally:
        w.abort()

"""Dynamic ``/tf``: moving frames become object poses and time-varying camera extrinsics.

The synthetic bags hold a transform tree whose poses are known in closed form (frames turning
about z at constant rates), written with rosbags' writers (ROS 1 bag, ROS 2 bag with MCAP
storage; the storage file is also read as a plain MCAP). Edges are published at different rates
and stamps, so the ingest must interpolate; slerp of a constant-rate turn about a fixed axis is
exact, so the dataset must equal the closed form to 1e-9. The real turtlesim bag's ``/tf`` is
checked against its own ``/turtleN/pose`` messages.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest import convert_path
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.tf_buffer import TfBuffer
from robogs.format.errors import InputError
from robogs.format.validate import validate

T0 = 1_700_000_000_000_000_000
W_ARM, W_BOX, W_RIG = 1.3, 0.7, -0.5  # rad/s about z
DUR = 0.6  # s


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _T(R: np.ndarray, t: list[float] | np.ndarray) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    return M


def _quat_xyzw(R: np.ndarray) -> list[float]:
    """Quaternion (x, y, z, w) of a rotation, by the trace method (w > 0 here)."""
    w = np.sqrt(max(1e-12, 1.0 + np.trace(R))) / 2.0
    return [
        (R[2, 1] - R[1, 2]) / (4 * w),
        (R[0, 2] - R[2, 0]) / (4 * w),
        (R[1, 0] - R[0, 1]) / (4 * w),
        w,
    ]


def _s(t: int) -> float:
    return (t - T0) / 1e9


# closed-form edges (parent, child) -> T(t)
T_WORLD_BASE = _T(np.eye(3), [0.1, 0.0, 0.0])
# camera: z towards the rig's origin, looking down 30 degrees; x right, y down (OpenCV)
_Rc = np.array([[0.0, -1.0, 0.0], [-0.5, 0.0, -np.sqrt(3) / 2], [np.sqrt(3) / 2, 0.0, -0.5]]).T
T_RIG_CAM = _T(_Rc, [1.0, 0.0, 0.8])


def T_base_arm(t: int) -> np.ndarray:
    return _T(_rz(W_ARM * _s(t)), [0.0, 0.0, 0.5])


def T_arm_box(t: int) -> np.ndarray:
    return _T(_rz(W_BOX * _s(t)), [0.4 + 0.1 * np.sin(2 * _s(t)), 0.0, 0.05])


def T_world_rig(t: int) -> np.ndarray:
    return _T(_rz(W_RIG * _s(t)), [0.0, 0.0, 0.0])


def _stamps(hz: float, offset_ms: float) -> list[int]:
    n = int(DUR * hz)
    return [T0 + int(offset_ms * 1e6) + int(round(i * 1e9 / hz)) for i in range(n)]


ARM_T = _stamps(100, 10)
BOX_T = _stamps(50, 13)
RIG_T = _stamps(100, 7)
CAM_T = _stamps(15, 22)
CUP_T = _stamps(30, 17)
CUP_IN_ARM = _T(_rz(0.25), [0.2, 0.1, 0.0])


def _write(path: Path, kind: str, robot_description: str | None = None) -> Path:
    """Write the scene as a ROS 1 bag (``ros1``) or a ROS 2 bag with MCAP storage (``ros2``)."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.types:
        from rosbags.typesys import get_types_from_msg

        ts.register(
            get_types_from_msg(
                "geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"
            )
        )
    M = ts.types

    def header(t: int, frame: str) -> Any:
        stamp = M["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        if kind == "ros1":
            return M["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return M["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def tstamped(t: int, parent: str, child: str, T: np.ndarray) -> Any:
        x, y, z, w = _quat_xyzw(T[:3, :3])
        return M["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent),
            child_frame_id=child,
            transform=M["geometry_msgs/msg/Transform"](
                translation=M["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
                rotation=M["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )

    tfm = M["tf2_msgs/msg/TFMessage"]
    events: list[tuple[int, str, str, Any]] = []
    events.append(
        (
            T0,
            "/tf_static",
            "tf2_msgs/msg/TFMessage",
            tfm(
                transforms=[
                    tstamped(T0, "world", "base", T_WORLD_BASE),
                    tstamped(T0, "rig", "cam_optical", T_RIG_CAM),
                ]
            ),
        )
    )
    for stamps, parent, child, fn in (
        (ARM_T, "base", "arm", T_base_arm),
        (BOX_T, "arm", "box", T_arm_box),
        (RIG_T, "world", "rig", T_world_rig),
    ):
        for t in stamps:
            msg = tfm(transforms=[tstamped(t, parent, child, fn(t))])
            events.append((t + 1_000_000, "/tf", "tf2_msgs/msg/TFMessage", msg))
    K = [40.0, 0.0, 15.5, 0.0, 40.0, 11.5, 0.0, 0.0, 1.0]
    for t in CAM_T:
        img = np.full((24, 32, 3), 80, np.uint8)
        img[:, : 1 + (t // 10**6) % 30] = 200
        if kind == "ros1":
            roi = M["sensor_msgs/msg/RegionOfInterest"](
                x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
            )
            info = M["sensor_msgs/msg/CameraInfo"](
                header=header(t, "cam_optical"), height=24, width=32,
                distortion_model="plumb_bob", D=np.zeros(5), K=np.array(K), R=np.eye(3).ravel(),
                P=np.zeros(12), binning_x=0, binning_y=0, roi=roi,
            )  # fmt: skip
        else:
            roi = M["sensor_msgs/msg/RegionOfInterest"](
                x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
            )
            info = M["sensor_msgs/msg/CameraInfo"](
                header=header(t, "cam_optical"), height=24, width=32,
                distortion_model="plumb_bob", d=np.zeros(5), k=np.array(K), r=np.eye(3).ravel(),
                p=np.zeros(12), binning_x=0, binning_y=0, roi=roi,
            )  # fmt: skip
        image = M["sensor_msgs/msg/Image"](
            header=header(t, "cam_optical"), height=24, width=32, encoding="rgb8",
            is_bigendian=0, step=96, data=img.reshape(-1).copy(),
        )  # fmt: skip
        events.append((t + 2_000_000, "/cam/image_raw", "sensor_msgs/msg/Image", image))
        events.append((t + 2_000_000, "/cam/camera_info", "sensor_msgs/msg/CameraInfo", info))
    for t in CUP_T:
        x, y, z, w = _quat_xyzw(CUP_IN_ARM[:3, :3])
        pose = M["geometry_msgs/msg/PoseStamped"](
            header=header(t, "arm"),
            pose=M["geometry_msgs/msg/Pose"](
                position=M["geometry_msgs/msg/Point"](
                    x=CUP_IN_ARM[0, 3], y=CUP_IN_ARM[1, 3], z=CUP_IN_ARM[2, 3]
                ),
                orientation=M["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            ),
        )
        events.append((t + 1_500_000, "/mocap/cup/pose", "geometry_msgs/msg/PoseStamped", pose))
    if robot_description is not None:
        events.append(
            (
                T0 + 1,
                "/robot_description",
                "std_msgs/msg/String",
                M["std_msgs/msg/String"](data=robot_description),
            )
        )
    events.sort(key=lambda e: e[0])
    types = {topic: typ for _, topic, typ, _ in events}
    if kind == "ros1":
        from rosbags.rosbag1 import Writer

        with Writer(path) as w:
            conns = {tp: w.add_connection(tp, ty, typestore=ts) for tp, ty in types.items()}
            for log, topic, typ, msg in events:
                w.write(conns[topic], log, ts.serialize_ros1(msg, typ))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {tp: w.add_connection(tp, ty, typestore=ts) for tp, ty in types.items()}
        for log, topic, typ, msg in events:
            w.write(conns[topic], log, ts.serialize_cdr(msg, typ))
    return path


def _pose_T(row: dict[str, float]) -> np.ndarray:
    w, x, y, z = row["qw"], row["qx"], row["qy"], row["qz"]
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    return _T(R, [row["x"], row["y"], row["z"]])


def _rows(table: Any, key: str, value: str) -> list[dict[str, Any]]:
    d = table.to_pydict()
    return [{k: d[k][i] for k in d} for i in range(table.num_rows) if d[key][i] == value]


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("tfbags")
    ros2 = _write(root / "r2", "ros2")
    (mcap,) = sorted(ros2.glob("*.mcap"))
    return {"ros1": _write(root / "a.bag", "ros1"), "ros2": ros2, "mcap": mcap}


@pytest.mark.parametrize("kind", ["ros1", "ros2", "mcap"])
def test_moving_frames_match_the_closed_form(
    tmp_path: Path, bags: dict[str, Path], kind: str
) -> None:
    ds = convert_path(bags[kind], tmp_path / "out", options=ConvertOptions(video=False))
    ep = ds.episode()
    poses = ep.table("object_poses")
    assert sorted(set(poses.column("object").to_pylist())) == ["arm", "box", "cup"]
    # box: sampled at its own edge's stamps; the arm edge is interpolated between its samples
    box = _rows(poses, "object", "box")
    assert [r["t_ns"] for r in box] == BOX_T
    for r in box:
        t = r["t_ns"]
        want = T_WORLD_BASE @ T_base_arm(t) @ T_arm_box(t)
        np.testing.assert_allclose(_pose_T(r), want, atol=1e-9)
    arm = _rows(poses, "object", "arm")
    assert [r["t_ns"] for r in arm] == ARM_T
    np.testing.assert_allclose(_pose_T(arm[7]), T_WORLD_BASE @ T_base_arm(ARM_T[7]), atol=1e-9)
    # a PoseStamped in the moving frame "arm", composed with the tree at its own stamps
    cup = _rows(poses, "object", "cup")
    assert [r["t_ns"] for r in cup] == CUP_T
    for r in cup:
        want = T_WORLD_BASE @ T_base_arm(r["t_ns"]) @ CUP_IN_ARM
        np.testing.assert_allclose(_pose_T(r), want, atol=1e-9)
    # the camera hangs from the turning rig: T_world_cam per frame
    cam = ds.camera("cam")
    assert cam.extrinsics == "time_varying" and cam.T_world_cam is None
    stream = ep.streams["camera/cam"]
    ext = pq.read_table(ds.resolve(stream["extrinsics"]))
    assert ext.column("t_ns").to_pylist() == CAM_T
    assert ep.frames("cam").column("t_ns").to_pylist() == CAM_T
    for r in _rows(ext, "t_ns", CAM_T[3]) + _rows(ext, "t_ns", CAM_T[-1]):
        np.testing.assert_allclose(_pose_T(r), T_world_rig(r["t_ns"]) @ T_RIG_CAM, atol=1e-9)
    prov = ds.manifest["provenance"]
    assert prov["topics"]["/tf"]["written"] == prov["topics"]["/tf"]["messages"]
    assert prov["topics"]["/tf"]["stamp_source"] == "sensor_header"
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def test_explicit_frames_and_robot_links(tmp_path: Path, bags: dict[str, Path]) -> None:
    opts = ConvertOptions(video=False, tf_objects={"thebox": "box"})
    ds = convert_path(bags["ros1"], tmp_path / "a", options=opts)
    names = set(ds.episode().table("object_poses").column("object").to_pylist())
    assert names == {"thebox", "cup"}
    urdf = '<robot name="r"><link name="base"/><link name="arm"/></robot>'
    bag = _write(tmp_path / "rd.bag", "ros1", robot_description=urdf)
    ds = convert_path(bag, tmp_path / "b", options=ConvertOptions(video=False))
    names = set(ds.episode().table("object_poses").column("object").to_pylist())
    assert names == {"box", "cup"}  # the robot link "arm" is not an object
    ds = convert_path(
        bags["ros1"], tmp_path / "c", options=ConvertOptions(video=False, tf_auto_objects=False)
    )
    names = set(ds.episode().table("object_poses").column("object").to_pylist())
    assert names == {"cup"}
    with pytest.raises(InputError, match="not in /tf or /tf_static: nowhere"):
        convert_path(
            bags["ros1"], tmp_path / "d", options=ConvertOptions(tf_objects={"x": "nowhere"})
        )
    assert not (tmp_path / "d").exists()


def test_buffer_spill_equals_in_memory() -> None:
    """Samples spilled to disk (out of order, with a repeated stamp) read back as in RAM."""
    rng = np.random.default_rng(3)
    ts = rng.permutation(np.arange(0, 5000, 10, dtype=np.int64))
    ts = np.r_[ts, ts[:1]]
    bufs = [TfBuffer(tolerance_ns=50, spill_rows=1 << 20), TfBuffer(tolerance_ns=50, spill_rows=16)]
    for b in bufs:
        for t in ts:
            a = 0.001 * t
            b.add_sample("w", "f", int(t), [t * 1e-3, 0, 0], [np.cos(a / 2), 0, 0, np.sin(a / 2)])
        b.finalize()
        assert b.duplicates == 1
    q = np.array([0, 5, 1234, 4990, 5100, 5030, -30, -60], np.int64)
    (Ta, oka), (Tb, okb) = (b.compose(b.chain("w", "f"), q) for b in bufs)
    np.testing.assert_array_equal(oka, [True, True, True, True, False, True, True, False])
    np.testing.assert_array_equal(oka, okb)
    np.testing.assert_allclose(Ta, Tb, atol=0)
    np.testing.assert_allclose(Ta[2, :3, :3], _rz(1.234), atol=1e-12)  # slerp between 1230, 1240
    np.testing.assert_allclose(Ta[2, 0, 3], 1.234, atol=1e-12)
    bufs[1].close()


@pytest.mark.realdata
def test_real_turtlesim_tf_matches_its_pose_topics(tmp_path: Path, real: Path) -> None:
    """turtle_tf publishes world -> turtleN from each /turtleN/pose (x, y, theta)."""
    from rosbags.highlevel import AnyReader

    src = real / "ros1_bags/rosbag.js/fixtures/example-bz2.bag"
    ds = convert_path(src, tmp_path / "out")
    poses = ds.episode().table("object_poses")
    assert sorted(set(poses.column("object").to_pylist())) == ["turtle1", "turtle2"]
    ref: dict[str, list[tuple[int, float, float, float]]] = {}
    with AnyReader([src]) as r:
        conns = [c for c in r.connections if c.topic.endswith("/pose")]
        for c, t, raw in r.messages(connections=conns):
            m = r.deserialize(raw, c.msgtype)
            ref.setdefault(c.topic.split("/")[1], []).append((t, m.x, m.y, m.theta))
    for name in ("turtle1", "turtle2"):
        rows = _rows(poses, "object", name)
        assert len(rows) == 1344
        P = np.array(ref[name])
        t = np.array([r["t_ns"] for r in rows])
        xy = np.array([[r["x"], r["y"]] for r in rows])
        yaw = np.array([2 * np.arctan2(r["qz"], r["qw"]) for r in rows])
        assert max(abs(r["z"]) + abs(r["qx"]) + abs(r["qy"]) for r in rows) == 0.0
        # each transform was published from the pose received just before it (or at its stamp)
        best = np.full(len(rows), np.inf)
        for k in (-1, 0):
            j = np.clip(np.searchsorted(P[:, 0].astype(np.int64), t) + k, 0, len(P) - 1)
            err = np.maximum(
                np.hypot(*(xy - P[j, 1:3]).T), np.abs(np.angle(np.exp(1j * (yaw - P[j, 3]))))
            )
            best = np.minimum(best, err)
        assert best.max() < 1e-6
    prov = ds.manifest["provenance"]
    assert prov["topics"]["/tf"]["written"] == 2688
    assert any("turtle1->turtle1, turtle2->turtle2" in n for n in prov["notes"])
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def test_cli_frame_flags_and_map_file(tmp_path: Path, bags: dict[str, Path], capsys) -> None:
    import json

    from robogs.cli.main import main

    roles = tmp_path / "roles.yaml"
    roles.write_text("/mocap/cup/pose: ignore\ntf_objects:\n  turntable: /arm\n", encoding="utf-8")
    rc = main(
        ["convert", str(bags["ros1"]), str(tmp_path / "a"), "--map", str(roles),
         "--tf-object", "box", "--no-video", "--json"]
    )  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["episodes"][0]["streams"] == ["camera/cam", "object_poses"]
    from robogs.format import Dataset

    poses = Dataset.open(tmp_path / "a").episode().table("object_poses")
    assert sorted(set(poses.column("object").to_pylist())) == ["box", "turntable"]
    bad = tmp_path / "bad.yaml"
    bad.write_text("tf_objects: [box]\n", encoding="utf-8")
    rc = main(["convert", str(bags["ros1"]), str(tmp_path / "b"), "--map", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and "tf_objects must map names to TF frames" in err and "Traceback" not in err


def test_time_varying_camera_round_trips_through_mcap(
    tmp_path: Path, bags: dict[str, Path]
) -> None:
    """Dataset -> MCAP export (/tf for the moving camera) -> dataset: same extrinsics and poses."""
    from robogs.convert.export import export

    ds = convert_path(bags["ros1"], tmp_path / "a")
    export("mcap", ds, tmp_path / "a.mcap")
    back = convert_path(tmp_path / "a.mcap", tmp_path / "b")
    assert back.camera("cam").extrinsics == "time_varying"
    tabs = []
    for d in (ds, back):
        ep = d.episode()
        ext = pq.read_table(d.resolve(ep.streams["camera/cam"]["extrinsics"]))
        tabs.append(
            (
                ext.to_pydict(),
                ep.table("object_poses")
                .sort_by([("object", "ascending"), ("t_ns", "ascending")])
                .to_pydict(),
            )
        )
    for a, b in zip(tabs[0], tabs[1], strict=True):
        assert a.keys() == b.keys()
        for k in a:
            if k in ("t_ns", "object"):
                assert a[k] == b[k]
            else:
                np.testing.assert_allclose(a[k], b[k], rtol=0, atol=1e-9)

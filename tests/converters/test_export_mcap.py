"""MCAP export: decoded with mcap's own reader, and read back by robogs' MCAP ingest."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from robogs.convert.export import export
from robogs.convert.export.ros2_mcap import stamp
from robogs.format import Dataset

try:
    from .test_export_data import build_tiny_dataset, check_round_trip, mcap_round_trip
except ImportError:
    from test_export_data import build_tiny_dataset, check_round_trip, mcap_round_trip


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return build_tiny_dataset(tmp_path_factory.mktemp("mcap") / "tiny")


def _read(path: Path) -> dict[str, list[tuple[int, int, object]]]:
    out: dict[str, list[tuple[int, int, object]]] = {}
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append(
                (message.log_time, message.publish_time, decoded)
            )
    return out


def _ns(msg: object) -> int:
    s = msg.header.stamp
    assert 0 <= s.nanosec < 1_000_000_000
    return s.sec * 1_000_000_000 + s.nanosec


def test_stamp_split_is_exact() -> None:
    for t in (0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789, -1):
        s = stamp(t)
        assert s["sec"] * 1_000_000_000 + s["nanosec"] == t and 0 <= s["nanosec"] < 1_000_000_000


def test_messages_equal_the_dataset(tiny: Dataset, tmp_path: Path) -> None:
    report = export("mcap", tiny, tmp_path / "t.mcap")
    msgs = _read(tmp_path / "t.mcap")
    ep = tiny.episode()
    assert report.facts["messages"] == {k: len(v) for k, v in msgs.items()}

    js = ep.table("joint_states")
    got = msgs["/joint_states"]
    assert [lt for lt, _, _ in got] == js.column("t_ns").to_pylist()
    for lt, pt, m in got:
        assert lt == pt == _ns(m)
    assert list(got[0][2].name) == ["j1", "j2"]
    for kind in ("position", "velocity", "effort"):
        arr = np.array([list(getattr(m, kind)) for _, _, m in got])
        ref = np.stack([js.column(f"{kind}.{j}").to_numpy() for j in ("j1", "j2")], -1)
        assert np.array_equal(arr, ref)

    frames = ep.frames("cam0")
    t_frames = frames.column("t_ns").to_pylist()
    images = msgs["/camera/cam0/image_raw/compressed"]
    assert [_ns(m) for _, _, m in images] == t_frames
    for (_, _, m), rgb in zip(images, ep.iter_video("cam0"), strict=True):
        assert m.format == "png" and m.header.frame_id == "cam0_optical_frame"
        png = cv2.cvtColor(
            cv2.imdecode(np.frombuffer(bytes(m.data), np.uint8), cv2.IMREAD_COLOR),
            cv2.COLOR_BGR2RGB,
        )
        assert np.array_equal(png, rgb)  # lossless w.r.t. the decoded video frame
    labels = msgs["/camera/cam0/labels/compressed"]
    for (_, _, m), (_, lab) in zip(labels, ep.iter_labels("cam0"), strict=True):
        assert np.array_equal(
            cv2.imdecode(np.frombuffer(bytes(m.data), np.uint8), cv2.IMREAD_UNCHANGED), lab
        )

    cam = tiny.camera("cam0")
    info = msgs["/camera/cam0/camera_info"][0][2]
    assert (info.width, info.height, info.distortion_model) == (cam.width, cam.height, "plumb_bob")
    K = np.array(info.k).reshape(3, 3)
    np.testing.assert_array_equal(K, cam.K - np.array([[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]]))
    assert list(info.d) == list(cam.distortion)

    ((lt, _, tf),) = msgs["/tf_static"]
    (tr,) = tf.transforms
    assert (tr.header.frame_id, tr.child_frame_id, lt) == (
        "world",
        "cam0_optical_frame",
        ep.start_ns,
    )
    q = tr.transform.rotation
    x, y, z, w = q.x, q.y, q.z, q.w
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    np.testing.assert_allclose(R, cam.T_world_cam[:3, :3], atol=1e-12)
    v = tr.transform.translation
    np.testing.assert_array_equal([v.x, v.y, v.z], cam.T_world_cam[:3, 3])

    for topic, stream, key in (
        ("/objects/box/pose", "object_poses", "box"),
        ("/ee/tool/pose", "ee_poses", "tool"),
    ):
        tab = ep.table(stream)
        got = msgs[topic]
        assert [_ns(m) for _, _, m in got] == tab.column("t_ns").to_pylist()
        arr = np.array(
            [
                [
                    m.pose.position.x,
                    m.pose.position.y,
                    m.pose.position.z,
                    m.pose.orientation.w,
                    m.pose.orientation.x,
                    m.pose.orientation.y,
                    m.pose.orientation.z,
                ]
                for _, _, m in got
            ]
        )
        ref = np.stack(
            [tab.column(c).to_numpy() for c in ("x", "y", "z", "qw", "qx", "qy", "qz")], -1
        )
        assert np.array_equal(arr, ref), key
    wr = ep.table("wrenches")
    got = msgs["/wrench/tool"]
    arr = np.array(
        [
            [
                m.wrench.force.x,
                m.wrench.force.y,
                m.wrench.force.z,
                m.wrench.torque.x,
                m.wrench.torque.y,
                m.wrench.torque.z,
            ]
            for _, _, m in got
        ]
    )
    assert np.array_equal(
        arr, np.stack([wr.column(c).to_numpy() for c in ("fx", "fy", "fz", "tx", "ty", "tz")], -1)
    )
    assert msgs["/robot_description"][0][2].data == tiny.urdf_path.read_text()


def test_round_trip_through_ingest_tiny(tiny: Dataset, tmp_path: Path) -> None:
    check_round_trip(tiny, mcap_round_trip(tiny, tmp_path))

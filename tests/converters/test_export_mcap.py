"""MCAP export: decoded with mcap's own reader, and read back by robogs' MCAP ingest."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.interfaces import QosDurability, QosReliability
from scipy.spatial.transform import Rotation

from robogs.convert.export import export
from robogs.convert.export.ros2_mcap import stamp
from robogs.convert.ingest.convert import convert_path
from robogs.format import Dataset, InputError

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
    assert lt == ep.start_ns
    edges = {(t.header.frame_id, t.child_frame_id): t for t in tf.transforms}
    # world -> root link, the fixed joint, the camera
    assert sorted(edges) == [
        ("link2", "tool"),
        ("world", "base_link"),
        ("world", "cam0_optical_frame"),
    ]
    v = edges[("link2", "tool")].transform.translation
    assert [v.x, v.y, v.z] == [0.1, 0.0, 0.0]  # tool_joint origin
    tr = edges[("world", "cam0_optical_frame")]
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
    description = msgs["/robot_description"][0][2].data
    assert description == (tmp_path / "t_description/urdf/tiny_arm.urdf").read_text()


def test_round_trip_through_ingest_tiny(tiny: Dataset, tmp_path: Path) -> None:
    check_round_trip(tiny, mcap_round_trip(tiny, tmp_path))


def _xyzw_matrix(t: object) -> np.ndarray:
    """4x4 of a geometry_msgs Transform (quaternion x, y, z, w)."""
    q, v = t.rotation, t.translation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = [v.x, v.y, v.z]
    return T


def test_rosbags_reads_every_message_with_ros2_types_and_qos(tiny: Dataset, tmp_path: Path) -> None:
    report = export("mcap", tiny, tmp_path / "t.mcap")
    counts: dict[str, int] = {}
    with AnyReader([tmp_path / "t.mcap"]) as reader:
        for c in reader.connections:
            assert re.fullmatch(r"[a-z0-9_]+/msg/[A-Za-z0-9]+", c.msgtype), c.msgtype
            (qos,) = c.ext.offered_qos_profiles
            latched = c.topic in ("/tf_static", "/robot_description")
            assert qos.reliability == QosReliability.RELIABLE
            assert qos.durability == (
                QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE
            )
        for c, t, raw in reader.messages():
            msg = reader.deserialize(raw, c.msgtype)  # every message of every topic
            counts[c.topic] = counts.get(c.topic, 0) + 1
            for stamped in [msg, *getattr(msg, "transforms", [])]:
                if hasattr(stamped, "header") and c.topic not in ("/tf_static",):
                    s = stamped.header.stamp
                    assert s.sec * 1_000_000_000 + s.nanosec == t
    assert counts == report.facts["messages"]
    assert {"/tf", "/tf_static", "/robot_description", "/joint_states"} <= set(counts)


def test_tf_is_the_datasets_kinematics_and_poses(tiny: Dataset, tmp_path: Path) -> None:
    export("mcap", tiny, tmp_path / "t.mcap")
    msgs = _read(tmp_path / "t.mcap")
    static = {
        (t.header.frame_id, t.child_frame_id): _xyzw_matrix(t.transform)
        for _, _, m in msgs["/tf_static"]
        for t in m.transforms
    }
    dynamic: dict[int, dict[tuple[str, str], np.ndarray]] = {}
    for _, _, m in msgs["/tf"]:
        for t in m.transforms:
            dynamic.setdefault(_ns(t), {})[(t.header.frame_id, t.child_frame_id)] = _xyzw_matrix(
                t.transform
            )
    urdf = tiny.urdf(load_meshes=False)  # yourdfpy's forward kinematics is the oracle
    js = tiny.episode().table("joint_states")
    for i, t in enumerate(js.column("t_ns").to_pylist()):
        edges = {**static, **dynamic[t]}
        assert set(dynamic[t]) == {("base_link", "link1"), ("link1", "link2")}
        urdf.update_cfg({j: js.column(f"position.{j}")[i].as_py() for j in ("j1", "j2")})
        T = edges[("world", "base_link")]
        for parent, child in (("base_link", "link1"), ("link1", "link2"), ("link2", "tool")):
            T = T @ edges[(parent, child)]
            np.testing.assert_allclose(T, urdf.get_transform(child, "base_link"), atol=1e-12)
    poses = tiny.episode().table("object_poses")
    for k, t in enumerate(poses.column("t_ns").to_pylist()):
        T = dynamic[t][("world", "box")]
        row = [poses.column(c)[k].as_py() for c in ("x", "y", "z", "qx", "qy", "qz", "qw")]
        np.testing.assert_allclose(T[:3, 3], row[:3], atol=0)
        np.testing.assert_allclose(T[:3, :3], Rotation.from_quat(row[3:]).as_matrix(), atol=1e-12)


def test_robot_package_resolves_and_round_trips(tiny: Dataset, tmp_path: Path) -> None:
    report = export("mcap", tiny, tmp_path / "x.mcap")
    pkg = tmp_path / "x_description"
    assert report.facts["package"] == str(pkg)
    text = _read(tmp_path / "x.mcap")["/robot_description"][0][2].data
    uris = re.findall(r'filename="([^"]+)"', text)
    assert uris and all(u.startswith("package://x_description/meshes/") for u in uris)
    src = {r.uri: r.path for r in tiny.urdf(load_meshes=True).robogs_mesh_refs}
    originals = re.findall(r'filename="([^"]+)"', tiny.urdf_path.read_text())
    for uri, original in zip(uris, originals, strict=True):
        shipped = pkg / uri[len("package://x_description/") :]
        assert shipped.read_bytes() == Path(src[original]).read_bytes()
    # robogs convert finds the package beside the MCAP: the robot comes back
    back = convert_path(tmp_path / "x.mcap", tmp_path / "back")
    check_round_trip(tiny, back)
    a, b = tiny.urdf(load_meshes=True), back.urdf(load_meshes=True)
    assert [j.name for j in b.robot.joints] == [j.name for j in a.robot.joints]
    assert len(b.robot.links) == len(a.robot.links)
    assert len(b.robogs_mesh_refs) == len(a.robogs_mesh_refs)
    for ra, rb in zip(a.robogs_mesh_refs, b.robogs_mesh_refs, strict=True):
        assert Path(ra.path).read_bytes() == Path(rb.path).read_bytes()
    # a second export with --force replaces the package it wrote; a foreign folder is kept
    export("mcap", tiny, tmp_path / "x.mcap", force=True)
    assert (pkg / "package.xml").is_file()
    (tmp_path / "y_description").mkdir()
    (tmp_path / "y_description" / "package.xml").write_text("<package><name>mine</name></package>")
    with pytest.raises(InputError, match="not written by robogs"):
        export("mcap", tiny, tmp_path / "y.mcap")
    assert not (tmp_path / "y.mcap").exists()
    assert (
        sorted(p.name for p in tmp_path.iterdir() if ".tmp-" in p.name or ".old-" in p.name) == []
    )

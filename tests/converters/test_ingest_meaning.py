"""Roles that follow meaning, and every defined message decoded (issue 18, items 2 and 3).

The ROS 1 bag is written here with ``rosbags.rosbag1.Writer`` and message definitions that
rosbags generates from the custom ``.msg`` texts below; the tool pose is the closed-form forward
kinematics of a planar two-link arm. Nothing here calls the converter's code to make its input.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.validate import validate

T0 = 1_700_000_000_000_000_000
L1, L2, H = 0.4, 0.3, 0.1  # link lengths and base height (m)

URDF = f"""<?xml version="1.0"?>
<robot name="planar">
  <link name="base_link"/>
  <link name="link1"/>
  <link name="link2"/>
  <link name="tool"/>
  <joint name="j1" type="revolute">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 {H}"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="{L1} 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="2"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="link2"/><child link="tool"/><origin xyz="{L2} 0 0"/>
  </joint>
</robot>
"""

CARTESIAN = """std_msgs/Header header
float64 x
float64 y
float64 z
string[] names
float64[] values
int32 mode
"""
MARKER = """string marker_name
geometry_msgs/Point translation
bool occluded
"""
MARKERS = """std_msgs/Header header
uint32 frame_number
vicon_bridge/Marker[] markers
"""


def _tip(q1: float, q2: float) -> tuple[float, float, float]:
    """Closed-form tool position of the planar arm in base_link (m)."""
    return (
        L1 * math.cos(q1) + L2 * math.cos(q1 + q2),
        L1 * math.sin(q1) + L2 * math.sin(q1 + q2),
        H,
    )


def _write_bag(path: Path, n: int = 200) -> dict[str, Any]:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    types: dict[str, Any] = {}
    types.update(get_types_from_msg(CARTESIAN, "robot_comm/msg/RobotCartesian"))
    types.update(get_types_from_msg(MARKER, "vicon_bridge/msg/Marker"))
    types.update(get_types_from_msg(MARKERS, "vicon_bridge/msg/Markers"))
    types.update(  # not in rosbags' Noetic store
        get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage")
    )
    ts.register(types)
    M = ts.types
    topics = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/tip_pose": "geometry_msgs/msg/PoseStamped",
        "/netft_data": "geometry_msgs/msg/WrenchStamped",
        "/forcetorque": "geometry_msgs/msg/WrenchStamped",
        "/robot/cartesian": "robot_comm/msg/RobotCartesian",
        "/vicon/markers": "vicon_bridge/msg/Markers",
        "/tf": "tf2_msgs/msg/TFMessage",
    }

    def header(t: int, frame: str = "") -> Any:
        stamp = M["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
        return M["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)

    def pose(p: tuple[float, float, float]) -> Any:
        return M["geometry_msgs/msg/Pose"](
            position=M["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]),
            orientation=M["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )

    def tf(t: int, parent: str, child: str, p: tuple[float, float, float]) -> Any:
        tr = M["geometry_msgs/msg/Transform"](
            translation=M["geometry_msgs/msg/Vector3"](x=p[0], y=p[1], z=p[2]),
            rotation=M["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )
        return M["geometry_msgs/msg/TransformStamped"](
            header=header(t, parent), child_frame_id=child, transform=tr
        )

    truth: dict[str, Any] = {"t": [], "tip": [], "wrench": {}, "cart": [], "markers": []}
    events: list[tuple[int, str, Any]] = []
    for i in range(n):
        t = T0 + i * 10_000_000  # 100 Hz
        q1, q2 = 0.8 * math.sin(0.05 * i), 0.6 * math.cos(0.03 * i)
        truth["t"].append(t)
        js = M["sensor_msgs/msg/JointState"](
            header=header(t),
            name=["j1", "j2"],
            position=np.array([q1, q2]),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        events.append((t + 1000, "/joint_states", js))
        tip = _tip(q1, q2)
        truth["tip"].append(tip)
        events.append(
            (
                t + 2000,
                "/tip_pose",
                M["geometry_msgs/msg/PoseStamped"](header(t, "base_link"), pose(tip)),
            )
        )
        for k, topic in enumerate(("/netft_data", "/forcetorque")):
            f = (1.0 + k + 0.01 * i, -2.0 * k, 3.0, 0.1, 0.2 * k, -0.3)
            truth["wrench"].setdefault(topic, []).append(f)
            w = M["geometry_msgs/msg/Wrench"](
                force=M["geometry_msgs/msg/Vector3"](x=f[0], y=f[1], z=f[2]),
                torque=M["geometry_msgs/msg/Vector3"](x=f[3], y=f[4], z=f[5]),
            )  # the same frame and stamps on both topics: a merged stream would repeat stamps
            events.append(
                (t + 3000 + k, topic, M["geometry_msgs/msg/WrenchStamped"](header(t, "ft"), w))
            )
        cart = (0.1 * i, -0.2, 0.3 + i, ["a", "b"], [float(i), 2.0 * i], i % 3)
        truth["cart"].append(cart)
        events.append(
            (
                t + 4000,
                "/robot/cartesian",
                M["robot_comm/msg/RobotCartesian"](
                    header(t), cart[0], cart[1], cart[2], cart[3], np.array(cart[4]), cart[5]
                ),
            )
        )
        marks = [(f"m{k}", (0.01 * i + k, float(k), 0.5), bool((i + k) % 2)) for k in range(3)]
        truth["markers"].append(marks)
        events.append(
            (
                t + 5000,
                "/vicon/markers",
                M["vicon_bridge/msg/Markers"](
                    header(t, "viconworld"),
                    i,
                    [
                        M["vicon_bridge/msg/Marker"](
                            name, M["geometry_msgs/msg/Point"](x=p[0], y=p[1], z=p[2]), occ
                        )
                        for name, p, occ in marks
                    ],
                ),
            )
        )
        box = (0.5 + 0.001 * i, 0.0, 0.02)
        tfs = [tf(t, "world", "viconworld", (0.0, 0.0, 0.0)), tf(t, "viconworld", "box", box)]
        events.append((t + 6000, "/tf", M["tf2_msgs/msg/TFMessage"](transforms=tfs)))
    events.sort(key=lambda e: e[0])
    with Writer(path) as writer:
        conns = {tp: writer.add_connection(tp, typ, typestore=ts) for tp, typ in topics.items()}
        for log, topic, msg in events:
            writer.write(conns[topic], log, ts.serialize_ros1(msg, topics[topic]))
    return truth


@pytest.fixture(scope="module")
def converted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Any, dict[str, Any], Path]:
    tmp = tmp_path_factory.mktemp("meaning")
    urdf = tmp / "planar.urdf"
    urdf.write_text(URDF)
    truth = _write_bag(tmp / "push.bag")
    ds = convert_path(tmp / "push.bag", tmp / "out", options=ConvertOptions(urdf=urdf))
    return ds, truth, tmp / "out"


def test_every_topic_is_decoded_custom_types_included(converted) -> None:
    ds, truth, _ = converted
    prov = ds.manifest["provenance"]
    dec = prov["decoded"]
    assert dec["undecodable"] == 0 and dec["ignored_topics"] == []
    assert dec["custom_types"] == ["robot_comm/msg/RobotCartesian", "vicon_bridge/msg/Markers"]
    for topic, rec in prov["topics"].items():
        assert rec["written"] == rec["messages"] == 200 or topic == "/tf", (topic, rec)
    ep = ds.episode()
    st = ep.streams["streams/robot_cartesian"]
    assert st["kind"] == "generic" and st["source"] == "/robot/cartesian"
    assert st["stamp_source"] == "sensor_header"
    rows = pq.read_table(ds.resolve(st["path"])).to_pylist()
    assert [r["t_ns"] for r in rows] == truth["t"]
    for r, (x, y, z, names, values, mode) in zip(rows, truth["cart"], strict=True):
        assert (r["x"], r["y"], r["z"], r["names"], r["values"], r["mode"]) == (
            x, y, z, names, values, mode,
        )  # fmt: skip
        assert r["header.frame_id"] == ""
    rows = pq.read_table(ds.resolve(ep.streams["streams/vicon_markers"]["path"])).to_pylist()
    for i, (r, marks) in enumerate(zip(rows, truth["markers"], strict=True)):
        assert r["frame_number"] == i
        assert r["markers.marker_name"] == [m[0] for m in marks]
        assert r["markers.translation.x"] == [m[1][0] for m in marks]
        assert r["markers.occluded"] == [m[2] for m in marks]


def test_two_wrench_topics_stay_two_streams(converted) -> None:
    ds, truth, _ = converted
    ep = ds.episode()
    assert "wrenches" not in ep.streams
    for topic, name in (("/netft_data", "netft_data"), ("/forcetorque", "forcetorque")):
        st = ep.streams[f"wrenches/{name}"]
        assert st["kind"] == "wrenches" and st["source"] == topic
        tab = pq.read_table(ds.resolve(st["path"]))
        assert tab.column("t_ns").to_pylist() == truth["t"]  # no duplicate, none dropped
        got = np.stack([tab.column(c).to_numpy() for c in ("fx", "fy", "fz", "tx", "ty", "tz")], 1)
        np.testing.assert_array_equal(got, np.array(truth["wrench"][topic]))


def test_pose_tracking_a_link_is_the_end_effector(converted) -> None:
    ds, truth, _ = converted
    ep = ds.episode()
    rec = ds.manifest["provenance"]["topics"]["/tip_pose"]
    assert rec["role"] == "ee_pose:tool" and "tracks link tool" in rec["reason"]
    tab = pq.read_table(ds.resolve(ep.streams["ee_poses"]["path"])).to_pylist()
    assert {r["link"] for r in tab} == {"tool"}
    assert [r["t_ns"] for r in tab] == truth["t"]
    np.testing.assert_allclose([[r["x"], r["y"], r["z"]] for r in tab], truth["tip"], atol=1e-12)


def test_frames_fixed_in_the_world_are_not_objects(converted) -> None:
    ds, _, _ = converted
    objects = set(ds.episode().table("object_poses").column("object").to_pylist())
    assert objects == {"box"}
    assert any("viconworld" in n and "never moves" in n for n in ds.manifest["provenance"]["notes"])


def test_output_validates(converted) -> None:
    errors = [f for f in validate(converted[2]).findings if f.severity == "error"]
    assert errors == []


def test_roles_can_be_overridden(tmp_path: Path, converted) -> None:
    src = converted[2].parent / "push.bag"
    urdf = converted[2].parent / "planar.urdf"
    opts = ConvertOptions(
        urdf=urdf,
        roles={
            "/tip_pose": "object_pose:tip",
            "/vicon/markers": "ignore",
            "/netft_data": "generic",
        },
    )
    ds = convert_path(src, tmp_path / "o", options=opts)
    ep = ds.episode()
    assert set(ep.table("object_poses").column("object").to_pylist()) == {"box", "tip"}
    assert "streams/vicon_markers" not in ep.streams
    assert ds.manifest["provenance"]["decoded"]["ignored_topics"] == ["/vicon/markers"]
    assert ep.streams["wrenches"]["source"] == "/forcetorque"
    assert ep.streams["streams/netft_data"]["kind"] == "generic"


def test_cli_prints_every_role_with_its_reason(tmp_path: Path, converted, capsys) -> None:
    from robogs.cli.main import main

    src = converted[2].parent / "push.bag"
    urdf = converted[2].parent / "planar.urdf"
    rc = main(["convert", str(src), str(tmp_path / "o"), "--urdf", str(urdf), "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 0
    lines = {ln.split()[0]: ln for ln in out.splitlines() if ln.startswith("    /")}
    assert "ee_pose:tool" in lines["/tip_pose"] and "tracks link tool" in lines["/tip_pose"]
    assert "generic" in lines["/robot/cartesian"] and "200/200" in lines["/robot/cartesian"]
    assert "wrench" in lines["/netft_data"] and "one stream per topic" in lines["/netft_data"]
    assert "decoded: 1400 messages of 7 topics, 0 undecodable; custom types: " in out


def test_link_fit_oracle(tmp_path: Path) -> None:
    """Closed-form tip paths: exact, offset along the last link, and a path of its own."""
    from robogs.convert.ingest.ee_track import link_fits, tracked_link
    from robogs.format.kinematics import Chain
    from robogs.format.urdf import load_urdf

    (tmp_path / "p.urdf").write_text(URDF)
    chain = Chain.from_urdf(load_urdf(tmp_path / "p.urdf", load_meshes=False))
    k = np.arange(300)
    t = (T0 + k * 10_000_000).astype(np.int64)
    q = np.stack([0.8 * np.sin(0.05 * k), 0.6 * np.cos(0.03 * k)], 1)
    tip = np.array([_tip(a, b) for a, b in q])
    hit = tracked_link(link_fits(chain, "base_link", t, q, t, tip))
    assert hit is not None and hit.link == "tool" and hit.rms_m < 1e-9 and hit.offset_m < 1e-9
    # 50 mm further along link2: still the arm's path, 50 mm from the nearest link origin
    ang = q.sum(1)
    far = tip + 0.05 * np.stack([np.cos(ang), np.sin(ang), 0 * ang], 1)
    hit = tracked_link(link_fits(chain, "base_link", t, q, t, far))
    assert hit is not None and hit.link == "tool" and abs(hit.offset_m - 0.05) < 1e-9
    # an object pushed along a line of its own tracks nothing
    line = np.stack([0.3 + 0.001 * k, 0.05 * np.sin(0.01 * k), 0.02 + 0 * k], 1)
    fits = link_fits(chain, "base_link", t, q, t, line)
    assert tracked_link(fits) is None and min(f.rms_m for f in fits) > 0.01

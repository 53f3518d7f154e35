"""ROS 1 and ROS 2 bags through rosbags: synthetic bags round-trip, every real bag is accounted for."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest import convert_path
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.registry import detect_format
from robogs.format.errors import InputError
from robogs.format.validate import validate


@pytest.mark.parametrize("compression", [None, "bz2", "lz4"])
def test_ros1_bag_round_trip(tmp_path: Path, synth, compression: str | None) -> None:
    sc = synth.write_ros1_bag(tmp_path / "a.bag", compression=compression)
    ds = convert_path(tmp_path / "a.bag", tmp_path / "out")
    ep = ds.episode()
    js = ep.table("joint_states").to_pydict()
    assert js["t_ns"] == sc.joint_t
    for k, j in enumerate(sc.joints):
        np.testing.assert_allclose(
            js[f"position.{j}"], [p[k] for p in sc.joint_pos], rtol=0, atol=1e-9
        )
    assert not any(c.startswith(("velocity.", "effort.")) for c in js)  # empty arrays in the bag
    assert ep.frames("cam").column("t_ns").to_pylist() == sc.image_t
    frames = list(ep.iter_video("cam"))
    assert len(frames) == len(sc.images)
    assert np.abs(frames[4].astype(float) - sc.images[4].astype(float)).mean() < 6.0
    cam = ds.camera("cam")  # ROS 1 upper-case K and D
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (40.0, 41.0, 30.5, 22.5)
    assert cam.distortion == (0.1, 0.0, 0.0, 0.0, 0.0)
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def _ros2_bag(real: Path, rel: str) -> Path:
    return real / "rosbag2" / rel


@pytest.mark.realdata
def test_real_pr2_camera_info_bag_converts(tmp_path: Path, real: Path) -> None:
    src = real / "ros1_bags/jsk_pr2eus/pr2eus/test/pr1040_camera_info.bag"
    ds = convert_path(src, tmp_path / "out")
    assert ds.camera_names == [
        "kinect_head_depth",
        "kinect_head_rgb",
        "l_forearm_cam",
        "narrow_stereo_left",
        "narrow_stereo_right",
        "prosilica",
        "r_forearm_cam",
        "wide_stereo_left",
        "wide_stereo_right",
    ]
    pro = ds.camera("prosilica")
    assert (pro.width, pro.height, pro.distortion_model, len(pro.distortion)) == (
        2448,
        2050,
        "plumb_bob",
        5,
    )
    prov = ds.manifest["provenance"]
    assert sum(t["messages"] for t in prov["topics"].values()) == 806
    assert sum(t["written"] for t in prov["topics"].values()) == 806
    assert any("T_world_cam set to identity" in n for n in prov["notes"])
    assert ds.episodes == []  # calibrations only, no time series
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["example-bz2.bag", "example-lz4.bag"])
def test_real_turtlesim_bags_without_tf_are_rejected_with_their_listing(
    tmp_path: Path, real: Path, name: str
) -> None:
    # with /tf the turtles become objects (tests/converters/test_ingest_tf.py); without it the
    # bag has nothing the format holds
    src = real / "ros1_bags/rosbag.js/fixtures" / name
    ds = convert_path(src, tmp_path / "tf")
    assert sorted(set(ds.episode().table("object_poses").column("object").to_pylist())) == [
        "turtle1",
        "turtle2",
    ]
    opts = ConvertOptions(roles={"/tf": "ignore"})
    with pytest.raises(InputError) as ei:
        convert_path(src, tmp_path / "out", options=opts)
    msg = str(ei.value)
    assert "nothing to convert" in msg and "/turtle1/pose turtlesim/msg/Pose x1344" in msg
    assert "/tf tf/msg/tfMessage x2688" in msg
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("name", "expect"),
    [
        ("example-unsorted-chunks.bag", "foo std_msgs/msg/String x3"),
        ("no-messages.bag", "topics: none"),
        ("empty-file.bag", "bag file is empty"),
    ],
)
@pytest.mark.realdata
def test_real_ros1_bags_without_content_are_rejected(
    tmp_path: Path, real: Path, name: str, expect: str
) -> None:
    with pytest.raises(InputError, match=expect):
        convert_path(real / "ros1_bags/rosbag.js/fixtures" / name, tmp_path / "out")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("rel", "expect"),
    [
        ("rosbag2_py/test/resources/mcap/talker", "/topic std_msgs/msg/String x10"),
        ("rosbag2_py/test/resources/sqlite3/talker", "/topic std_msgs/msg/String x10"),
        ("rosbag2_tests/resources/mcap/cdr_test", "/array_topic test_msgs/msg/Arrays x4"),
        ("rosbag2_tests/resources/sqlite3/cdr_test", "/test_topic test_msgs/msg/BasicTypes x3"),
        ("rosbag2_py/test/resources/mcap/wbag", "AAA std_msgs/msg/String x804"),
    ],
)
@pytest.mark.realdata
def test_real_ros2_bags_are_rejected_with_their_listing(
    tmp_path: Path, real: Path, rel: str, expect: str
) -> None:
    src = _ros2_bag(real, rel)
    assert detect_format(src).name == "ros2"
    with pytest.raises(InputError) as ei:
        convert_path(src, tmp_path / "out")
    assert "nothing to convert" in str(ei.value) and expect in str(ei.value)
    assert not (tmp_path / "out").exists()


@pytest.mark.realdata
@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_real_ros2_talker_is_read_despite_metadata_qos(real: Path, storage: str) -> None:
    """The talker's metadata.yaml QoS differs from its storage; reading the folder yields nothing."""
    from rosbags.highlevel import AnyReader

    from robogs.convert.ingest.rosbag_source import open_bag, ros2_storage_paths

    folder = _ros2_bag(real, f"rosbag2_py/test/resources/{storage}/talker")
    with AnyReader([folder]) as r:  # the trap: 20 messages listed, none delivered
        assert r.message_count == 20 and sum(1 for _ in r.messages()) == 0
    paths, facts = ros2_storage_paths(folder)
    assert facts["direct"] and facts["metadata_counts"] == {
        "/parameter_events": 0,
        "/rosout": 10,
        "/topic": 10,
    }
    reader = open_bag(paths)
    with reader:
        msgs = [(c, raw) for c, _, raw in reader.messages()]
        strings = [
            reader.deserialize(raw, c.msgtype).data for c, raw in msgs if c.topic == "/topic"
        ]
    assert len(msgs) == 20
    assert strings == [f"Hello, world! {i}" for i in range(10)]


@pytest.mark.realdata
def test_real_standalone_mcap_from_a_ros2_bag(tmp_path: Path, real: Path) -> None:
    src = _ros2_bag(real, "rosbag2_py/test/resources/mcap/talker/talker.mcap")
    assert detect_format(src).name == "mcap"
    with pytest.raises(InputError, match="/rosout rcl_interfaces/msg/Log x10"):
        convert_path(src, tmp_path / "out")

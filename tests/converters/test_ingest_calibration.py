"""Calibration files and CameraInfo messages -> CameraModel; static TF chains; roles."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from robogs.convert.ingest.calibration import camera_from_info_msg, read_calibration
from robogs.convert.ingest.roles import (
    camera_name_from_topic,
    default_role,
    load_role_map,
    parse_topic_flags,
)
from robogs.convert.ingest.tf_tree import (
    StaticTfTree,
    matrix_to_quat_np,
    pose_to_matrix,
    quat_to_matrix_np,
)
from robogs.format.errors import InputError

CAL = "camera_info"


@pytest.mark.realdata
def test_every_real_calibration_parses_or_is_rejected(real: Path) -> None:
    files = sorted(
        p.relative_to(real / CAL).as_posix()
        for p in (real / CAL).rglob("*")
        if p.suffix in (".yaml", ".yml", ".ini")
    )
    accepted = {
        "image_common/camera_calibration_parsers/test/calib5.ini": (
            "mono_left",
            640,
            480,
            "plumb_bob",
            5,
        ),
        "image_common/camera_calibration_parsers/test/calib8.ini": (
            "mono_left",
            640,
            480,
            "rational_polynomial",
            8,
        ),
        "image_common/camera_info_manager/tests/test_calibration.yaml": (
            "08144361026320a0",
            640,
            480,
            "plumb_bob",
            5,
        ),
        "opencv/samples/data/left_intrinsics.yml": ("left_intrinsics", 640, 480, "plumb_bob", 5),
    }
    rejected = {  # real cameracalibrator output: a fisheye model written as plumb_bob with 4 numbers
        "image_pipeline/camera_calibration_fisheye/fiseye_cal_reference/mono/calibrationdata/ost.yaml",
        "image_pipeline/camera_calibration_fisheye/fiseye_cal_reference/stereo/calibrationdata/left.yaml",
        "image_pipeline/camera_calibration_fisheye/fiseye_cal_reference/stereo/calibrationdata/right.yaml",
    }
    assert set(files) == set(accepted) | rejected
    for rel, (name, w, h, model, nd) in accepted.items():
        cam = read_calibration(real / CAL / rel)
        assert (cam.name, cam.width, cam.height, cam.distortion_model, len(cam.distortion)) == (
            name,
            w,
            h,
            model,
            nd,
        )
    for rel in rejected:
        with pytest.raises(InputError, match="plumb_bob needs 5 coefficients, got 4") as ei:
            read_calibration(real / CAL / rel)
        assert rel.split("/")[-1] in str(ei.value) and "equidistant" in str(ei.value)


@pytest.mark.realdata
def test_real_calibration_numbers(real: Path) -> None:
    ros = read_calibration(
        real / CAL / "image_common/camera_info_manager/tests/test_calibration.yaml"
    )
    # camera_matrix data: [1168.68, 0, 295.015, 0, 1169.01, 252.247, 0, 0, 1]; +0.5 px to robogs centres
    assert (ros.fx, ros.fy, ros.cx, ros.cy) == (1168.68, 1169.01, 295.015 + 0.5, 252.247 + 0.5)
    assert ros.distortion == (-1.04482, 1.59252, -0.0196308, 0.0287906, 0.0)
    cv = read_calibration(real / CAL / "opencv/samples/data/left_intrinsics.yml", name="left")
    assert cv.name == "left"
    assert cv.fx == cv.fy == 5.3591573396163199e02
    assert (cv.cx, cv.cy) == (3.4228315473308373e02 + 0.5, 2.3557082909788173e02 + 0.5)
    assert cv.distortion == (
        -2.6637260909660682e-01,
        -3.8588898922304653e-02,
        1.7831947042852964e-03,
        -2.8122100441115472e-04,
        2.3839153080878486e-01,
    )
    ini = read_calibration(real / CAL / "image_common/camera_calibration_parsers/test/calib8.ini")
    assert (ini.fx, ini.fy, ini.cx, ini.cy) == (
        369.344588,
        367.154330,
        320.739078 + 0.5,
        203.592450 + 0.5,
    )
    assert ini.distortion[5:] == (0.543582, -0.027892, 0.0)


def test_opencv_yaml_loader_is_safe(tmp_path: Path) -> None:
    p = tmp_path / "evil.yml"
    p.write_text("%YAML:1.0\n---\nimage_width: !!python/object/apply:os.system ['echo pwned']\n")
    with pytest.raises(InputError, match="not valid YAML"):
        read_calibration(p)


def _info(**kw) -> SimpleNamespace:
    base = dict(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=1, nanosec=2), frame_id="cam"),
        width=640,
        height=480,
        distortion_model="plumb_bob",
        d=[0.1, 0.2, 0.0, 0.0, 0.0],
        k=[500.0, 0, 319.5, 0, 501.0, 239.5, 0, 0, 1],
        p=[0.0] * 12,
        binning_x=0,
        binning_y=0,
        roi=SimpleNamespace(x_offset=0, y_offset=0, width=0, height=0),
    )
    base.update(kw)
    return SimpleNamespace(**base)


def test_camera_info_roi_and_binning() -> None:
    cam = camera_from_info_msg(
        _info(
            roi=SimpleNamespace(x_offset=100, y_offset=40, width=320, height=240),
            binning_x=2,
            binning_y=2,
        ),
        name="c",
        topic="/c/camera_info",
        t_ns=5,
    )
    # ROI first (shift the principal point), then binning (halve everything)
    assert (cam.width, cam.height) == (160, 120)
    assert (cam.fx, cam.fy) == (250.0, 250.5)
    assert (cam.cx, cam.cy) == ((319.5 - 100) / 2 + 0.5, (239.5 - 40) / 2 + 0.5)


def test_camera_info_errors_name_topic_and_stamp() -> None:
    with pytest.raises(
        InputError, match=r"topic /c/camera_info stamp 7.*rational_polynomial needs 8"
    ):
        camera_from_info_msg(
            _info(distortion_model="rational_polynomial"), name="c", topic="/c/camera_info", t_ns=7
        )
    with pytest.raises(InputError, match="skew"):
        camera_from_info_msg(
            _info(k=[500.0, 3.0, 319.5, 0, 501.0, 239.5, 0, 0, 1]), name="c", topic="/c", t_ns=1
        )
    eq = camera_from_info_msg(
        _info(distortion_model="equidistant", d=[0.1, 0.01, 0.0, 0.001]),
        name="c",
        topic="/c",
        t_ns=1,
    )
    assert eq.distortion_model == "equidistant" and len(eq.distortion) == 4


def test_numpy_quaternions_match_robogs_frames() -> None:
    from robogs.format.frames import matrix_to_quat, quat_to_matrix

    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.normal(size=4)
        R = quat_to_matrix_np(q)
        np.testing.assert_allclose(R, quat_to_matrix(q), atol=1e-14)
        np.testing.assert_allclose(matrix_to_quat_np(R), matrix_to_quat(R), atol=1e-12)
    for R in (np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])):
        np.testing.assert_allclose(quat_to_matrix_np(matrix_to_quat_np(R)), R, atol=1e-14)


def test_static_tf_chain_in_both_directions() -> None:
    rng = np.random.default_rng(4)

    def rand_T() -> np.ndarray:
        return pose_to_matrix(rng.normal(size=3), rng.normal(size=4))

    T_w_b, T_b_c, T_w_d = rand_T(), rand_T(), rand_T()
    tree = StaticTfTree()
    tree.add("world", "base", T_w_b)
    tree.add("base", "cam", T_b_c)
    tree.add("world", "desk", T_w_d)
    np.testing.assert_allclose(tree.lookup("world", "cam"), T_w_b @ T_b_c, atol=1e-12)
    np.testing.assert_allclose(
        tree.lookup("cam", "desk"), np.linalg.inv(T_w_b @ T_b_c) @ T_w_d, atol=1e-12
    )
    assert tree.lookup("world", "nowhere") is None


def test_roles_from_types_topics_and_overrides(tmp_path: Path) -> None:
    assert str(default_role("/joint_states", "sensor_msgs/JointState")[0]) == "joint_states"
    assert (
        str(default_role("/objects/box/pose", "geometry_msgs/msg/PoseStamped")[0])
        == "object_pose:box"
    )
    assert (
        str(default_role("/ee/tool0/pose", "geometry_msgs/msg/PoseStamped")[0]) == "ee_pose:tool0"
    )
    assert (
        str(default_role("/vrpn/mug/pose", "geometry_msgs/msg/PoseStamped")[0]) == "object_pose:mug"
    )
    assert str(default_role("/wrench/ft", "geometry_msgs/msg/WrenchStamped")[0]) == "wrench:ft"
    assert str(default_role("/tf_static", "tf2_msgs/msg/TFMessage")[0]) == "tf_static"
    role, why = default_role("/cam/depth/image_raw", "sensor_msgs/msg/Image")
    assert role.kind == "generic" and "depth" in why
    assert camera_name_from_topic("/camera/cam0/image_raw/compressed") == "cam0"
    assert camera_name_from_topic("/kinect_head/rgb/camera_info") == "kinect_head_rgb"
    m = tmp_path / "roles.yaml"
    m.write_text("topics:\n  /mocap/a: object_pose:mug\n  /rosout: ignore\n")
    assert {k: str(v) for k, v in load_role_map(m).items()} == {
        "/mocap/a": "object_pose:mug",
        "/rosout": "ignore",
    }
    assert str(parse_topic_flags(["ee_pose:tool0=/x"])["/x"]) == "ee_pose:tool0"
    with pytest.raises(InputError, match="unknown role"):
        parse_topic_flags(["pose=/x"])
    with pytest.raises(InputError, match="ROLE=TOPIC"):
        parse_topic_flags(["/x"])

"""Small valid inputs for every reader, the starting points of the fuzz targets.

Each seed is written by a third-party writer (``mcap_ros2.writer``, ``rosbags``, OpenCV,
trimesh, PyYAML, pyarrow) or by hand, never by the robogs reader it feeds; the dataset seed
is the synthetic scene of :mod:`robogs.synth.scene`. Seeds are built once per session
(:func:`build_seeds`) and never modified: a fuzz case copies what it mutates.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Seeds", "build_seeds", "TINY_URDF", "JOINTS", "T0"]

T0 = 1_700_000_000_000_000_000  # ns
JOINTS = ("j1", "j2")

TINY_URDF = """<?xml version="1.0"?>
<robot name="tiny">
  <link name="base">
    <inertial><mass value="1.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <visual><geometry><mesh filename="meshes/base.stl"/></geometry></visual>
  </link>
  <link name="l1">
    <inertial><origin xyz="0 0 0.1"/><mass value="0.5"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial>
    <visual><geometry><box size="0.05 0.05 0.2"/></geometry></visual>
  </link>
  <link name="l2">
    <inertial><origin xyz="0 0 0.1"/><mass value="0.3"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.0005"/></inertial>
    <visual><geometry><cylinder radius="0.02" length="0.2"/></geometry></visual>
  </link>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/><origin xyz="0 0 0.05" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2" rpy="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="5" velocity="2"/>
  </joint>
</robot>
"""


@dataclass(frozen=True)
class Seeds:
    """Paths of the seed inputs (all under one session folder)."""

    root: Path
    dataset: Path
    urdf: Path
    mcaps: tuple[Path, ...]
    bags: tuple[Path, ...]
    ros2_bag: Path
    videos: tuple[Path, ...]
    calibrations: tuple[Path, ...]
    stamps: Path
    logs: tuple[Path, ...]
    meshes: tuple[Path, ...]


def _stl_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """Binary STL written by hand: 80-byte header, uint32 count, 50 bytes per triangle."""
    out = [b"robogs seed".ljust(80, b" "), struct.pack("<I", len(faces))]
    for f in faces:
        tri = vertices[f]
        n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        n = n / (np.linalg.norm(n) or 1.0)
        out.append(struct.pack("<12fH", *n, *tri.reshape(-1), 0))
    return b"".join(out)


def _box() -> tuple[np.ndarray, np.ndarray]:
    v = np.array([[x, y, z] for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (0.0, 0.1)])
    f = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )  # fmt: skip
    return v, f


def _write_robot(root: Path) -> Path:
    (root / "robot" / "meshes").mkdir(parents=True)
    v, f = _box()
    (root / "robot" / "meshes" / "base.stl").write_bytes(_stl_bytes(v, f))
    path = root / "robot" / "robot.urdf"
    path.write_text(TINY_URDF)
    return path


def _msgdef(msgtype: str, ros_version: int = 2) -> str:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE if ros_version == 2 else Stores.ROS1_NOETIC)
    return store.generate_msgdef(msgtype, ros_version=ros_version)[0]


def _stamp(t: int) -> dict[str, int]:
    return {"sec": t // 1_000_000_000, "nanosec": t % 1_000_000_000}


def _png(i: int) -> bytes:
    import cv2

    img = np.full((12, 16, 3), 60 + 20 * i, np.uint8)
    ok, buf = cv2.imencode(".png", img)
    assert ok
    return buf.tobytes()


def _write_mcap(path: Path, compression: str, crcs: bool = True) -> None:
    """A ROS 2 MCAP: 12 JointStates, 3 compressed images + CameraInfo, /tf_static, a pose.

    Without CRCs, byte damage reaches the record parsers instead of stopping at a checksum.
    """
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer

    types = {
        "/joint_states": "sensor_msgs/msg/JointState",
        "/cam/image_raw/compressed": "sensor_msgs/msg/CompressedImage",
        "/cam/camera_info": "sensor_msgs/msg/CameraInfo",
        "/tf_static": "tf2_msgs/msg/TFMessage",
        "/box/pose": "geometry_msgs/msg/PoseStamped",
    }
    events = []
    for i in range(12):
        t = T0 + i * 10_000_000
        msg = {
            "header": {"stamp": _stamp(t), "frame_id": ""},
            "name": list(JOINTS),
            "position": [0.1 * i, -0.05 * i],
            "velocity": [0.1, -0.05],
            "effort": [0.0, 0.0],
        }
        events.append((t, "/joint_states", msg))
    for i in range(3):
        t = T0 + 5_000_000 + i * 33_000_000
        hdr = {"stamp": _stamp(t), "frame_id": "cam_optical"}
        events.append(
            (t, "/cam/image_raw/compressed", {"header": hdr, "format": "png", "data": _png(i)})
        )
        info = {
            "header": hdr,
            "height": 12,
            "width": 16,
            "distortion_model": "plumb_bob",
            "d": [0.01, -0.02, 0.0, 0.0, 0.0],
            "k": [20.0, 0.0, 8.0, 0.0, 20.0, 6.0, 0.0, 0.0, 1.0],
            "r": [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0],
            "p": [20.0, 0, 8.0, 0, 0, 20.0, 6.0, 0, 0, 0, 1.0, 0],
            "binning_x": 0,
            "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        }
        events.append((t, "/cam/camera_info", info))
    tf = {
        "transforms": [
            {
                "header": {"stamp": _stamp(T0), "frame_id": "world"},
                "child_frame_id": "cam_optical",
                "transform": {
                    "translation": {"x": 0.4, "y": 0.0, "z": 1.0},
                    "rotation": {"x": 1.0, "y": 0.0, "z": 0.0, "w": 0.0},
                },
            }
        ]
    }
    events.append((T0, "/tf_static", tf))
    for i in range(4):
        t = T0 + 2_000_000 + i * 25_000_000
        pose = {
            "header": {"stamp": _stamp(t), "frame_id": "world"},
            "pose": {
                "position": {"x": 0.3, "y": 0.01 * i, "z": 0.03},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
        }
        events.append((t, "/box/pose", pose))
    events.sort(key=lambda e: e[0])
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
    with open(path, "wb") as fh:
        writer = Writer(fh, chunk_size=4096, compression=comp[compression], enable_crcs=crcs)
        schemas = {typ: writer.register_msgdef(typ, _msgdef(typ)) for typ in set(types.values())}
        for t, topic, msg in events:
            writer.write_message(topic, schemas[types[topic]], msg, log_time=t, publish_time=t)
        writer.finish()


def _ros1_messages():
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    M = ts.types

    def header(t: int, frame: str = "") -> object:
        return M["std_msgs/msg/Header"](
            seq=0,
            stamp=M["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9),
            frame_id=frame,
        )

    out = []
    for i in range(10):
        t = T0 + i * 10_000_000
        msg = M["sensor_msgs/msg/JointState"](
            header=header(t),
            name=list(JOINTS),
            position=np.array([0.1 * i, 0.2]),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        out.append((t, "/joint_states", "sensor_msgs/msg/JointState", msg))
    for i in range(2):
        t = T0 + 3_000_000 + i * 40_000_000
        img = np.full(12 * 16 * 3, 100 + i, np.uint8)
        msg = M["sensor_msgs/msg/Image"](
            header=header(t, "cam_optical"),
            height=12,
            width=16,
            encoding="rgb8",
            is_bigendian=0,
            step=48,
            data=img,
        )
        out.append((t, "/cam/image_raw", "sensor_msgs/msg/Image", msg))
    return ts, out


def _write_ros1(path: Path, compression: str | None) -> None:
    from rosbags.rosbag1 import Writer

    ts, events = _ros1_messages()
    writer = Writer(path)
    if compression:
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer:
        conns = {}
        for _, topic, typ, _ in events:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, typ, typestore=ts)
        for t, topic, typ, msg in events:
            writer.write(conns[topic], t, ts.serialize_ros1(msg, typ))


def _write_ros2(path: Path) -> None:
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    M = ts.types
    with Writer(path, version=8) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for i in range(10):
            t = T0 + i * 10_000_000
            msg = M["sensor_msgs/msg/JointState"](
                header=M["std_msgs/msg/Header"](
                    stamp=M["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9),
                    frame_id="",
                ),
                name=list(JOINTS),
                position=np.array([0.1 * i, 0.2]),
                velocity=np.zeros(0),
                effort=np.zeros(0),
            )
            writer.write(conn, t, ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))


def _write_videos(root: Path) -> tuple[Path, ...]:
    import cv2

    out = []
    for name, fourcc in (("v.mp4", "mp4v"), ("v.avi", "MJPG")):
        path = root / name
        vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10.0, (16, 12))
        for i in range(4):
            frame = np.zeros((12, 16, 3), np.uint8)
            frame[:, : 4 * (i + 1)] = (40 * i, 200, 90)
            vw.write(frame)
        vw.release()
        assert path.stat().st_size > 0, path
        out.append(path)
    return tuple(out)


def _write_calibrations(root: Path) -> tuple[Path, ...]:
    import yaml

    ros = {
        "image_width": 16,
        "image_height": 12,
        "camera_name": "cam0",
        "camera_matrix": {"rows": 3, "cols": 3, "data": [20.0, 0, 8.0, 0, 20.0, 6.0, 0, 0, 1]},
        "distortion_model": "plumb_bob",
        "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.01, -0.02, 0, 0, 0]},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": [1, 0, 0, 0, 1, 0, 0, 0, 1]},
        "projection_matrix": {
            "rows": 3,
            "cols": 4,
            "data": [20.0, 0, 8.0, 0, 0, 20.0, 6.0, 0, 0, 0, 1, 0],
        },
    }
    p_ros = root / "cam_ros.yaml"
    p_ros.write_text(yaml.safe_dump(ros, sort_keys=False))
    p_cv = root / "cam_opencv.yaml"
    p_cv.write_text(
        "%YAML:1.0\n---\nimage_width: 16\nimage_height: 12\n"
        "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 20., 0., 8., 0., 20., 6., 0., 0., 1. ]\n"
        "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
        "   data: [ 0.01, -0.02, 0., 0., 0. ]\n"
    )
    p_ini = root / "cam.ini"
    p_ini.write_text(
        "# oST version 5.0 parameters\n\n[image]\n\nwidth\n16\n\nheight\n12\n\n[cam0]\n\n"
        "camera matrix\n20.0 0 8.0\n0 20.0 6.0\n0 0 1\n\n"
        "distortion\n0.01 -0.02 0 0 0\n\n"
        "rectification\n1 0 0\n0 1 0\n0 0 1\n\n"
        "projection\n20.0 0 8.0 0\n0 20.0 6.0 0\n0 0 1 0\n"
    )
    return p_ros, p_cv, p_ini


def _write_logs(root: Path) -> tuple[Path, ...]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 40
    t = T0 + np.arange(n, dtype=np.int64) * 8_000_000
    q1, q2 = 0.5 * np.sin(np.arange(n) * 0.1), 0.3 * np.cos(np.arange(n) * 0.1)
    lines = ["t_ns,position.j1,position.j2,velocity.j1,velocity.j2"]
    lines += [f"{t[i]},{q1[i]:.6f},{q2[i]:.6f},0.05,-0.03" for i in range(n)]
    p_csv = root / "log.csv"
    p_csv.write_text("\n".join(lines) + "\n")
    p_pq = root / "log.parquet"
    pq.write_table(
        pa.table({"time": (t - T0) / 1e9, "q0": q1, "q1": q2, "dq0": q1 * 0, "dq1": q2 * 0}), p_pq
    )
    return p_csv, p_pq


def _write_meshes(root: Path) -> tuple[Path, ...]:
    import trimesh

    v, f = _box()
    mesh = trimesh.Trimesh(v, f, process=False)
    folder = root / "meshes"
    folder.mkdir()
    out = []
    for name, kwargs in (
        ("box.obj", {}),
        ("box.ply", {"encoding": "ascii"}),
        ("box.stl", {}),
        ("box.dae", {}),
        ("box.glb", {}),
    ):
        path = folder / name
        data = mesh.export(file_type=name.rsplit(".", 1)[1], **kwargs)
        path.write_bytes(data.encode() if isinstance(data, str) else data)
        out.append(path)
    return tuple(out)


def build_seeds(root: Path) -> Seeds:
    """Write every seed under ``root`` (an empty folder) and return their paths."""
    from robogs.synth.scene import synthesize

    root.mkdir(parents=True, exist_ok=True)
    dataset = root / "ds"
    synthesize(dataset, seed=0, size="small", progress=False)
    urdf = _write_robot(root)
    mcaps = []
    for comp in ("zstd", "lz4", "none"):
        p = root / f"a_{comp}.mcap"
        _write_mcap(p, comp)
        mcaps.append(p)
    for comp in ("zstd", "none"):
        p = root / f"nocrc_{comp}.mcap"
        _write_mcap(p, comp, crcs=False)
        mcaps.append(p)
    bags = []
    for comp in (None, "bz2", "lz4"):
        p = root / f"a_{comp or 'none'}.bag"
        _write_ros1(p, comp)
        bags.append(p)
    ros2 = root / "r2"
    _write_ros2(ros2)
    stamps = root / "stamps.csv"
    stamps.write_text(
        "frame_index,t_ns\n" + "".join(f"{i},{T0 + i * 100_000_000}\n" for i in range(4))
    )
    return Seeds(
        root=root,
        dataset=dataset,
        urdf=urdf,
        mcaps=tuple(mcaps),
        bags=tuple(bags),
        ros2_bag=ros2,
        videos=_write_videos(root),
        calibrations=_write_calibrations(root),
        stamps=stamps,
        logs=_write_logs(root),
        meshes=_write_meshes(root),
    )

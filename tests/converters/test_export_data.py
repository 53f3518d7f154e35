"""A tiny, fully specified dataset for the export tests, built with the dataset writer.

The robot has three links with inertials (one with a rotated inertial frame and off-diagonal
inertia), a revolute and a prismatic joint with limits, STL/PLY meshes and one box primitive.
physics.json holds joint dynamics, a rigid box and a static table; the episode has joint
states, object/end-effector poses, wrenches, 2D/3D boxes, segments and one camera with a
4-frame mp4 and label PNGs. Stamps are irregular and epoch-sized so that sec/nanosec splits
and float conversions are exercised.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import trimesh

from robogs.format import Dataset
from robogs.format.cameras import CameraModel
from robogs.format.images import VideoWriter, encode_label_png
from robogs.format.splats import SplatSet

T0_NS = 1_700_000_000_123_456_789

URDF = """<?xml version="1.0"?>
<robot name="tiny_arm">
  <link name="base_link">
    <inertial>
      <origin xyz="0 0 0.05" rpy="0 0 0"/>
      <mass value="2.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.008"/>
    </inertial>
    <visual><geometry><mesh filename="meshes/base.stl"/></geometry></visual>
    <collision><geometry><mesh filename="meshes/base.stl"/></geometry></collision>
  </link>
  <link name="link1">
    <inertial>
      <origin xyz="0.01 0.0 0.1" rpy="0.1 0.2 0.3"/>
      <mass value="1.0"/>
      <inertia ixx="0.004" ixy="0.0005" ixz="-0.0002" iyy="0.005" iyz="0.0003" izz="0.003"/>
    </inertial>
    <visual>
      <origin xyz="0 0 0.1" rpy="0 0 0"/>
      <geometry><mesh filename="meshes/link1.ply"/></geometry>
    </visual>
  </link>
  <link name="link2">
    <inertial>
      <origin xyz="0.05 0 0" rpy="0 0 0"/>
      <mass value="0.3"/>
      <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0004"/>
    </inertial>
    <visual>
      <origin xyz="0.05 0 0" rpy="0 0 0"/>
      <geometry><box size="0.1 0.04 0.04"/></geometry>
    </visual>
    <collision>
      <origin xyz="0.05 0 0" rpy="0 0 0"/>
      <geometry><box size="0.1 0.04 0.04"/></geometry>
    </collision>
  </link>
  <link name="tool"/>
  <joint name="j1" type="revolute">
    <parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-2.0" upper="2.5" effort="10" velocity="2"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="0 0 0.2" rpy="0 0 0.3"/>
    <axis xyz="1 0 0"/>
    <limit lower="0.0" upper="0.12" effort="50" velocity="0.5"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="link2"/><child link="tool"/>
    <origin xyz="0.1 0 0" rpy="0 0 0"/>
  </joint>
</robot>
"""

PHYSICS = {
    "gravity_mps2": [0.0, 0.0, -9.81],
    "objects": {
        "box": {
            "equation": "rigid",
            "mass_kg": 0.5,
            "com_m": [0.001, -0.002, 0.003],
            "inertia_kgm2": [
                [2.0e-4, 1.0e-5, 0.0],
                [1.0e-5, 3.0e-4, -2.0e-5],
                [0.0, -2.0e-5, 2.5e-4],
            ],
            "friction_static": 0.6,
            "friction_dynamic": 0.45,
            "restitution": 0.15,
            "damping_linear": 0.0,
            "damping_angular": 0.0,
        },
        "table": {
            "equation": "static",
            "friction_static": 0.8,
            "friction_dynamic": 0.7,
            "restitution": 0.05,
        },
        "link1": {
            "equation": "articulated",
            "friction_static": 0.9,
            "friction_dynamic": 0.85,
            "restitution": 0.0,
        },
    },
    "joints": {
        "j1": {"damping": 0.12, "friction": 0.05, "armature": 0.01},
        "j2": {"damping": 2.5, "friction": 0.4},
    },
    "effects": [],
    "sensors": {"cam0": {"time_offset_ns": 0}},
}

N_JS = 60
N_POSE = 12
N_FRAMES = 4
CAM_W, CAM_H = 32, 24


def _stamps(n: int, period_ns: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (
        T0_NS + np.cumsum(period_ns + rng.integers(-period_ns // 10, period_ns // 10, n))
    ).astype(np.int64)


def _quat_z(angle: np.ndarray) -> np.ndarray:
    return np.stack([np.cos(angle / 2), 0 * angle, 0 * angle, np.sin(angle / 2)], axis=-1)


def _pose_table(key: str, names: list[str], t: np.ndarray, seed: int) -> pa.Table:
    rng = np.random.default_rng(seed)
    n = len(t)
    cols: dict[str, list] = {c: [] for c in ("t_ns", key, "x", "y", "z", "qw", "qx", "qy", "qz")}
    for i in range(n):
        for k, name in enumerate(names):
            q = _quat_z(np.array(0.1 * i + k)) + rng.normal(0, 0.05, 4)
            q /= np.linalg.norm(q)
            p = np.array([0.3 + 0.01 * i, 0.1 * k, 0.05]) + rng.normal(0, 1e-3, 3)
            for c, v in zip(
                ("t_ns", key, "x", "y", "z", "qw", "qx", "qy", "qz"),
                (t[i], name, *p, *q),
                strict=True,
            ):
                cols[c].append(v)
    return pa.table(
        {
            "t_ns": pa.array(cols["t_ns"], pa.int64()),
            key: pa.array(cols[key], pa.string()),
            **{c: pa.array(cols[c], pa.float64()) for c in ("x", "y", "z", "qw", "qx", "qy", "qz")},
        }
    )


def _splats(n: int, targets: int, kind: str, sh_k: int, seed: int, centre: np.ndarray) -> SplatSet:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4)).astype(np.float32)
    return SplatSet(
        means=(centre + rng.normal(0, 0.03, (n, 3))).astype(np.float32),
        quats=q,
        log_scales=rng.uniform(-6, -4, (n, 3 if kind == "3dgs" else 2)).astype(np.float32),
        opacity_logits=rng.normal(size=n).astype(np.float32),
        sh=rng.normal(0, 0.3, (n, sh_k, 3)).astype(np.float32),
        bind_id=rng.integers(0, targets, n).astype(np.int32),
        bind_face=rng.integers(0, 10, n).astype(np.int32),
        bind_uv=rng.uniform(0, 0.5, (n, 2)).astype(np.float32),
        bind_offset=rng.normal(0, 1e-3, n).astype(np.float32),
    )


def build_tiny_dataset(root: Path) -> Dataset:
    """Write the tiny dataset at ``root`` (must not exist) and return it opened."""
    tmp_meshes = root.parent / f"{root.name}-src"
    tmp_meshes.mkdir(parents=True, exist_ok=True)
    base = trimesh.creation.box((0.2, 0.2, 0.1))
    base.apply_translation((0, 0, 0.05))
    base.export(tmp_meshes / "base.stl")
    trimesh.creation.cylinder(radius=0.03, height=0.2, sections=12).export(tmp_meshes / "link1.ply")
    trimesh.creation.box((0.05, 0.05, 0.05)).export(tmp_meshes / "box.ply")
    table = trimesh.creation.box((1.0, 1.0, 0.02))
    table.apply_translation((0.4, 0, -0.01))
    table.export(tmp_meshes / "table.ply")

    w = Dataset.create(root)
    w.write_text("robot/robot.urdf", URDF)
    w.copy_file("robot/meshes/base.stl", tmp_meshes / "base.stl")
    w.copy_file("robot/meshes/link1.ply", tmp_meshes / "link1.ply")
    w.copy_file("assets/box/mesh.ply", tmp_meshes / "box.ply")
    w.copy_file("assets/table/mesh.ply", tmp_meshes / "table.ply")
    w.set_robot("robot/robot.urdf", base_link="base_link", ee_link="tool")
    w.set_physics(PHYSICS)

    links = ["base_link", "link1", "link2", "tool"]
    w.write_splats(
        "robot/splats.ply", _splats(300, len(links), "3dgs", 4, 1, np.array([0.0, 0.0, 0.2]))
    )
    w.manifest["robot"]["splats"] = {
        "path": "robot/splats.ply",
        "kind": "3dgs",
        "sh_degree": 1,
        "targets": links,
        "rest": {"t_ns": int(T0_NS), "joint_positions": {"j1": 0.0, "j2": 0.0}},
    }
    w.write_splats(
        "assets/box/splats.ply", _splats(80, 1, "2dgs", 1, 2, np.array([0.3, 0.0, 0.05]))
    )
    w.set_asset(
        "box",
        kind="object",
        mesh="assets/box/mesh.ply",
        splats={
            "path": "assets/box/splats.ply",
            "kind": "2dgs",
            "sh_degree": 0,
            "targets": ["box"],
            "rest": {
                "t_ns": int(T0_NS),
                "object_poses": {"box": [0.3, 0.0, 0.05, 1.0, 0.0, 0.0, 0.0]},
            },
        },
    )
    w.set_asset("table", kind="table", mesh="assets/table/mesh.ply")

    R = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]).T  # camera looking along +x
    T_world_cam = np.eye(4)
    T_world_cam[:3, :3] = R
    T_world_cam[:3, 3] = (-0.8, 0.05, 0.3)
    w.set_camera(
        CameraModel(
            "cam0",
            CAM_W,
            CAM_H,
            30.0,
            31.0,
            16.2,
            11.8,
            distortion_model="plumb_bob",
            distortion=(0.01, -0.02, 0.001, 0.0005, 0.003),
            T_world_cam=T_world_cam,
        )
    )

    ep = "episodes/ep000"
    t_js = _stamps(N_JS, 10_000_000, 3)
    rng = np.random.default_rng(4)
    phase = np.linspace(0, 2 * np.pi, N_JS)
    js = pa.table(
        {
            "t_ns": pa.array(t_js, pa.int64()),
            "position.j1": 0.8 * np.sin(phase),
            "position.j2": 0.05 + 0.04 * np.sin(2 * phase),
            "velocity.j1": 0.8 * np.cos(phase) * 2 * np.pi / 0.6,
            "velocity.j2": 0.08 * np.cos(2 * phase) * 2 * np.pi / 0.6,
            "effort.j1": rng.normal(0, 1, N_JS),
            "effort.j2": rng.normal(0, 5, N_JS),
        }
    )
    w.write_table(f"{ep}/joint_states.parquet", js, kind="joint_states")
    t_pose = _stamps(N_POSE, 50_000_000, 5)
    w.write_table(
        f"{ep}/object_poses.parquet", _pose_table("object", ["box"], t_pose, 6), kind="object_poses"
    )
    w.write_table(
        f"{ep}/ee_poses.parquet", _pose_table("link", ["tool"], t_pose, 7), kind="ee_poses"
    )
    wr = {
        "t_ns": pa.array(t_pose, pa.int64()),
        "frame": pa.array(["tool"] * N_POSE, pa.string()),
        **{
            c: pa.array(rng.normal(0, 2, N_POSE), pa.float64())
            for c in ("fx", "fy", "fz", "tx", "ty", "tz")
        },
    }
    w.write_table(f"{ep}/wrenches.parquet", pa.table(wr), kind="wrenches")
    b3 = _pose_table("object", ["box"], t_pose, 8)
    for c in ("size_x", "size_y", "size_z"):
        b3 = b3.append_column(c, pa.array(np.full(N_POSE, 0.05), pa.float64()))
    w.write_table(f"{ep}/boxes3d.parquet", b3, kind="boxes3d")
    seg = pa.table(
        {
            "label_id": pa.array([1, 2, 3, 4], pa.int32()),
            "category": pa.array(["robot", "robot", "box", "table"], pa.string()),
            "instance": pa.array([0, 1, 0, 0], pa.int32()),
            "kind": pa.array(["robot_link", "robot_link", "object", "background"], pa.string()),
            "target": pa.array(["link1", "link2", "box", ""], pa.string()),
        }
    )
    w.write_table(f"{ep}/segments.parquet", seg, kind="segments")

    t_frames = _stamps(N_FRAMES, 33_333_333, 9)
    frames = pa.table(
        {
            "t_ns": pa.array(t_frames, pa.int64()),
            "frame_index": pa.array(range(N_FRAMES), pa.int64()),
        }
    )
    w.write_table(f"{ep}/cameras/cam0/frames.parquet", frames, kind="camera_frames")
    with VideoWriter(w.path(f"{ep}/cameras/cam0/rgb.mp4"), CAM_W, CAM_H, 30.0) as vw:
        for i in range(N_FRAMES):
            img = np.zeros((CAM_H, CAM_W, 3), np.uint8)
            img[:, :, 0] = 40 * i
            img[4:12, 6 + i : 14 + i, 1] = 200
            vw.write(img)
    pngs, b2 = (
        [],
        {
            c: []
            for c in (
                "t_ns",
                "camera",
                "frame_index",
                "label_id",
                "x_min",
                "y_min",
                "x_max",
                "y_max",
            )
        },
    )
    for i in range(N_FRAMES):
        lab = np.zeros((CAM_H, CAM_W), np.uint16)
        lab[4:12, 6 + i : 14 + i] = 3
        lab[16:, :] = 4
        pngs.append(encode_label_png(lab))
        for c, v in zip(b2, (t_frames[i], "cam0", i, 3, 6.0 + i, 4.0, 14.0 + i, 12.0), strict=True):
            b2[c].append(v)
    labels = pa.table(
        {"frame_index": pa.array(range(N_FRAMES), pa.int64()), "png": pa.array(pngs, pa.binary())}
    )
    w.write_table(f"{ep}/cameras/cam0/labels.parquet", labels, kind="camera_labels")
    boxes2d = pa.table(
        {
            "t_ns": pa.array(b2["t_ns"], pa.int64()),
            "camera": pa.array(b2["camera"], pa.string()),
            "frame_index": pa.array(b2["frame_index"], pa.int64()),
            "label_id": pa.array(b2["label_id"], pa.int32()),
            **{c: pa.array(b2[c], pa.float64()) for c in ("x_min", "y_min", "x_max", "y_max")},
        }
    )
    w.write_table(f"{ep}/boxes2d.parquet", boxes2d, kind="boxes2d")

    def s(kind: str, path: str, **extra: object) -> dict:
        return {"kind": kind, "path": path, "stamp_source": "synthetic", "offset_ns": 0, **extra}

    streams = {
        "joint_states": s("joint_states", f"{ep}/joint_states.parquet", nominal_rate_hz=100.0),
        "object_poses": s("object_poses", f"{ep}/object_poses.parquet"),
        "ee_poses": s("ee_poses", f"{ep}/ee_poses.parquet"),
        "wrenches": s("wrenches", f"{ep}/wrenches.parquet"),
        "boxes3d": s("boxes3d", f"{ep}/boxes3d.parquet"),
        "boxes2d": s("boxes2d", f"{ep}/boxes2d.parquet"),
        "segments": s("segments", f"{ep}/segments.parquet"),
        "camera/cam0": {
            "kind": "camera",
            "camera": "cam0",
            "frames": f"{ep}/cameras/cam0/frames.parquet",
            "video": f"{ep}/cameras/cam0/rgb.mp4",
            "labels": f"{ep}/cameras/cam0/labels.parquet",
            "stamp_source": "synthetic",
            "offset_ns": 0,
        },
    }
    start = int(min(t_js[0], t_pose[0], t_frames[0]))
    end = int(max(t_js[-1], t_pose[-1], t_frames[-1]))
    w.add_episode("ep000", start_ns=start, end_ns=end, streams=streams)
    return w.commit()


def same_table(a: pa.Table, b: pa.Table, what: str) -> None:
    """Same rows, identical stamps, float columns within 1e-9, other columns identical."""
    assert a.num_rows == b.num_rows, what
    assert a.column("t_ns").to_pylist() == b.column("t_ns").to_pylist(), f"{what}: stamps differ"
    for name in a.column_names:
        if name == "t_ns":
            continue
        col_a, col_b = a.column(name), b.column(name)
        if pa.types.is_floating(col_a.type):
            np.testing.assert_allclose(
                col_b.to_numpy(), col_a.to_numpy(), rtol=0, atol=1e-9, err_msg=f"{what}.{name}"
            )
        else:
            assert col_a.to_pylist() == col_b.to_pylist(), f"{what}.{name}"


def mcap_round_trip(src: Dataset, tmp: Path) -> Dataset:
    """Export ``src`` to MCAP and read it back with robogs' MCAP ingest."""
    from robogs.convert.export import export
    from robogs.convert.ingest.convert import convert_path

    export("mcap", src, tmp / "x.mcap")
    return convert_path(tmp / "x.mcap", tmp / "back")


def check_round_trip(src: Dataset, back: Dataset) -> None:
    """Tables equal (stamps exactly, values within 1e-9), cameras and labels equal."""
    a, b = src.episode(), back.episode()
    for stream in ("joint_states", "object_poses", "ee_poses", "wrenches"):
        if a.has(stream):
            same_table(
                a.table(stream), b.table(stream).select(a.table(stream).column_names), stream
            )
    for cam in src.camera_names:
        ca, cb = src.camera(cam), back.camera(cam)
        np.testing.assert_allclose(cb.K, ca.K, atol=1e-9)
        np.testing.assert_allclose(cb.T_world_cam, ca.T_world_cam, atol=1e-9)
        assert (cb.width, cb.height) == (ca.width, ca.height)
        da = np.zeros(5) if ca.distortion_model == "none" else np.asarray(ca.distortion)
        np.testing.assert_allclose(
            np.asarray(cb.distortion) if cb.distortion else np.zeros(5), da, atol=1e-12
        )
        assert a.frames(cam).column("t_ns").to_pylist() == b.frames(cam).column("t_ns").to_pylist()
        for (ia, la), (ib, lb) in zip(a.iter_labels(cam), b.iter_labels(cam), strict=True):
            assert ia == ib and np.array_equal(la, lb)


def test_tiny_dataset_reads_back(tmp_path: Path) -> None:
    ds = build_tiny_dataset(tmp_path / "tiny")
    ep = ds.episode()
    assert ep.table("joint_states").num_rows == N_JS
    assert sorted(ds.urdf(load_meshes=True).joint_map) == ["j1", "j2", "tool_joint"]
    assert len(list(ep.iter_labels("cam0"))) == N_FRAMES
    assert sum(1 for _ in ep.iter_video("cam0")) == N_FRAMES

"""The tiny scene: a small dataset written with the dataset writer, for the validator tests.

A two-joint planar arm on a table, a box sliding in front of it, one camera
looking down at 10 fps, with labels, 2D/3D boxes and physics. Every derived
quantity comes from closed-form expressions written here (planar forward
kinematics, pinhole projection of boxes), never from the code under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import trimesh

from robogs.format import Dataset
from robogs.format.cameras import CameraModel
from robogs.format.images import VideoWriter, encode_label_png

T0 = 1_000_000_000
DURATION_S = 4.0
JOINT_HZ = 100.0
EE_HZ = 50.0
CAM_HZ = 10.0
L1, L2, BASE_Z = 0.30, 0.25, 0.10
BOX = (0.10, 0.08, 0.06)
TABLE = (1.0, 1.0, 0.04)
TABLE_CENTER = (0.3, 0.0, -0.02)
W, H, F = 160, 120, 100.0
CAM_Z = 1.5
LABEL_BOX, LABEL_TABLE = 100, 200


def _box_inertia(m: float, size: tuple[float, float, float]) -> np.ndarray:
    x, y, z = size
    return np.diag([m * (y * y + z * z), m * (x * x + z * z), m * (x * x + y * y)]) / 12.0


def _inertial_xml(
    m: float, com: tuple[float, float, float], size: tuple[float, float, float]
) -> str:
    inertia = _box_inertia(m, size)
    return (
        f'<inertial><origin xyz="{com[0]} {com[1]} {com[2]}" rpy="0 0 0"/><mass value="{m}"/>'
        f'<inertia ixx="{inertia[0, 0]}" ixy="0" ixz="0" iyy="{inertia[1, 1]}" iyz="0" izz="{inertia[2, 2]}"/>'
        "</inertial>"
    )


def _urdf() -> str:
    def link(
        name: str,
        mesh: str,
        m: float,
        com: tuple[float, float, float],
        size: tuple[float, float, float],
    ) -> str:
        geom = f'<geometry><mesh filename="{mesh}"/></geometry>'
        return (
            f'<link name="{name}">{_inertial_xml(m, com, size)}<visual>{geom}</visual>'
            f"<collision>{geom}</collision></link>"
        )

    return f"""<?xml version="1.0"?>
<robot name="planar2r">
  {link("base_link", "meshes/base.stl", 2.0, (0.0, 0.0, 0.05), (0.1, 0.1, 0.1))}
  {link("link1", "meshes/link1.stl", 1.0, (L1 / 2, 0.0, 0.0), (L1, 0.04, 0.04))}
  {link("link2", "meshes/link2.stl", 0.8, (L2 / 2, 0.0, 0.0), (L2, 0.04, 0.04))}
  <link name="tool0"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="link1"/>
    <origin xyz="0 0 {BASE_Z}" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.9" upper="2.9" effort="50" velocity="3"/></joint>
  <joint name="j2" type="revolute"><parent link="link1"/><child link="link2"/>
    <origin xyz="{L1} 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2.5" upper="2.5" effort="30" velocity="3"/></joint>
  <joint name="tool" type="fixed"><parent link="link2"/><child link="tool0"/>
    <origin xyz="{L2} 0 0" rpy="0 0 0"/></joint>
</robot>
"""


def _stl(size: tuple[float, float, float], center: tuple[float, float, float]) -> bytes:
    mesh = trimesh.creation.box(extents=size)
    mesh.apply_translation(center)
    return mesh.export(file_type="stl")


def _ply(size: tuple[float, float, float]) -> bytes:
    return trimesh.creation.box(extents=size).export(file_type="ply")


def _q(t: np.ndarray) -> np.ndarray:
    """[N, 2] joint angles (rad) at times t (s from the start)."""
    return np.stack(
        [0.6 * np.sin(2 * np.pi * 0.25 * t), 0.8 * np.sin(2 * np.pi * 0.2 * t) + 0.3], axis=1
    )


def _box_pose(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box centre [N, 3] (m) and yaw [N] (rad): it slides along +x on the table."""
    x = 0.45 + 0.05 * t
    y = np.full_like(t, 0.15)
    z = np.full_like(t, BOX[2] / 2)
    return np.stack([x, y, z], axis=1), 0.1 * t


def _yaw_quat(yaw: np.ndarray) -> np.ndarray:
    return np.stack(
        [np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)], axis=1
    )


def _project(p: np.ndarray) -> np.ndarray:
    """World points [N, 3] -> pixel coordinates [N, 2] for the camera looking down from (0.3, 0, CAM_Z)."""
    xc, yc, zc = p[:, 0] - 0.3, -(p[:, 1] - 0.0), CAM_Z - p[:, 2]
    return np.stack([F * xc / zc + W / 2, F * yc / zc + H / 2], axis=1)


def _box_corners(c: np.ndarray, yaw: float, size: tuple[float, float, float]) -> np.ndarray:
    s = np.array(size) / 2
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * s
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    return corners @ R.T + c


def _label_image(c: np.ndarray, yaw: float) -> np.ndarray:
    img = np.zeros((H, W), np.uint16)
    for label, corners in (
        (LABEL_TABLE, _box_corners(np.array(TABLE_CENTER), 0.0, TABLE)),
        (LABEL_BOX, _box_corners(c, yaw, BOX)),
    ):
        uv = _project(corners)
        x0, y0 = np.clip(np.floor(uv.min(axis=0)).astype(int), 0, [W, H])
        x1, y1 = np.clip(np.ceil(uv.max(axis=0)).astype(int), 0, [W, H])
        img[y0:y1, x0:x1] = label
    return img


def build_tiny_scene(root: Path) -> Path:
    """Write the tiny scene to ``root`` (a new folder) and return it."""
    tj = np.arange(int(DURATION_S * JOINT_HZ) + 1) / JOINT_HZ
    te = np.arange(int(DURATION_S * EE_HZ) + 1) / EE_HZ
    tc = np.arange(int(DURATION_S * CAM_HZ) + 1) / CAM_HZ

    def ns(t: np.ndarray) -> np.ndarray:
        return T0 + np.rint(t * 1e9).astype(np.int64)

    ep = "episodes/ep000"
    with Dataset.create(root) as w:
        w.write_text("robot/robot.urdf", _urdf())
        w.write_bytes("robot/meshes/base.stl", _stl((0.1, 0.1, 0.1), (0.0, 0.0, 0.05)))
        w.write_bytes("robot/meshes/link1.stl", _stl((L1, 0.04, 0.04), (L1 / 2, 0.0, 0.0)))
        w.write_bytes("robot/meshes/link2.stl", _stl((L2, 0.04, 0.04), (L2 / 2, 0.0, 0.0)))
        w.set_robot("robot/robot.urdf", base_link="base_link", ee_link="tool0")
        w.write_bytes("assets/box/mesh.ply", _ply(BOX))
        w.write_bytes("assets/table/mesh.ply", _ply(TABLE))
        w.set_asset("box", kind="object", mesh="assets/box/mesh.ply")
        w.set_asset("table", kind="table", mesh="assets/table/mesh.ply")
        w.set_physics(
            {
                "gravity_mps2": [0.0, 0.0, -9.81],
                "objects": {
                    "box": {
                        "equation": "rigid",
                        "mass_kg": 0.5,
                        "com_m": [0.0, 0.0, 0.0],
                        "inertia_kgm2": _box_inertia(0.5, BOX).tolist(),
                        "friction_static": 0.5,
                        "friction_dynamic": 0.4,
                        "restitution": 0.1,
                        "size_m": list(BOX),
                    },
                    "table": {"equation": "static", "size_m": list(TABLE)},
                },
                "sensors": {"cam0": {"time_offset_ns": 0}},
            }
        )
        T_world_cam = np.array(
            [[1.0, 0, 0, 0.3], [0, -1.0, 0, 0.0], [0, 0, -1.0, CAM_Z], [0, 0, 0, 1.0]]
        )
        w.set_camera(CameraModel("cam0", W, H, F, F, W / 2, H / 2, T_world_cam=T_world_cam))

        q = _q(tj)
        w.write_table(
            f"{ep}/joint_states.parquet",
            pa.table({"t_ns": ns(tj), "position.j1": q[:, 0], "position.j2": q[:, 1]}),
            kind="joint_states",
        )
        qe = _q(te)
        x = L1 * np.cos(qe[:, 0]) + L2 * np.cos(qe[:, 0] + qe[:, 1])
        y = L1 * np.sin(qe[:, 0]) + L2 * np.sin(qe[:, 0] + qe[:, 1])
        quat = _yaw_quat(qe[:, 0] + qe[:, 1])
        w.write_table(
            f"{ep}/ee_poses.parquet",
            pa.table(
                {
                    "t_ns": ns(te),
                    "link": ["tool0"] * te.size,
                    "x": x,
                    "y": y,
                    "z": np.full_like(x, BASE_Z),
                    "qw": quat[:, 0],
                    "qx": quat[:, 1],
                    "qy": quat[:, 2],
                    "qz": quat[:, 3],
                }
            ),
            kind="ee_poses",
        )
        c, yaw = _box_pose(tj)
        qb = _yaw_quat(yaw)
        n = tj.size
        obj = pa.table(
            {
                "t_ns": np.concatenate([ns(tj), ns(tj)]),
                "object": ["box"] * n + ["table"] * n,
                "x": np.concatenate([c[:, 0], np.full(n, TABLE_CENTER[0])]),
                "y": np.concatenate([c[:, 1], np.full(n, TABLE_CENTER[1])]),
                "z": np.concatenate([c[:, 2], np.full(n, TABLE_CENTER[2])]),
                "qw": np.concatenate([qb[:, 0], np.ones(n)]),
                "qx": np.zeros(2 * n),
                "qy": np.zeros(2 * n),
                "qz": np.concatenate([qb[:, 3], np.zeros(n)]),
            }
        )
        w.write_table(f"{ep}/object_poses.parquet", obj, kind="object_poses")
        cb, yb = _box_pose(tc)
        qbc = _yaw_quat(yb)
        m = tc.size
        w.write_table(
            f"{ep}/boxes3d.parquet",
            pa.table(
                {
                    "t_ns": ns(tc),
                    "object": ["box"] * m,
                    "x": cb[:, 0],
                    "y": cb[:, 1],
                    "z": cb[:, 2],
                    "qw": qbc[:, 0],
                    "qx": np.zeros(m),
                    "qy": np.zeros(m),
                    "qz": qbc[:, 3],
                    "size_x": np.full(m, BOX[0]),
                    "size_y": np.full(m, BOX[1]),
                    "size_z": np.full(m, BOX[2]),
                }
            ),
            kind="boxes3d",
        )
        labels = [_label_image(cb[k], yb[k]) for k in range(m)]
        rows: dict[str, list] = {
            k: []
            for k in (
                "t_ns",
                "camera",
                "frame_index",
                "label_id",
                "x_min",
                "y_min",
                "x_max",
                "y_max",
            )
        }
        for k, img in enumerate(labels):
            for label in (LABEL_BOX, LABEL_TABLE):
                ys, xs = np.nonzero(img == label)
                rows["t_ns"].append(int(ns(tc[k : k + 1])[0]))
                rows["camera"].append("cam0")
                rows["frame_index"].append(k)
                rows["label_id"].append(label)
                rows["x_min"].append(float(xs.min()))
                rows["y_min"].append(float(ys.min()))
                rows["x_max"].append(float(xs.max() + 1))
                rows["y_max"].append(float(ys.max() + 1))
        w.write_table(
            f"{ep}/boxes2d.parquet",
            pa.table(
                {
                    **{k: rows[k] for k in ("t_ns", "camera")},
                    "frame_index": pa.array(rows["frame_index"], pa.int64()),
                    "label_id": pa.array(rows["label_id"], pa.int32()),
                    **{
                        k: pa.array(rows[k], pa.float64())
                        for k in ("x_min", "y_min", "x_max", "y_max")
                    },
                }
            ),
            kind="boxes2d",
        )
        w.write_table(
            f"{ep}/segments.parquet",
            pa.table(
                {
                    "label_id": pa.array([LABEL_BOX, LABEL_TABLE], pa.int32()),
                    "category": ["box", "table"],
                    "instance": pa.array([1, 1], pa.int32()),
                    "kind": ["object", "object"],
                    "target": ["box", "table"],
                }
            ),
            kind="segments",
        )
        cam = f"{ep}/cameras/cam0"
        w.write_table(
            f"{cam}/frames.parquet",
            pa.table({"t_ns": ns(tc), "frame_index": pa.array(np.arange(m), pa.int64())}),
            kind="camera_frames",
        )
        w.write_table(
            f"{cam}/labels.parquet",
            pa.table(
                {
                    "frame_index": pa.array(np.arange(m), pa.int64()),
                    "png": pa.array([encode_label_png(img) for img in labels], pa.binary()),
                }
            ),
            kind="camera_labels",
        )
        with VideoWriter(w.path(f"{cam}/rgb.mp4"), W, H, CAM_HZ) as vw:
            for img in labels:
                rgb = np.zeros((H, W, 3), np.uint8)
                rgb[img == LABEL_TABLE] = (160, 110, 70)
                rgb[img == LABEL_BOX] = (40, 170, 60)
                vw.write(rgb)

        def stream(kind: str, rel: str, rate: float | None, **extra: object) -> dict:
            return {
                "kind": kind,
                "path": rel,
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": rate,
                **extra,
            }

        w.add_episode(
            "ep000",
            start_ns=T0,
            end_ns=int(ns(np.array([DURATION_S]))[0]),
            streams={
                "joint_states": stream("joint_states", f"{ep}/joint_states.parquet", JOINT_HZ),
                "ee_poses": stream("ee_poses", f"{ep}/ee_poses.parquet", EE_HZ),
                "object_poses": stream("object_poses", f"{ep}/object_poses.parquet", JOINT_HZ),
                "boxes2d": stream("boxes2d", f"{ep}/boxes2d.parquet", None),
                "boxes3d": stream("boxes3d", f"{ep}/boxes3d.parquet", None),
                "segments": {
                    "kind": "segments",
                    "path": f"{ep}/segments.parquet",
                    "stamp_source": "none",
                    "offset_ns": 0,
                },
                "camera/cam0": {
                    "kind": "camera",
                    "camera": "cam0",
                    "frames": f"{cam}/frames.parquet",
                    "video": f"{cam}/rgb.mp4",
                    "labels": f"{cam}/labels.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                    "nominal_rate_hz": CAM_HZ,
                },
            },
        )
        w.commit()
    return root

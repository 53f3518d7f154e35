"""A pushed-box dataset with known geometry, written with ``DatasetWriter`` (test oracle).

The robot is a gantry (prismatic x, y, z, then a yaw joint) whose ``tool`` link carries the
pusher collision (a sphere or a vertical cylinder, off the link origin); the ``column`` link
carries a distractor cylinder higher up. A box of known size rests on a tilted, raised plane
and is pushed along its x axis in one episode and along its y axis in the other, the pusher
touching the face centre at the box's mid height. Poses are written with noise; joint columns
are in an order that is not the URDF's. Nothing here calls robogs.physics.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

__all__ = ["Truth", "write_scene"]

T0 = 1_700_000_000_000_000_000


@dataclass
class Truth:
    size: np.ndarray
    normal: np.ndarray
    point: np.ndarray  # a point of the support plane
    radius: float
    density_wood: float = 600.0

    def plane_z(self, xy: np.ndarray) -> np.ndarray:
        n = self.normal
        d = n @ self.point
        return (d - xy[..., 0] * n[0] - xy[..., 1] * n[1]) / n[2]


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _quat(R: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a rotation matrix (Shepperd's method, trace branch + fallbacks)."""
    w = np.sqrt(max(0.0, 1 + R[0, 0] + R[1, 1] + R[2, 2])) / 2
    x = np.copysign(np.sqrt(max(0.0, 1 + R[0, 0] - R[1, 1] - R[2, 2])) / 2, R[2, 1] - R[1, 2])
    y = np.copysign(np.sqrt(max(0.0, 1 - R[0, 0] + R[1, 1] - R[2, 2])) / 2, R[0, 2] - R[2, 0])
    z = np.copysign(np.sqrt(max(0.0, 1 - R[0, 0] - R[1, 1] + R[2, 2])) / 2, R[1, 0] - R[0, 1])
    return np.array([w, x, y, z])


def urdf_text(pusher: str, radius: float, tool_xyz=(0.02, 0.0, 0.0), shape_z=-0.04) -> str:
    geo = (
        f'<sphere radius="{radius}"/>'
        if pusher == "sphere"
        else f'<cylinder radius="{radius}" length="0.08"/>'
    )
    lim = '<limit lower="-3" upper="3" effort="10" velocity="1"/>'
    j = ""
    for name, parent, child, axis in (
        ("jx", "base_link", "carriage_x", "1 0 0"),
        ("jy", "carriage_x", "carriage_y", "0 1 0"),
        ("jz", "carriage_y", "column", "0 0 1"),
    ):
        j += (
            f'<joint name="{name}" type="prismatic"><parent link="{parent}"/>'
            f'<child link="{child}"/><axis xyz="{axis}"/>{lim}</joint>\n'
        )
    inert = (
        '<inertial><mass value="1"/>'
        '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
    )
    return f"""<robot name="gantry">
<link name="base_link"/><link name="carriage_x">{inert}</link>
<link name="carriage_y">{inert}</link>
<link name="column">{inert.replace("<mass", '<origin xyz="0 0 0.35"/><mass')}<collision><origin xyz="0 0 0.35"/>
<geometry><cylinder radius="0.03" length="0.5"/></geometry></collision></link>
<link name="wrist">{inert}</link>
<link name="tool"><collision><origin xyz="0 0 {shape_z}"/><geometry>{geo}</geometry></collision></link>
{j}<joint name="jyaw" type="revolute"><parent link="column"/><child link="wrist"/>
<axis xyz="0 0 1"/>{lim}</joint>
<joint name="tool_fixed" type="fixed"><parent link="wrist"/><child link="tool"/>
<origin xyz="{tool_xyz[0]} {tool_xyz[1]} {tool_xyz[2]}"/></joint>
</robot>
"""


def _pose_table(t, key, name, pos, quat) -> pa.Table:
    return pa.table(
        {
            "t_ns": pa.array(t, pa.int64()),
            key: pa.array([name] * len(t), pa.string()),
            **{c: pos[:, i] for i, c in enumerate("xyz")},
            **{c: quat[:, i] for i, c in enumerate(("qw", "qx", "qy", "qz"))},
        }
    )


def _stream(kind: str, path: str, hz: float) -> dict:
    return {
        "kind": kind,
        "path": path,
        "stamp_source": "synthetic",
        "offset_ns": 0,
        "nominal_rate_hz": hz,
    }


def write_scene(
    root: Path,
    *,
    seed: int = 0,
    pusher: str = "sphere",
    radius: float = 0.012,
    size=(0.10, 0.07, 0.05),
    table_mesh: bool = True,
    box_annotation: bool = False,
    box_mesh: bool = False,
    robot: bool = True,
    objects: bool = True,
    ee_tip: bool = False,
    noise_m: float = 0.0005,
) -> Truth:
    """Write the dataset at ``root`` and return the truth."""
    import trimesh

    from robogs.format.dataset import Dataset

    rng = np.random.default_rng(seed)
    size = np.asarray(size, dtype=float)
    R_plane = _rx(np.radians(2.0)) @ _ry(np.radians(-1.5))
    n = R_plane[:, 2]
    p0 = np.array([0.55, 0.05, 0.12])
    truth = Truth(size, n, p0, radius)
    yaw0, tool_yaw = np.radians(20.0), 0.3
    tool_off = _rz(tool_yaw) @ np.array([0.02, 0.0, 0.0])
    w = Dataset.create(root, name="init_scene")
    if robot:
        w.write_text("robot/robot.urdf", urdf_text(pusher, radius))
        w.set_robot("robot/robot.urdf", base_link="base_link")
    if table_mesh:
        slab = trimesh.creation.box(extents=(1.2, 1.0, 0.04))
        w.write_bytes("assets/table/mesh.ply", slab.export(file_type="ply"))
        centre = p0 - 0.02 * n
        w.set_asset(
            "table",
            kind="table",
            mesh="assets/table/mesh.ply",
            pose=[*centre.tolist(), *_quat(R_plane).tolist()],
        )
    w.set_asset("box", kind="object")
    if box_mesh:
        w.write_bytes(
            "assets/box/mesh.ply", trimesh.creation.box(extents=size).export(file_type="ply")
        )
        w.set_asset("box", kind="object", mesh="assets/box/mesh.ply")
    R_box = R_plane @ _rz(yaw0)
    for k, (axis, start_xy) in enumerate(((0, (0.0, 0.0)), (1, (0.05, -0.12)))):
        ep = f"push{k}"
        d = R_box[:, axis]  # push direction, in the plane
        c0 = p0 + R_plane @ np.array([*start_xy, 0.0]) + 0.5 * size[2] * n
        contact = 0.5 * size[axis] + radius
        # pusher path: approach (0-1 s), push 0.12 m (1-3 s), retreat (3-4 s); smooth speed
        t_obj = np.arange(0.0, 4.0, 1 / 60.0)
        t_js = np.arange(0.0, 4.0, 1 / 200.0)

        def s_box(t):
            u = np.clip((t - 1.0) / 2.0, 0.0, 1.0)
            return 0.12 * (u - np.sin(2 * np.pi * u) / (2 * np.pi))

        def s_pusher(t):
            approach = np.where(t < 1.0, -0.06 * (1.0 - t), 0.0)
            retreat = np.where(t > 3.0, -0.05 * (t - 3.0), 0.0)
            return s_box(t) + approach + retreat

        c = c0 + s_box(t_obj)[:, None] * d
        pos = c + rng.normal(0.0, noise_m, c.shape)
        quats = []
        for _ in t_obj:
            v = rng.normal(0.0, np.radians(0.2), 3)
            a = np.linalg.norm(v)
            K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / max(a, 1e-12)
            dR = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
            quats.append(_quat(dR @ R_box))
        P = c0 - contact * d + s_pusher(t_js)[:, None] * d  # pusher-sphere centre
        col = P - tool_off - np.array([0.0, 0.0, -0.04])  # column frame = joint values
        js = pa.table(
            {
                "t_ns": pa.array(T0 + np.round(t_js * 1e9).astype(np.int64), pa.int64()),
                "position.jyaw": np.full(len(t_js), tool_yaw),
                "position.jz": col[:, 2],
                "position.jx": col[:, 0],
                "position.jy": col[:, 1],
            }
        )
        streams = {}
        if objects:
            w.write_table(
                f"episodes/{ep}/object_poses.parquet",
                _pose_table(
                    T0 + np.round(t_obj * 1e9).astype(np.int64),
                    "object",
                    "box",
                    pos,
                    np.array(quats),
                ),
                kind="object_poses",
            )
            streams["object_poses"] = _stream(
                "object_poses", f"episodes/{ep}/object_poses.parquet", 60.0
            )
        if ee_tip:  # a recorded pose of a frame at the pusher-sphere centre
            q_tool = np.tile(_quat(_rz(tool_yaw)), (len(t_js), 1))
            tip = _pose_table(js.column("t_ns").to_numpy(), "link", "tip", P, q_tool)
            w.write_table(f"episodes/{ep}/ee_poses.parquet", tip, kind="ee_poses")
            streams["ee_poses"] = _stream("ee_poses", f"episodes/{ep}/ee_poses.parquet", 200.0)
        w.write_table(f"episodes/{ep}/joint_states.parquet", js, kind="joint_states")
        streams["joint_states"] = _stream(
            "joint_states", f"episodes/{ep}/joint_states.parquet", 200.0
        )
        if box_annotation:
            tb = np.array([T0, T0 + 2_000_000_000])
            ann = _pose_table(
                tb, "object", "box", np.stack([c[0], c[-1]]), np.array([quats[0], quats[-1]])
            )
            for i, col_name in enumerate(("size_x", "size_y", "size_z")):
                ann = ann.append_column(col_name, pa.array(np.full(2, size[i])))
            w.write_table(f"episodes/{ep}/boxes3d.parquet", ann, kind="boxes3d")
            streams["boxes3d"] = _stream("boxes3d", f"episodes/{ep}/boxes3d.parquet", 1.0)
        w.add_episode(ep, start_ns=T0, end_ns=T0 + 4_000_000_000, streams=streams, segment=ep)
    w.commit()
    return truth

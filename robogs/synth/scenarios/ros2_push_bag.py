"""A ROS 2 MCAP bag of force-controlled pushes, as a rig would record it (issue 15 acceptance).

Written with the ``mcap`` / ``mcap-ros2-support`` libraries directly: it shares no code with
``robogs convert`` (reader or ROS 2 exporter) or with the physics model. The motion and forces
come from :mod:`robogs.synth.scenarios.force_push` (its own numpy truth). The rig:

* a URDF package ``push_rig_description`` (``package.xml``, ``urdf/rig.urdf``, a base mesh
  referenced as ``package://push_rig_description/meshes/base.stl``): a gantry with prismatic
  joints ``x``, ``y``, ``z`` and a yaw joint; the tool link ``tool0`` carries the pusher's
  collision capsule (radius ``r``, length ``L``, axis along ``tool0``'s y) at ``PUSHER_TIP``;
* topics: ``/joint_states`` (500 Hz, the driver's order ``yaw, z, x, y``, not the URDF's;
  the robot moves on between pushes),
  ``/tf_static`` (``tool0 -> pusher_tip``: the pusher frame exists only there),
  ``/objects/box/pose`` (mocap ``PoseStamped`` in ``base_link``, 30 Hz, only while a push is
  recorded: gaps between pushes while the box is put back by hand), ``/wrench/tool0``
  (``WrenchStamped`` in ``tool0``, 250 Hz: force on the tool, with the tool's weight and
  noise).

:func:`write_push_bag` returns the truth (the box, the table, the pusher) for tests.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from robogs.synth.scenarios.force_push import ForcePushRecording, ForcePushTruth, make_force_push

__all__ = ["write_rig_package", "write_push_bag", "PUSHER_TIP", "Z0", "JOINT_ORDER"]

PUSHER_TIP = (0.0, 0.0, -0.1)
"""``T_tool0_pusher_tip`` translation [m] (no rotation)."""
Z0 = 0.3
"""Height of the z joint's origin above base_link [m]."""
JOINT_ORDER = ("yaw", "z", "x", "y")
"""The driver's joint order in /joint_states (the URDF declares x, y, z, yaw)."""

_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_TIME = "int32 sec\nuint32 nanosec\n"
_VEC = "float64 x\nfloat64 y\nfloat64 z\n"
_QUAT = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
_SEP = "=" * 80 + "\n"


def _msgdef(body: str, deps: dict[str, str]) -> str:
    return body + "".join(f"{_SEP}MSG: {k}\n{v}" for k, v in deps.items())


_DEFS = {
    "sensor_msgs/msg/JointState": _msgdef(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n",
        {"std_msgs/Header": _HEADER, "builtin_interfaces/Time": _TIME},
    ),
    "tf2_msgs/msg/TFMessage": _msgdef(
        "geometry_msgs/TransformStamped[] transforms\n",
        {
            "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\n"
            "geometry_msgs/Transform transform\n",
            "std_msgs/Header": _HEADER,
            "builtin_interfaces/Time": _TIME,
            "geometry_msgs/Transform": "geometry_msgs/Vector3 translation\n"
            "geometry_msgs/Quaternion rotation\n",
            "geometry_msgs/Vector3": _VEC,
            "geometry_msgs/Quaternion": _QUAT,
        },
    ),
    "geometry_msgs/msg/PoseStamped": _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        {
            "std_msgs/Header": _HEADER,
            "builtin_interfaces/Time": _TIME,
            "geometry_msgs/Pose": "geometry_msgs/Point position\n"
            "geometry_msgs/Quaternion orientation\n",
            "geometry_msgs/Point": _VEC,
            "geometry_msgs/Quaternion": _QUAT,
        },
    ),
    "geometry_msgs/msg/WrenchStamped": _msgdef(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
        {
            "std_msgs/Header": _HEADER,
            "builtin_interfaces/Time": _TIME,
            "geometry_msgs/Wrench": "geometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
            "geometry_msgs/Vector3": _VEC,
        },
    ),
}


def _stl_cube(half: float) -> bytes:
    """ASCII STL of a cube of half edge ``half`` [m] (12 triangles)."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * half
    faces = [
        (0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4),
        (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5),
    ]  # fmt: skip
    lines = ["solid base"]
    for a, b, c in faces:
        n = np.cross(v[b] - v[a], v[c] - v[a])
        n /= np.linalg.norm(n)
        lines.append(f"facet normal {n[0]:g} {n[1]:g} {n[2]:g}\nouter loop")
        lines += [f"vertex {p[0]:g} {p[1]:g} {p[2]:g}" for p in (v[a], v[b], v[c])]
        lines.append("endloop\nendfacet")
    lines.append("endsolid base\n")
    return "\n".join(lines).encode()


def write_rig_package(folder: Path, *, radius: float, length: float) -> Path:
    """Write the ``push_rig_description`` package under ``folder``; returns the URDF path."""
    pkg = Path(folder) / "push_rig_description"
    (pkg / "urdf").mkdir(parents=True, exist_ok=True)
    (pkg / "meshes").mkdir(exist_ok=True)
    (pkg / "package.xml").write_text(
        '<?xml version="1.0"?>\n<package format="3">\n  <name>push_rig_description</name>\n'
        "  <version>0.1.0</version>\n  <description>gantry pusher rig</description>\n"
        '  <maintainer email="rig@example.org">rig</maintainer>\n  <license>MIT</license>\n'
        "</package>\n"
    )
    (pkg / "meshes" / "base.stl").write_bytes(_stl_cube(0.05))
    tip = " ".join(f"{v:g}" for v in PUSHER_TIP)
    inertial = (
        '<inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )

    def link(name: str, extra: str = "") -> str:
        return f'  <link name="{name}">{inertial}{extra}</link>\n'

    def joint(name: str, kind: str, parent: str, child: str, axis: str, xyz: str = "0 0 0") -> str:
        return (
            f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}"/><axis xyz="{axis}"/>'
            '<limit lower="-3.2" upper="3.2" effort="100" velocity="2"/></joint>\n'
        )

    urdf = (
        '<?xml version="1.0"?>\n<robot name="push_rig">\n'
        + link(
            "base_link",
            '<visual><geometry><mesh filename="package://push_rig_description/meshes/base.stl"/>'
            "</geometry></visual>",
        )
        + link("x_carriage")
        + link("y_carriage")
        + link("z_carriage")
        + link(
            "tool0",
            f'<collision><origin xyz="{tip}" rpy="1.5707963267948966 0 0"/>'
            f'<geometry><capsule radius="{radius:g}" length="{length:g}"/></geometry></collision>',
        )
        + joint("x", "prismatic", "base_link", "x_carriage", "1 0 0")
        + joint("y", "prismatic", "x_carriage", "y_carriage", "0 1 0")
        + joint("z", "prismatic", "y_carriage", "z_carriage", "0 0 1", f"0 0 {Z0:g}")
        + joint("yaw", "revolute", "z_carriage", "tool0", "0 0 1")
        + "</robot>\n"
    )
    path = pkg / "urdf" / "rig.urdf"
    path.write_text(urdf)
    return path


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": int(t_ns // 1_000_000_000), "nanosec": int(t_ns % 1_000_000_000)}


def _yaw_of(q: np.ndarray) -> float:
    return float(np.angle(np.exp(2j * np.arctan2(q[3], q[0]))))


def _joints(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Joint values in ``JOINT_ORDER`` that put the pusher tip at ``p`` with tool yaw of ``q``
    (the tip is straight below tool0: tool0 = tip - PUSHER_TIP)."""
    vals = {"x": p[0], "y": p[1], "z": p[2] - PUSHER_TIP[2] - Z0, "yaw": _yaw_of(q)}
    return np.array([vals[j] for j in JOINT_ORDER], dtype=float)


def _transit(
    a: np.ndarray, b: np.ndarray, t_a: int, t_b: int, hz: float
) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-jerk joint motion from ``a`` to ``b`` strictly between stamps ``t_a`` and ``t_b``
    [ns] at ``hz``: stamps [K] and values [K, J]."""
    t = np.arange(t_a, t_b, int(1e9 / hz))[1:]
    u = (t - t_a) / float(t_b - t_a)
    s = 10 * u**3 - 15 * u**4 + 6 * u**5
    return t, a[None] + s[:, None] * (b - a)[None]


def write_push_bag(
    path: str | Path,
    *,
    mass_true: float,
    seed: int = 0,
    n_traj: int = 6,
    table_z: float = 0.0,
) -> dict[str, Any]:
    """Write the bag at ``path`` (``.mcap``) and return the truth.

    Args:
        path: output file.
        mass_true: the box's true mass [kg].
        seed, n_traj, table_z: see :func:`~robogs.synth.scenarios.force_push.make_force_push`.

    Returns:
        ``{"size_m", "mass_kg", "table_z_m", "pusher_radius_m", "pusher_length_m", "mu_d"}``.
    """
    from mcap_ros2.writer import Writer

    rec: ForcePushRecording = make_force_push(
        mass_true=mass_true, mass_nominal=mass_true, seed=seed, n_traj=n_traj, table_z=table_z
    )
    msgs: list[tuple[int, str, str, dict[str, Any]]] = []
    t_first = min(int(tr.ee_t_ns[0]) for tr in rec.trajectories)
    tf = {
        "header": {"stamp": _stamp(t_first), "frame_id": "tool0"},
        "child_frame_id": "pusher_tip",
        "transform": {
            "translation": dict(zip("xyz", PUSHER_TIP, strict=True)),
            "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    }
    msgs.append((t_first - 1000, "/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": [tf]}))
    rng = np.random.default_rng(seed + 1000)
    offset = np.asarray(ForcePushTruth().sensor_offset)
    for k, tr in enumerate(rec.trajectories):
        q_all = np.stack([_joints(p, q) for p, q in zip(tr.ee_pos, tr.ee_quat, strict=True)])
        t_all = np.asarray(tr.ee_t_ns)
        w_t, w_f = np.asarray(tr.wrench_t_ns), np.asarray(tr.wrench_tool)
        if k + 1 < len(rec.trajectories):  # the robot moves on to the next push, unloaded
            nxt = rec.trajectories[k + 1]
            q_next = _joints(nxt.ee_pos[0], nxt.ee_quat[0])
            tt, qq = _transit(q_all[-1], q_next, int(t_all[-1]), int(nxt.ee_t_ns[0]), 500.0)
            t_all, q_all = np.concatenate([t_all, tt]), np.concatenate([q_all, qq])
            tw = np.arange(int(w_t[-1]), int(nxt.wrench_t_ns[0]), 4_000_000)[1:]
            fw = offset[None] + rng.normal(0.0, ForcePushTruth().sigma_force, (len(tw), 3))
            w_t, w_f = np.concatenate([w_t, tw]), np.concatenate([w_f, fw])
        for t, qv in zip(t_all, q_all, strict=True):
            vals = dict(zip(JOINT_ORDER, qv, strict=True))
            msgs.append(
                (
                    int(t),
                    "/joint_states",
                    "sensor_msgs/msg/JointState",
                    {
                        "header": {"stamp": _stamp(int(t)), "frame_id": ""},
                        "name": list(JOINT_ORDER),
                        "position": [float(vals[j]) for j in JOINT_ORDER],
                        "velocity": [],
                        "effort": [],
                    },
                )
            )
        for t, p, q in zip(tr.t_ns, tr.object_pos, tr.object_quat, strict=True):
            msgs.append(
                (
                    int(t),
                    "/objects/box/pose",
                    "geometry_msgs/msg/PoseStamped",
                    {
                        "header": {"stamp": _stamp(int(t)), "frame_id": "base_link"},
                        "pose": {
                            "position": {"x": p[0], "y": p[1], "z": p[2]},
                            "orientation": {"x": q[1], "y": q[2], "z": q[3], "w": q[0]},
                        },
                    },
                )
            )
        for t, f in zip(w_t, w_f, strict=True):
            msgs.append(
                (
                    int(t),
                    "/wrench/tool0",
                    "geometry_msgs/msg/WrenchStamped",
                    {
                        "header": {"stamp": _stamp(int(t)), "frame_id": "tool0"},
                        "wrench": {
                            "force": {"x": f[0], "y": f[1], "z": f[2]},
                            "torque": {"x": 0.0, "y": 0.0, "z": 0.0},
                        },
                    },
                )
            )
    msgs.sort(key=lambda m: m[0])
    with open(path, "wb") as fh:
        w = Writer(fh)
        schemas = {k: w.register_msgdef(k, v) for k, v in _DEFS.items()}
        for seq, (t, topic, kind, msg) in enumerate(msgs):
            w.write_message(topic, schemas[kind], msg, log_time=t, publish_time=t, sequence=seq)
        w.finish()
    truth = ForcePushTruth(mass=mass_true, table_z=table_z)
    return {
        "size_m": list(truth.size),
        "mass_kg": mass_true,
        "table_z_m": table_z,
        "pusher_radius_m": truth.pusher_radius,
        "pusher_length_m": truth.pusher_length,
        "mu_d": truth.mu_d,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m robogs.synth.scenarios.ros2_push_bag DIR``: the rig package and ``push.mcap``
    in DIR (the truth is printed as JSON; keep it away from the dataset)."""
    import argparse
    import json

    p = argparse.ArgumentParser(prog="python -m robogs.synth.scenarios.ros2_push_bag")
    p.add_argument("folder", type=Path)
    p.add_argument("--mass", type=float, default=0.33, help="true box mass [kg]")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--pushes", type=int, default=6)
    a = p.parse_args(argv)
    a.folder.mkdir(parents=True, exist_ok=True)
    truth = ForcePushTruth()
    write_rig_package(a.folder, radius=truth.pusher_radius, length=truth.pusher_length)
    out = write_push_bag(a.folder / "push.mcap", mass_true=a.mass, seed=a.seed, n_traj=a.pushes)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""``objects.pusher.geometry = "robot"``: the URDF's links push in the MuJoCo engine.

Oracles (the URDFs are written here by hand, the end-effector motion is closed form):

* equivalence: a tool link whose only collision geometry is a sphere of the primitive's radius
  at the pusher offset is the primitive: the pushed box's trajectory agrees within 1e-6 m;
* a flat paddle (box collision) pushing a box face-on, off-centre, at constant speed: after
  contact the box's x is the paddle face's x plus its half size (0.5 mm), its yaw stays 0;
  the primitive sphere at the same point (radius = the paddle's half thickness) turns the box
  and does not keep that relation (counterfactual);
* a mesh MuJoCo refuses (only degenerate faces: surface area 0, so neither its volume nor its
  shell compiles) is hulled (8 vertices of the paddle box), noted, and pushes as the paddle.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from robogs.format.errors import FormatError, InputError
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.engines.mujoco_robot import (
    RobotPusher,
    distal_links,
    pusher_frames,
    pusher_geometry,
)

torch.set_num_threads(1)

DT = 1e-3
HALF = 0.025  # the box's half size [m]
Z = HALF  # pusher height: the box's centre


def _urdf(tmp: Path, tool_collision: str, extra_links: str = "") -> Path:
    """x, y, z slides and a yaw hinge from the base to ``tool`` (T_base_tool = trans(x, y, z)
    Rz(yaw)), then ``tool``'s collision and any extra links."""
    joints = []
    links = ['<link name="base"/>']
    parent = "base"
    for name, kind, axis in (
        ("jx", "prismatic", "1 0 0"),
        ("jy", "prismatic", "0 1 0"),
        ("jz", "prismatic", "0 0 1"),
        ("jyaw", "revolute", "0 0 1"),
    ):
        child = "tool" if name == "jyaw" else f"l_{name}"
        joints.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<axis xyz="{axis}"/><limit lower="-10" upper="10" effort="1" velocity="1"/></joint>'
        )
        if child != "tool":
            links.append(
                f'<link name="{child}"><inertial><mass value="0.1"/>'
                '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial></link>'
            )
        parent = child
    links.append(
        '<link name="tool"><inertial><mass value="0.1"/>'
        '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
        f"{tool_collision}</link>"
    )
    path = tmp / "robot" / "arm.urdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        '<?xml version="1.0"?><robot name="arm">'
        + "".join(links)
        + "".join(joints)
        + extra_links
        + "</robot>"
    )
    return path


def _physics(geometry: str, radius: float, friction_p: float = 0.0) -> dict:
    pusher = {"equation": "kinematic", "radius_m": radius, "friction_dynamic": friction_p}
    if geometry == "robot":
        pusher["geometry"] = "robot"
        pusher["link"] = "tool"
    return {
        "revision": 1,
        "objects": {
            "box": {
                "equation": "rigid",
                "size_m": [2 * HALF] * 3,
                "mass_kg": 0.4,
                "friction_dynamic": 0.4,
            },
            "table": {"equation": "static", "plane_z_m": 0.0},
            "pusher": pusher,
        },
    }


def _rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _motion(x0: float, v: float, n: int, y: float, yaw: float, offset: np.ndarray):
    """Closed form: the tool origin at (x0 + v t, y, Z - offset_z...) with yaw ``yaw``; returns
    the tool rotations [n, 3, 3] and the drive (the pusher point = tool + R offset)."""
    t = np.arange(n) * DT
    tool = np.stack([x0 + v * t, np.full(n, y), np.full(n, Z)], -1) - _rz(yaw) @ offset
    rot = np.repeat(_rz(yaw)[None], n, 0)
    point = tool + rot @ offset
    drive = make_drive(
        DT,
        point[None],
        np.full((1, n), yaw),
        t[None],
        np.array([[0.0, 0.0, HALF]]),
        np.zeros(1),
    )
    return rot, drive, tool


def _robot(urdf: Path, rot: np.ndarray, offset) -> RobotPusher:
    frames, rig = pusher_frames(rot, offset, {"tool": np.eye(4)[None]})
    return RobotPusher(
        urdf, "tool", frames, root=urdf.parents[1], spread_m=rig.spread_m, spread_rad=rig.spread_rad
    )


def _box_path(eng: MujocoEngine, drive) -> tuple[np.ndarray, np.ndarray]:
    out = eng.rollout(drive)
    return out.pos["box"][0, 0], out.quat["box"][0, 0]


def test_a_urdf_sphere_at_the_pusher_offset_is_the_primitive(tmp_path: Path) -> None:
    r = 0.012
    offset = np.array([0.03, -0.01, 0.02])  # the pusher point in the tool frame [m]
    sphere = (
        f'<collision><origin xyz="{offset[0]} {offset[1]} {offset[2]}"/>'
        f'<geometry><sphere radius="{r}"/></geometry></collision>'
    )
    urdf = _urdf(tmp_path, sphere)
    # off-centre (y 12 mm), heading 0.4 rad, with pusher friction: the box slides and turns
    rot, drive, _ = _motion(-0.08, 0.25, 900, 0.012, 0.4, offset)
    for mu_p in (0.0, 0.3):
        prim = MujocoEngine(_physics("primitive", r, mu_p), dt=DT)
        phys = _physics("robot", r, mu_p)
        phys["objects"]["pusher"]["offset_m"] = offset.tolist()
        robo = MujocoEngine(phys, dt=DT, meshes={"pusher": _robot(urdf, rot, offset)})
        assert robo.pusher_geoms == ["pusher/tool/0"]
        p0, q0 = _box_path(prim, drive)
        p1, q1 = _box_path(robo, drive)
        assert np.linalg.norm(p0[-1] - p0[0]) > 0.05  # it was pushed
        assert abs(2 * math.atan2(q0[-1, 3], q0[-1, 0])) > 0.02  # and turned (off-centre)
        assert np.abs(p1 - p0).max() < 1e-6
        assert np.abs(np.abs(np.sum(q0 * q1, -1)) - 1).max() < 1e-9


PADDLE = (0.004, 0.05, 0.02)  # half sizes [m]: 8 mm thick, 100 mm wide, 40 mm high


def _paddle_push(eng: MujocoEngine, drive, tool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box x minus (paddle face x + half size) over the steps after contact settles, and the
    box yaw [rad] there."""
    pos, quat = _box_path(eng, drive)
    face = tool[:, 0] + PADDLE[0]
    gap = pos[:, 0] - (face + HALF)
    late = slice(len(gap) // 2, None)
    yaw = 2 * np.arctan2(quat[:, 3], quat[:, 0])
    return gap[late], yaw[late]


def _paddle_case(tmp_path: Path, collision: str):
    urdf = _urdf(tmp_path, collision)
    rot, drive, tool = _motion(-0.06, 0.1, 1200, 0.015, 0.0, np.zeros(3))
    phys = _physics("robot", PADDLE[0])
    eng = MujocoEngine(phys, dt=DT, meshes={"pusher": _robot(urdf, rot, None)})
    return eng, drive, tool


def test_b_a_flat_paddle_pushes_the_box_face_on(tmp_path: Path) -> None:
    box = f'<collision><geometry><box size="{2 * PADDLE[0]} {2 * PADDLE[1]} {2 * PADDLE[2]}"/>'
    eng, drive, tool = _paddle_case(tmp_path, box + "</geometry></collision>")
    gap, yaw = _paddle_push(eng, drive, tool)
    assert np.abs(gap).max() < 5e-4  # box x = paddle face x + half size
    assert np.abs(yaw).max() < math.radians(0.5)  # face-on: no turn though 15 mm off-centre
    # counterfactual: a sphere of the paddle's half thickness at the tool origin turns the box
    prim = MujocoEngine(_physics("primitive", PADDLE[0]), dt=DT)
    gap_s, yaw_s = _paddle_push(prim, drive, tool)
    assert np.abs(gap_s).max() > 2e-3 and np.abs(yaw_s).max() > math.radians(5)


def test_c_a_mesh_mujoco_refuses_is_hulled_and_noted(tmp_path: Path) -> None:
    """Only degenerate faces over the paddle's 8 corners: MuJoCo refuses its volume and its
    surface (area 0); mjcf_robot's rule hulls it (8 vertices), says so, and it pushes as the
    paddle."""
    sx, sy, sz = PADDLE
    corners = [(x, y, z) for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in corners)
    text += "".join(f"f {i + 1} {i + 1} {(i + 1) % 8 + 1}\n" for i in range(8))
    (tmp_path / "robot").mkdir(parents=True, exist_ok=True)
    (tmp_path / "robot" / "paddle.obj").write_text(text)
    mesh = '<collision><geometry><mesh filename="paddle.obj"/></geometry></collision>'
    eng, drive, tool = _paddle_case(tmp_path, mesh)
    assert any("paddle.obj" in n and "convex hull" in n for n in eng.scene.notes)
    g = mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_GEOM, "pusher/tool/0")
    assert eng.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
    assert eng.model.mesh_vertnum[eng.model.geom_dataid[g]] == 8
    gap, yaw = _paddle_push(eng, drive, tool)
    assert np.abs(gap).max() < 5e-4 and np.abs(yaw).max() < math.radians(0.5)


def test_robot_geoms_touch_only_objects_and_take_the_pusher_friction(tmp_path: Path) -> None:
    box = f'<collision><geometry><box size="{2 * PADDLE[0]} {2 * PADDLE[1]} {2 * PADDLE[2]}"/>'
    eng, _, _ = _paddle_case(tmp_path, box + "</geometry></collision>")
    m = eng.model
    g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pusher/tool/0")
    assert m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0
    rows = [k for k, p in enumerate(eng.scene.pairs) if "pusher/tool/0" in p]
    assert [set(eng.scene.pairs[k]) for k in rows] == [{"box", "pusher/tool/0"}]
    m2 = eng.model_for({"objects.pusher.friction_dynamic": 0.37})
    assert m2.pair_friction[rows[0], 0] == pytest.approx(0.37)


def test_links_below_the_pusher_link_and_the_rigidity_check(tmp_path: Path) -> None:
    from robogs.format.kinematics import Chain
    from robogs.format.urdf import load_urdf

    extra = (
        '<link name="finger"/><link name="cam"/><link name="tip"/>'
        '<joint name="jf" type="revolute"><parent link="tool"/><child link="finger"/>'
        '<axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="jt" type="fixed"><parent link="finger"/><child link="tip"/></joint>'
        '<joint name="jc" type="fixed"><parent link="l_jx"/><child link="cam"/></joint>'
    )
    chain = Chain.from_urdf(load_urdf(_urdf(tmp_path, "", extra), load_meshes=False))
    assert sorted(distal_links(chain, "tool")) == ["finger", "tip", "tool"]
    # yaw alone, and a fixed offset: rigid (spread 0); the pusher-frame pose is closed form
    off = np.array([0.01, 0.02, -0.03])
    yaws = np.linspace(-2.0, 2.5, 7)
    frames, rig = pusher_frames(np.stack([_rz(y) for y in yaws]), off, {"tool": np.eye(4)[None]})
    assert rig.spread_m < 1e-12 and rig.spread_rad < 1e-7
    assert np.abs(frames["tool"][:3, 3] + off).max() < 1e-12
    # the tool pitched by 10 deg half the time (5 deg from the mean pose, at a 50 mm reach:
    # 4.4 mm > the 2 mm budget, no noise in two samples): refused, naming the fallback
    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    pitch = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    with pytest.raises(InputError, match="rolls or pitches") as err:
        pusher_frames(np.stack([np.eye(3), pitch]), None, {"tool": np.eye(4)[None]}, reach_m=0.05)
    assert "primitive" in (err.value.hint or "") and "by 4.36 mm" in str(err.value)
    # at a 10 mm reach the same pitch moves the geometry 0.87 mm: accepted
    _, rig = pusher_frames(
        np.stack([np.eye(3), pitch]), None, {"tool": np.eye(4)[None]}, reach_m=0.01
    )
    assert rig.moved_m == pytest.approx(0.01 * math.radians(5), rel=1e-9)


def test_planar_refuses_the_robot_pusher_and_auto_picks_mujoco() -> None:
    from robogs.format.schemas import schema_problems
    from robogs.physics.engine import resolve_backend

    phys = _physics("robot", 0.01)
    with pytest.raises(InputError, match="objects.pusher.geometry") as err:
        resolve_backend(phys, "planar")
    assert "--engine mujoco" in (err.value.hint or "")
    assert resolve_backend(phys, "auto")[0] == "mujoco"
    assert not schema_problems("physics", phys)
    phys["objects"]["pusher"]["geometry"] = "robt"
    assert schema_problems("physics", phys)
    with pytest.raises(InputError, match="objects.pusher.geometry is 'robt'"):
        MujocoEngine(phys, dt=DT)
    with pytest.raises(FormatError, match="geometry"):
        pusher_geometry(phys)


def test_a_dataset_with_the_robot_pusher_reaches_the_engine(tmp_path: Path) -> None:
    """A gantry dataset (``init_scene``: tool link yawed 0.3 rad, its collision sphere 40 mm
    below the tool origin, joints at 200 Hz): ``robogs physics set`` accepts
    ``objects.pusher.geometry=robot``; forward kinematics of the recorded joints puts the tool
    at the closed-form pose in the pusher frame (translation ``-offset``, no rotation) and the
    engine's pusher geom is the URDF sphere at the pusher point."""
    from init_scene import write_scene

    from robogs.physics.engine import recording_backend
    from robogs.physics.init import init_physics, set_physics_values
    from robogs.physics.recording import load_recording

    root = tmp_path / "ds"
    truth = write_scene(root, seed=7)
    init_physics(root, objects=["box=material:wood"])
    doc = set_physics_values(root, ["objects.pusher.geometry=robot"])
    pusher = doc["objects"]["pusher"]
    assert pusher["geometry"] == "robot"
    rec = load_recording(root)
    rp = rec.robot_pusher
    assert rp is not None and list(rp.frames) == [pusher["link"]]
    offset = np.asarray(pusher.get("offset_m", [0.0, 0.0, 0.0]))
    frame = rp.frames[pusher["link"]]
    r_yaw = _rz(0.3)  # the tool's yaw: the tool frame's axes in the pusher frame are identity
    assert np.abs(frame[:3, :3] - np.eye(3)).max() < 1e-9
    assert np.abs(frame[:3, 3] + r_yaw.T @ (r_yaw @ offset)).max() < 1e-9
    assert rp.spread_m < 1e-9 and rp.spread_rad < 1e-6 and rp.moved_m < 1e-7
    assert rp.budget_m == pytest.approx(2e-3, abs=1e-9)  # geometry.box3d_mm, noise-free joints
    shapes = rec.shapes()
    assert shapes.meshes["pusher"] is rp and any(
        "objects.pusher.geometry" in n for n in shapes.notes
    )
    assert recording_backend(rec, "auto")[0] == "mujoco"
    with pytest.raises(InputError, match="objects.pusher.geometry"):
        recording_backend(rec, "planar")
    eng = MujocoEngine(rec.physics, meshes=shapes.meshes, dt=DT, joints="free")
    g = mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_GEOM, eng.pusher_geoms[0])
    assert eng.model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE
    assert eng.model.geom_size[g][0] == pytest.approx(truth.radius)
    # the sphere sits at the pusher point when offset_m is its centre (0, 0, -0.04)
    centre = frame[:3, 3] + frame[:3, :3] @ np.array([0.0, 0.0, -0.04])
    assert np.abs(eng.model.geom_pos[g] - centre).max() < 1e-12

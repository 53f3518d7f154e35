"""The URDF robot as MJCF (robogs.format.mjcf_robot) against robogs' own URDF kinematics.

Oracle: :class:`robogs.format.kinematics.Chain` (itself checked against yourdfpy's scene graph
in test_chain.py). MuJoCo compiles the written document; ``mj_kinematics`` at the joint values
(mimic joints from their source) must put every link body at ``Chain.forward`` within 1e-6 m and
1e-6 in every rotation-matrix entry (measured: 1e-15 on the fixture robot and the four real
arms). A URDF with one joint's axis swapped is caught by the same comparison. Mesh files keep
their vertex count (the source's, counted by trimesh independently of the converter), or the
conversion says why not.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
import trimesh

from robogs.format.errors import FormatError, PathEscapeError
from robogs.format.kinematics import Chain
from robogs.format.mjcf_robot import (
    ROBOT_ARMATURE,
    add_robot,
    robot_document,
    robot_mjcf,
    robot_qpos,
)
from robogs.format.urdf import load_urdf

from .conftest import REAL_URDFS

TOL = 1e-6  # m, and rotation-matrix entries (rad for small angles)

ROBOT = """<?xml version="1.0"?>
<robot name="fixture_arm">
  <link name="base">
    <inertial><origin xyz="0 0 0.04"/><mass value="3"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial>
    <visual><geometry><mesh filename="package://fixture_description/meshes/base.dae"/></geometry>
    </visual>
    <collision><geometry><cylinder radius="0.06" length="0.08"/></geometry></collision>
  </link>
  <link name="upper">
    <inertial><origin xyz="0.01 0.02 0.15" rpy="0.1 -0.2 0.3"/><mass value="1.2"/>
      <inertia ixx="0.004" ixy="0.0005" ixz="-0.0002" iyy="0.005" iyz="0.0003" izz="0.003"/>
    </inertial>
    <visual><origin xyz="0 0 0.15" rpy="0 0.1 0"/>
      <geometry><mesh filename="../meshes/upper.ply" scale="1 1 2"/></geometry></visual>
    <collision><geometry><mesh filename="package://fixture_description/meshes/upper.stl"/>
    </geometry></collision>
  </link>
  <link name="fore"/>
  <link name="slider">
    <inertial><mass value="0.4"/>
      <inertia ixx="0.0004" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0002"/></inertial>
    <visual><geometry><box size="0.05 0.03 0.02"/></geometry></visual>
  </link>
  <link name="finger_a">
    <inertial><mass value="0.05"/>
      <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
    <collision><geometry><sphere radius="0.01"/></geometry></collision>
  </link>
  <link name="finger_b">
    <inertial><mass value="0.05"/>
      <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>
  </link>
  <link name="tool"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0.01 -0.02 0.08" rpy="0.2 -0.1 0.4"/>
    <axis xyz="0.3 -0.2 0.9"/>
    <limit lower="-2.1" upper="1.7" effort="50" velocity="2"/>
  </joint>
  <joint name="elbow" type="continuous">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0.02 0.0 0.3" rpy="1.2 0.3 -0.7"/>
    <axis xyz="0 1 0"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="fore"/><child link="slider"/>
    <origin xyz="0.1 0.02 -0.03" rpy="-0.4 0.25 1.9"/>
    <axis xyz="1 0 1"/>
    <limit lower="-0.05" upper="0.15" effort="100" velocity="0.3"/>
  </joint>
  <joint name="finger_a_joint" type="prismatic">
    <parent link="slider"/><child link="finger_a"/>
    <origin xyz="0 0.02 0.05" rpy="0 0 0.3"/>
    <axis xyz="0 1 0"/>
    <limit lower="0" upper="0.04" effort="10" velocity="0.1"/>
  </joint>
  <joint name="finger_b_joint" type="prismatic">
    <parent link="slider"/><child link="finger_b"/>
    <origin xyz="0 -0.02 0.05" rpy="0 0 -0.3"/>
    <axis xyz="0 -1 0"/>
    <limit lower="0" upper="0.04" effort="10" velocity="0.1"/>
    <mimic joint="finger_a_joint" multiplier="0.8" offset="0.003"/>
  </joint>
  <joint name="tool_joint" type="fixed">
    <parent link="slider"/><child link="tool"/>
    <origin xyz="0 0 0.12" rpy="3.0 0.1 -1.2"/>
  </joint>
</robot>
"""

PACKAGE_XML = "<package><name>fixture_description</name></package>\n"


def _meshes() -> dict[str, trimesh.Trimesh]:
    base = trimesh.creation.cylinder(radius=0.06, height=0.08, sections=11)
    upper = trimesh.creation.capsule(height=0.25, radius=0.03, count=[8, 8])
    return {"base.dae": base, "upper.ply": upper, "upper.stl": upper.convex_hull}


def write_fixture(folder: Path, urdf: str = ROBOT) -> Path:
    """The fixture robot as a ROS package under ``folder``; returns the URDF path."""
    pkg = folder / "fixture_description"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    (pkg / "package.xml").write_text(PACKAGE_XML)
    for name, mesh in _meshes().items():
        kind = name.rsplit(".", 1)[1]
        data = (
            trimesh.exchange.dae.export_collada(mesh)
            if kind == "dae"
            else mesh.export(file_type=kind)
        )
        (pkg / "meshes" / name).write_bytes(data)
    path = pkg / "urdf" / "robot.urdf"
    path.write_text(urdf)
    return path


def fk_gap(robot, chain: Chain, qs: np.ndarray) -> tuple[float, float]:
    """Worst (position m, rotation-matrix entry) gap between MuJoCo's link bodies and the chain,
    over the joint vectors ``qs`` [B, J] (``chain.joint_names`` order)."""
    assert robot.actuated == chain.joint_names
    model = mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)
    data = mujoco.MjData(model)
    adr = [model.joint(j).qposadr[0] for j in robot.joints]
    T = chain.forward(torch.from_numpy(qs)).numpy()
    worst_p = worst_r = 0.0
    for b, q in enumerate(qs):
        data.qpos[adr] = robot_qpos(robot, q)
        mujoco.mj_kinematics(model, data)
        for k, link in enumerate(chain.link_names):
            i = model.body(robot.links[link]).id
            worst_p = max(worst_p, float(np.abs(data.xpos[i] - T[b, k, :3, 3]).max()))
            R = data.xmat[i].reshape(3, 3)
            worst_r = max(worst_r, float(np.abs(R - T[b, k, :3, :3]).max()))
    return worst_p, worst_r


def random_q(chain: Chain, n: int, seed: int) -> np.ndarray:
    lo = np.where(np.isfinite(chain.joint_lower), chain.joint_lower, -math.pi)
    hi = np.where(np.isfinite(chain.joint_upper), chain.joint_upper, math.pi)
    return np.random.default_rng(seed).uniform(lo, hi, size=(n, chain.num_joints))


@pytest.fixture(scope="module")
def fixture_robot(tmp_path_factory):
    path = write_fixture(tmp_path_factory.mktemp("mjcf_robot"))
    robot = robot_mjcf(path)
    chain = Chain.from_urdf(load_urdf(path, load_meshes=False))
    return path, robot, chain


def test_fixture_robot_fk_matches_the_chain(fixture_robot) -> None:
    _, robot, chain = fixture_robot
    gap = fk_gap(robot, chain, random_q(chain, 40, seed=3))
    assert max(gap) < TOL, gap


def test_joints_limits_and_mimic_are_the_urdfs(fixture_robot) -> None:
    path, robot, chain = fixture_robot
    model = mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)
    urdf = load_urdf(path, load_meshes=False)
    moving = [j for j in urdf.robot.joints if j.type != "fixed"]
    assert model.njnt == len(moving) == len(robot.joints) == 5
    assert model.nbody == 1 + len(urdf.robot.links)  # every link a body (fusestatic off)
    for i, name in enumerate(chain.joint_names):
        j = model.joint(name)
        lo, hi = chain.joint_lower[i], chain.joint_upper[i]
        if np.isfinite(lo):
            assert j.limited[0] == 1 and tuple(j.range) == (lo, hi), name
        else:
            assert j.limited[0] == 0, name  # continuous
        assert model.dof_armature[j.dofadr[0]] == ROBOT_ARMATURE
    types = {j.name: j.type for j in moving}
    for j in robot.joints:
        want = (
            mujoco.mjtJoint.mjJNT_SLIDE if types[j] == "prismatic" else mujoco.mjtJoint.mjJNT_HINGE
        )
        assert model.joint(j).type[0] == want, j
    assert robot.mimic == {"finger_b_joint": ("finger_a_joint", 0.8, 0.003)}
    assert model.neq == 1
    assert model.eq_data[0, :2].tolist() == [0.003, 0.8]
    # the robot acts on nothing: no geom collides, every body is gravity compensated
    assert not model.geom_contype.any() and not model.geom_conaffinity.any()
    assert np.all(model.body_gravcomp[1:] == 1.0)


def test_masses_and_inertia_are_the_urdfs(fixture_robot) -> None:
    path, robot, _ = fixture_robot
    model = mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)
    urdf = load_urdf(path, load_meshes=False)
    for link in urdf.robot.links:
        body = model.body(robot.links[link.name])
        if link.inertial is None:
            continue
        assert body.mass[0] == pytest.approx(float(link.inertial.mass), rel=1e-12)
        I_urdf = np.asarray(link.inertial.inertia, dtype=float)
        origin = link.inertial.origin
        T_urdf = np.eye(4) if origin is None else np.asarray(origin, dtype=float)
        R_urdf = T_urdf[:3, :3]
        np.testing.assert_allclose(body.ipos, T_urdf[:3, 3], atol=1e-15)
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, body.iquat)
        R = R.reshape(3, 3)
        I_mj = R @ np.diag(body.inertia) @ R.T  # in the link frame
        np.testing.assert_allclose(I_mj, R_urdf @ I_urdf @ R_urdf.T, atol=1e-15)
    # 'fore' has no <inertial> but moves: the declared frame mass
    assert model.body("fore").mass[0] == pytest.approx(1e-6)
    assert any("fore" in n for n in robot.notes)


def test_meshes_keep_their_vertex_count(fixture_robot) -> None:
    _, robot, _ = fixture_robot
    src = _meshes()
    by_name = {c.source.name: c for c in robot.conversions}
    assert {c.action for c in by_name.values()} == {"converted", "copied"}
    assert by_name["base.dae"].file.endswith(".obj") and by_name["upper.ply"].file.endswith(".obj")
    assert by_name["upper.stl"].file.endswith(".stl")
    model = mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)
    for name, conv in by_name.items():
        want = len(np.unique(np.asarray(src[name].vertices), axis=0))
        assert conv.vertices_in == conv.vertices_out == want, name
        mesh_id = next(
            i
            for i in range(model.nmesh)
            if robot.files.get(conv.file) and model.mesh(i).name == Path(conv.file).stem
        )
        assert model.mesh_vertnum[mesh_id] == want, name
    # the PLY mesh keeps its URDF scale
    from scipy.spatial.distance import pdist

    m = model.mesh("robot_upper")
    v = model.mesh_vert[m.vertadr[0] : m.vertadr[0] + m.vertnum[0]]
    want = pdist(np.asarray(src["upper.ply"].vertices) * (1.0, 1.0, 2.0)).max()
    assert pdist(v).max() == pytest.approx(want, rel=1e-6)  # MuJoCo stores float32
    assert all(f.startswith("meshes/robot/") and ".." not in f for f in robot.files)


def test_a_swapped_axis_is_caught_by_the_fk_comparison(tmp_path, fixture_robot) -> None:
    """Mutation: the elbow's axis y -> z in the URDF MuJoCo reads; the chain keeps the original."""
    _, _, chain = fixture_robot
    bad = ROBOT.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 1"/>', 1)
    assert bad != ROBOT
    robot = robot_mjcf(write_fixture(tmp_path, bad), meshes=False)
    pos, rot = fk_gap(robot, chain, random_q(chain, 10, seed=5))
    assert pos > 1e3 * TOL and rot > 1e3 * TOL, (pos, rot)


def test_add_robot_keeps_the_scene_indices_and_starts_at_q0(fixture_robot) -> None:
    """The robot goes after the scene's bodies and actuators; the keyframe gets q0."""
    from robogs.format.mjcf import scene_mjcf

    _, robot, chain = fixture_robot
    box = {"equation": "rigid", "mass_kg": 0.4, "size_m": [0.08, 0.06, 0.05]}
    physics = {"objects": {"box": box, "table": {"equation": "static"}, "pusher": {}}}
    scene = scene_mjcf(physics, poses={"box": [0.3, 0, 0.025, 1, 0, 0, 0]})
    q0 = random_q(chain, 1, seed=8)[0]
    xml, servos = add_robot(scene.xml, robot, q0)
    alone = mujoco.MjModel.from_xml_string(scene.xml)
    model = mujoco.MjModel.from_xml_string(xml, robot.files)
    assert [model.joint(i).name for i in range(alone.njnt)] == [
        alone.joint(i).name for i in range(alone.njnt)
    ]
    assert [model.actuator(i).name for i in range(alone.nu)] == [
        alone.actuator(i).name for i in range(alone.nu)
    ]
    assert servos == [f"robot_{j}" for j in chain.joint_names] + [
        f"robot_v_{j}" for j in chain.joint_names
    ]
    assert model.npair == alone.npair
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    np.testing.assert_array_equal(data.qpos[: alone.nq], alone.key("start").qpos)
    np.testing.assert_array_equal(data.ctrl[alone.nu : alone.nu + chain.num_joints], q0)
    mujoco.mj_kinematics(model, data)
    T = chain.forward(torch.from_numpy(q0)).numpy()
    for k, link in enumerate(chain.link_names):
        np.testing.assert_allclose(data.xpos[model.body(link).id], T[k, :3, 3], atol=TOL)
    with pytest.raises(FormatError, match="already used"):
        add_robot(xml, robot)
    # with a prefix the robot goes in a second time, FK unchanged under the new names
    path = fixture_robot[0]
    again = robot_mjcf(path, meshes=False, prefix="robot/")
    assert again.links["tool"] == "robot/tool" and again.joints[0] == "robot/shoulder"
    xml2, servos2 = add_robot(xml, again, q0)
    assert servos2[0] == "robot_robot/shoulder"
    model2 = mujoco.MjModel.from_xml_string(xml2, robot.files)
    data2 = mujoco.MjData(model2)
    mujoco.mj_resetDataKeyframe(model2, data2, model2.key("start").id)
    mujoco.mj_kinematics(model2, data2)
    for k, link in enumerate(chain.link_names):
        i = model2.body(again.links[link]).id
        np.testing.assert_allclose(data2.xpos[i], T[k, :3, 3], atol=TOL)


# --------------------------------------------------------------------------- hostile input


@pytest.mark.parametrize(
    ("uri", "error"),
    [
        ("../../../outside.stl", PathEscapeError),
        ("package://fixture_description/../../outside.stl", PathEscapeError),
        ("file:///etc/passwd", PathEscapeError),
        ("/etc/hosts", PathEscapeError),
        ("package://fixture_description/meshes/missing.stl", FormatError),
    ],
)
def test_hostile_or_missing_mesh_is_refused(tmp_path, uri, error) -> None:
    (tmp_path / "outside.stl").write_bytes(trimesh.creation.box().export(file_type="stl"))
    bad = ROBOT.replace("package://fixture_description/meshes/upper.stl", uri)
    path = write_fixture(tmp_path / "inner" / "deeper", bad)
    with pytest.raises(error) as err:
        robot_mjcf(path, root=path.parents[1])
    assert err.value.where and "upper" in err.value.where  # names the link and the URI


def test_entities_and_bad_meshdir_are_refused(tmp_path) -> None:
    bomb = '<?xml version="1.0"?>\n<!DOCTYPE r [<!ENTITY a "aaaa">]>\n' + ROBOT.split("\n", 1)[1]
    with pytest.raises(FormatError, match="entities"):
        robot_mjcf(write_fixture(tmp_path / "a", bomb))
    with pytest.raises(FormatError, match="meshdir"):
        robot_mjcf(write_fixture(tmp_path / "b"), meshdir="../up/")


def test_a_mesh_mujoco_refuses_is_kept_as_shell_or_dropped_and_said(tmp_path) -> None:
    """A 10 um cube (volume too small for MuJoCo) is kept with inertia='shell', a single
    triangle (fewer than 4 vertices, no hull) is dropped; both are in the notes."""
    path = write_fixture(tmp_path)
    meshes = path.parents[1] / "meshes"
    trimesh.creation.box((1e-5, 1e-5, 1e-5)).export(meshes / "tiny.obj")
    tri = trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], [[0, 1, 2]])
    tri.export(meshes / "tri.stl")
    text = path.read_text().replace(
        '<link name="tool"/>',
        '<link name="tool"><visual><geometry><mesh filename="../meshes/tiny.obj"/></geometry>'
        '</visual><visual><geometry><mesh filename="../meshes/tri.stl"/></geometry></visual>'
        "</link>",
    )
    path.write_text(text)
    robot = robot_mjcf(path, meshes=True)
    by_name = {c.source.name: c for c in robot.conversions}
    assert by_name["tiny.obj"].shell and by_name["tiny.obj"].vertices_out == 8
    assert by_name["tri.stl"].action == "dropped" and by_name["tri.stl"].file is None
    assert any("tiny.obj" in n and "shell" in n for n in robot.notes)
    assert any("tri.stl" in n and "dropped" in n for n in robot.notes)
    model = mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)
    tool = model.body("tool").id
    assert int((model.geom_bodyid == tool).sum()) == 1  # the tiny cube only


# --------------------------------------------------------------------------- real arms


@pytest.mark.realdata
@pytest.mark.parametrize("name", sorted(REAL_URDFS))
def test_real_urdf_fk_matches_the_chain(name: str, real_urdf_args) -> None:
    path, root, pkgs = real_urdf_args(name)
    robot = robot_mjcf(path, root=root, package_roots=pkgs, meshes=False)
    chain = Chain.from_urdf(load_urdf(path, root=root, package_roots=pkgs, load_meshes=False))
    model = mujoco.MjModel.from_xml_string(robot_document(robot))
    moving = [j for j in chain.joint_types if j != "fixed"]
    # every link a body; a root link named 'world' is MuJoCo's world body (UR5)
    assert model.njnt == len(moving)
    assert model.nbody == chain.num_links + (chain.link_names[0] != "world")
    for i, j in enumerate(chain.joint_names):
        if np.isfinite(chain.joint_lower[i]):
            assert tuple(model.joint(j).range) == (chain.joint_lower[i], chain.joint_upper[i])
    gap = fk_gap(robot, chain, random_q(chain, 25, seed=11))
    assert max(gap) < TOL, gap


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["ur5", "dobot_cr3"])
def test_real_meshes_convert_with_their_vertex_count(name: str, real_urdf_args) -> None:
    """UR5: COLLADA visuals -> OBJ, STL collisions copied; CR3: STL. Every mesh compiles with
    the vertex count trimesh reads from the source (STL: its distinct positions)."""
    path, root, pkgs = real_urdf_args(name)
    robot = robot_mjcf(path, root=root, package_roots=pkgs)
    assert robot.conversions and not robot.notes
    for conv in robot.conversions:
        mesh = trimesh.load(conv.source, force="mesh", process=False)
        v = np.asarray(mesh.vertices)
        want = len(np.unique(v, axis=0)) if conv.source.suffix.lower() == ".stl" else len(v)
        assert conv.vertices_in == conv.vertices_out == want, conv
    mujoco.MjModel.from_xml_string(robot_document(robot), robot.files)

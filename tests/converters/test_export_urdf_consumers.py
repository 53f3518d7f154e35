"""The URDF export opens in the tools that consume URDF: yourdfpy, MuJoCo and pybullet.

Oracles: link poses are the dataset's forward kinematics (``robogs.format.kinematics.Chain`` on
the dataset URDF) at the scene's joint positions, object poses are the dataset's first
``object_poses`` sample (or the manifest pose), and masses are the dataset URDF's and
``physics.json``'s, plus the tiny frame inertials the sidecar declares.
"""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
import yourdfpy

from robogs.convert.export import export
from robogs.convert.export.urdf_physics import FRAME_MASS_KG
from robogs.convert.export.urdf_scene import pose_matrix
from robogs.format import Dataset
from robogs.format.kinematics import Chain

try:
    from .test_export_data import build_tiny_dataset
except ImportError:
    from test_export_data import build_tiny_dataset


@pytest.fixture(scope="module", params=["tiny", "synth"])
def exported(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """(dataset, export folder, sidecar) for the tiny arm and the synthetic UR5 push scene."""
    root = tmp_path_factory.mktemp(f"consumers-{request.param}")
    if request.param == "tiny":
        ds = build_tiny_dataset(root / "ds")
    else:
        from robogs.synth.scene import synthesize

        synthesize(root / "ds", seed=0, size="small")
        ds = Dataset.open(root / "ds")
    out = root / "out"
    export("urdf", ds, out)
    sidecar = json.loads(next(out.glob("*.contact.json")).read_text())
    return ds, out, sidecar


def _truth(ds: Dataset, sidecar: dict) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """T_world_link of every robot link at the scene's joint positions (the dataset's FK) and
    every link's mass (the dataset's, or the declared frame mass)."""
    ref = ds.urdf(load_meshes=False)
    chain = Chain.from_urdf(ref)
    q = sidecar["scene"]["joint_positions"]
    T = chain.forward(np.array([q[j] for j in chain.joint_names])).numpy()
    poses = {name: T[k] for k, name in enumerate(chain.link_names)}
    frames = set(sidecar.get("frame_inertials", {}).get("links", []))
    masses = {}
    for link in ref.robot.links:
        if link.inertial is not None:
            masses[link.name] = float(link.inertial.mass)
        elif link.name in frames:
            masses[link.name] = FRAME_MASS_KG
    return poses, masses


def test_scene_poses_are_the_datasets(exported) -> None:
    ds, _, sidecar = exported
    scene = sidecar["scene"]
    ep = ds.episodes[0]
    assert scene["episode"] == ep.id and scene["t_ns"] == ep.start_ns
    js = ep.table("joint_states").sort_by("t_ns")
    assert scene["joint_positions_t_ns"] == js.column("t_ns")[0].as_py()
    for j, v in scene["joint_positions"].items():
        assert v == js.column(f"position.{j}")[0].as_py()
    poses = ep.table("object_poses").sort_by("t_ns")
    for name, entry in scene["objects"].items():
        if entry["source"] == "object_poses":
            i = poses.column("object").to_pylist().index(name)
            row = [poses.column(c)[i].as_py() for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]
            assert (entry["pose"], entry["t_ns"]) == (row, poses.column("t_ns")[i].as_py())
        elif entry["source"] == "manifest":
            assert entry["pose"] == ds.assets[name]["pose"]
    assert {e["source"] for e in scene["objects"].values()} >= {"object_poses"}


def test_yourdfpy_loads_the_scene(exported) -> None:
    ds, out, sidecar = exported
    poses, masses = _truth(ds, sidecar)
    scene = yourdfpy.URDF.load(
        str(out / "scene.urdf"),
        mesh_dir=str(out),
        build_collision_scene_graph=True,
        load_collision_meshes=True,
    )
    scene.update_cfg({j: v for j, v in sidecar["scene"]["joint_positions"].items()})
    world = sidecar["scene"]["root_link"]
    for link, T in poses.items():
        np.testing.assert_allclose(scene.get_transform(link, world), T, atol=1e-12, err_msg=link)
        inertial = scene.link_map[link].inertial
        if link in masses:
            assert float(inertial.mass) == masses[link], link
        else:  # only a root link may have no inertial (it does not move)
            assert inertial is None and link == ds.urdf(load_meshes=False).base_link
    for name, entry in sidecar["scene"]["objects"].items():
        np.testing.assert_allclose(
            scene.get_transform(name, world), pose_matrix(entry["pose"]), atol=1e-12
        )
    # every collision geometry loaded (no mesh dropped as unreadable)
    n_meshes = sum(len(lk.collisions) for lk in scene.robot.links)
    assert len(scene.collision_scene.geometry) == n_meshes


def _fused_owner(ref: yourdfpy.URDF, link: str) -> str | None:
    """The MuJoCo body a link ends up in: fixed joints are fused into the parent (MuJoCo's URDF
    default ``fusestatic``); None for the world body."""
    parent_joint = {j.child: j for j in ref.robot.joints}
    while link in parent_joint:
        j = parent_joint[link]
        if j.type != "fixed":
            return link
        link = j.parent
    return None


def test_mujoco_compiles_steps_and_matches(exported) -> None:
    ds, out, sidecar = exported
    poses, masses = _truth(ds, sidecar)
    ref = ds.urdf(load_meshes=False)
    model = mujoco.MjModel.from_xml_path(str(out / "scene.urdf"))
    moving = [j for j in ref.robot.joints if j.type != "fixed"]
    floating = [n for n, e in sidecar["scene"]["objects"].items() if e["joint"] == "floating"]
    assert model.nbody == 1 + len(moving) + len(floating)
    # masses: each body holds its link plus the links fused into it
    want: dict[str, float] = {}
    for link, m in masses.items():
        owner = _fused_owner(ref, link)
        if owner is not None:
            want[owner] = want.get(owner, 0.0) + m
    for body, m in want.items():
        assert model.body(body).mass[0] == pytest.approx(m, rel=1e-12), body
    phys = ds.physics()
    for name in floating:
        assert model.body(name).mass[0] == phys["objects"][name]["mass_kg"]
        assert model.jnt_type[model.body(name).jntadr[0]] == mujoco.mjtJoint.mjJNT_FREE
    # link and object poses at the scene's joint positions
    data = mujoco.MjData(model)
    for j, v in sidecar["scene"]["joint_positions"].items():
        data.qpos[model.joint(j).qposadr[0]] = v
    mujoco.mj_forward(model, data)
    for j in moving:
        T = poses[j.child]
        np.testing.assert_allclose(data.xpos[model.body(j.child).id], T[:3, 3], atol=1e-9)
        np.testing.assert_allclose(
            data.xmat[model.body(j.child).id].reshape(3, 3), T[:3, :3], atol=1e-9
        )
    for name in floating:
        T = pose_matrix(sidecar["scene"]["objects"][name]["pose"])
        np.testing.assert_allclose(data.xpos[model.body(name).id], T[:3, 3], atol=1e-9)
    mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)) and data.time > 0
    # the robot alone and each object alone compile too
    robot = mujoco.MjModel.from_xml_path(str(out / sidecar["urdf"]))
    assert robot.nbody == 1 + len(moving)
    for entry in sidecar["objects"].values():
        mujoco.MjModel.from_xml_path(str(out / entry["urdf"]))


def test_pybullet_loads_robot_and_objects(exported) -> None:
    pb = pytest.importorskip(
        "pybullet", reason="pybullet is optional (no wheel for every platform; it may not build)"
    )
    ds, out, sidecar = exported
    poses, masses = _truth(ds, sidecar)
    client = pb.connect(pb.DIRECT)
    try:
        robot = pb.loadURDF(str(out / sidecar["urdf"]), useFixedBase=True, physicsClientId=client)
        n = pb.getNumJoints(robot, physicsClientId=client)
        q = sidecar["scene"]["joint_positions"]
        infos = [pb.getJointInfo(robot, i, physicsClientId=client) for i in range(n)]
        for i, info in enumerate(infos):
            if info[1].decode() in q:
                pb.resetJointState(robot, i, q[info[1].decode()], physicsClientId=client)
        for i, info in enumerate(infos):
            link = info[12].decode()
            mass = pb.getDynamicsInfo(robot, i, physicsClientId=client)[0]
            assert mass == pytest.approx(masses[link], rel=1e-9), link  # never pybullet's 1 kg
            state = pb.getLinkState(robot, i, computeForwardKinematics=True, physicsClientId=client)
            np.testing.assert_allclose(state[4], poses[link][:3, 3], atol=1e-6, err_msg=link)
            R = np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            np.testing.assert_allclose(R, poses[link][:3, :3], atol=1e-6, err_msg=link)
        # objects: their own URDF, placed at the sidecar pose (pybullet has no floating joint)
        phys = ds.physics()
        for name, entry in sidecar["objects"].items():
            pose = sidecar["scene"]["objects"][name]["pose"]
            x, y, z, w, qx, qy, qz = pose
            body = pb.loadURDF(
                str(out / entry["urdf"]),
                basePosition=[x, y, z],
                baseOrientation=[qx, qy, qz, w],
                useFixedBase=sidecar["scene"]["objects"][name]["joint"] == "fixed",
                physicsClientId=client,
            )
            pos, _ = pb.getBasePositionAndOrientation(body, physicsClientId=client)
            com = np.asarray(phys["objects"][name].get("com_m", [0, 0, 0]), dtype=float)
            want = pose_matrix(pose) @ np.append(com, 1.0)  # pybullet reports the CoM
            np.testing.assert_allclose(pos, want[:3], atol=1e-6)
            if "mass_kg" in phys["objects"][name] and entry.get("equation") == "rigid":
                m = pb.getDynamicsInfo(body, -1, physicsClientId=client)[0]
                assert m == phys["objects"][name]["mass_kg"]
        pb.stepSimulation(physicsClientId=client)
    finally:
        pb.disconnect(client)

"""``robogs export mjcf`` with a robot: the URDF arm in the scene document, its recorded joint
trajectory beside it, replayable, and the scene's own model untouched.

Oracles: the dataset's ``joint_states`` table (the trajectory file), robogs' URDF forward
kinematics (:class:`robogs.format.kinematics.Chain`) at every recorded sample (the compiled
document's ``mj_kinematics``, 1e-6 m / 1e-6), and the scene document without the robot
(:func:`robogs.format.mjcf.scene_mjcf`, what the ``mujoco`` engine compiles): same joints,
actuators and pairs first, and the same object motion when both are stepped.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from robogs.convert.export import export
from robogs.convert.export.mjcf import TRAJECTORY_FILE
from robogs.format.kinematics import Chain

try:
    from .test_export_data import build_tiny_dataset
except ImportError:
    from test_export_data import build_tiny_dataset

TOL = 1e-6


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    root = tmp_path_factory.mktemp("mjcf_robot")
    ds = build_tiny_dataset(root / "ds")
    report = export("mjcf", ds, root / "out")
    model = mujoco.MjModel.from_xml_path(str(root / "out" / "scene.xml"))
    return ds, root / "out", report, model


def test_files_and_notes(exported) -> None:
    _, out, report, _ = exported
    assert report.files == [
        "scene.xml",
        "meshes/box_hull.stl",
        "meshes/robot/robot_base.stl",
        "meshes/robot/robot_link1.obj",
        TRAJECTORY_FILE,
    ]
    assert all((out / f).is_file() for f in report.files)
    rob = report.facts["robot"]
    assert rob["actuated"] == ["j1", "j2"] and rob["joints"] == ["j1", "j2"]
    assert {m["source"]: m["action"] for m in rob["meshes"]} == {
        "base.stl": "copied",
        "link1.ply": "converted",
    }
    assert all(m["vertices_in"] == m["vertices_out"] for m in rob["meshes"])
    assert any("kinematic" in n for n in report.notes)
    assert "kinematic" in (out / "scene.xml").read_text()  # the <custom> remark


def test_trajectory_file_is_the_joint_states_table(exported) -> None:
    ds, out, report, _ = exported
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    with np.load(out / TRAJECTORY_FILE) as npz:
        assert npz["joint_names"].tolist() == chain.joint_names
        assert npz["episodes"].tolist() == [ep.id for ep in ds.episodes]
        tab = ds.episodes[0].table("joint_states").sort_by("t_ns")
        np.testing.assert_array_equal(npz["t_ns_0"], tab.column("t_ns").to_numpy())
        for i, j in enumerate(chain.joint_names):
            np.testing.assert_array_equal(npz["q_0"][:, i], tab.column(f"position.{j}").to_numpy())
    assert report.facts["robot"]["trajectory"]["samples"] == [tab.num_rows]


def test_fk_at_every_recorded_sample_and_the_start_keyframe(exported) -> None:
    ds, out, _, model = exported
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    with np.load(out / TRAJECTORY_FILE) as npz:
        q = npz["q_0"]
    T = chain.forward(torch.from_numpy(q)).numpy()
    data = mujoco.MjData(model)
    adr = [model.joint(j).qposadr[0] for j in chain.joint_names]
    ids = [model.body(link).id for link in chain.link_names]
    worst = 0.0
    for k in range(len(q)):
        data.qpos[adr] = q[k]
        mujoco.mj_kinematics(model, data)
        worst = max(worst, float(np.abs(data.xpos[ids] - T[k, :, :3, 3]).max()))
        R = data.xmat[ids].reshape(-1, 3, 3)
        worst = max(worst, float(np.abs(R - T[k, :, :3, :3]).max()))
    assert worst < TOL, worst
    mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    np.testing.assert_array_equal(data.qpos[adr], q[0])
    nu = len(chain.joint_names)
    np.testing.assert_array_equal(data.ctrl[-2 * nu : -nu], q[0])


def test_scene_part_is_the_engines_and_the_robot_moves_nothing(exported) -> None:
    """The scene's joints, actuators and pairs come first and equal the robot-less document's;
    stepping both with the robot replayed through its servos, the box moves the same (within
    the solver's tolerance), and the servos track the recorded joints."""
    from robogs.convert.export.urdf_scene import scene_state
    from robogs.format.mjcf import scene_mjcf

    ds, out, report, model = exported
    physics = ds.physics()
    poses = {n: p.pose for n, p in scene_state(ds, ["box"]).objects.items()}
    alone = mujoco.MjModel.from_xml_string(
        scene_mjcf(physics, meshes={"box": ds.mesh("box")}, poses=poses, meshdir="meshes/").xml,
        {"meshes/box_hull.stl": (out / "meshes" / "box_hull.stl").read_bytes()},
    )
    assert [model.joint(i).name for i in range(alone.njnt)] == [
        alone.joint(i).name for i in range(alone.njnt)
    ]
    assert model.npair == alone.npair
    np.testing.assert_array_equal(model.pair_friction, alone.pair_friction)
    servos = report.facts["robot"]["servos"]
    assert [model.actuator(alone.nu + i).name for i in range(len(servos))] == servos

    with np.load(out / TRAJECTORY_FILE) as npz:
        t, q = (npz["t_ns_0"] - npz["t_ns_0"][0]) * 1e-9, npz["q_0"]
    dt = model.opt.timestep
    grid = np.arange(0.0, t[-1], dt)
    qg = np.stack([np.interp(grid, t, q[:, i]) for i in range(q.shape[1])], -1)
    d, d0 = mujoco.MjData(model), mujoco.MjData(alone)
    mujoco.mj_resetDataKeyframe(model, d, model.key("start").id)
    mujoco.mj_resetDataKeyframe(alone, d0, alone.key("start").id)
    nu, J = alone.nu, q.shape[1]
    adr = [model.joint(j).qposadr[0] for j in ("j1", "j2")]
    d.qpos[adr] = qg[0]
    d.qvel[[model.joint(j).dofadr[0] for j in ("j1", "j2")]] = (qg[1] - qg[0]) / dt
    track = 0.0
    for k in range(len(grid) - 1):  # the pusher's convention (docs/exports.md)
        d.ctrl[nu : nu + J] = qg[k]
        d.ctrl[nu + J : nu + 2 * J] = (qg[k + 1] - qg[k]) / dt
        mujoco.mj_step(model, d)
        mujoco.mj_step(alone, d0)
        track = max(track, float(np.abs(d.qpos[adr] - qg[k + 1]).max()))
    assert len(grid) > 500
    # the box: the same motion with and without the robot (it settles on the table). Measured
    # 1.5e-9 m: the moving robot's dofs enter the Newton solver's stopping test (with the robot
    # at rest the gap is 6e-17 m); bound 1e-7 m. Tracking: measured 7.1e-8 (rad, m)
    gap = float(np.abs(d.qpos[: alone.nq] - d0.qpos).max())
    assert gap < 1e-7, gap
    assert track < 1e-6, track  # rad or m


def test_the_docs_replay_block_runs(exported, tmp_path, monkeypatch) -> None:
    """docs/exports.md's robot replay, run as written next to this export."""
    import re
    import shutil
    from pathlib import Path

    _, out, _, _ = exported
    doc = (Path(__file__).resolve().parents[2] / "docs" / "exports.md").read_text()
    section = doc[doc.index("## MJCF") :]
    section = section[: section.index("\n## ", 1)]
    (block,) = re.findall(r"```python\n(.*?)```", section, re.S)
    shutil.copytree(out, tmp_path / "scene_mjcf")
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "__docs__"}
    exec(compile(block, "docs/exports.md (MJCF robot replay)", "exec"), ns)
    assert len(ns["grid"]) > 500 and ns["worst"] < 1e-6

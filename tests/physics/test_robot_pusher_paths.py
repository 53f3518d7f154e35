"""``objects.pusher.geometry = "robot"`` on its other paths (issue 16, h71).

Oracles (the gantry dataset of ``init_scene``, seed 7: prismatic x, y, z and a yaw joint, the
``tool`` link fixed 20 mm along the wrist's x, its collision a 12 mm sphere 40 mm below it; joints
at 200 Hz, noise-free):

* ``robogs render --simulate`` pushes with the robot pusher ``compare`` gets: its links' frames
  equal ``load_recording``'s and its box path equals the path of the engine built with the
  recording's shapes, on the same drive, within 1e-9 m; the primitive of ``objects.pusher``
  (here a 6 mm sphere, not the URDF's 12 mm one) leaves a different path (counterfactual);
* the ``ee_poses``-only path (no ``joint_states``; the pusher link ``wrist`` with ``tool`` below
  it on a fixed joint; the wrist pose written in closed form, trans(jx, jy, jz) Rz(jyaw)) gives
  the same robot pusher and the same box path as the ``joint_states`` path, within 1e-9 m;
* the rigidity budget: the second-difference noise estimate recovers a known white noise on a
  smooth path; a rigid robot whose end-effector orientation is recorded with 1 deg noise is
  accepted (the 2 mm ``geometry.box3d_mm`` alone, and the former 0.23 deg constant, would refuse
  it); a prismatic finger sweeping 10 mm is refused naming the finger and 5 mm (its largest
  distance from the constant pose), and ``robogs compare`` exits 2 with that one line;
* a URDF whose pusher links carry no collision geometry: ``robogs compare`` exits 2 with one
  line naming the links and the fix.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import torch

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.engines.mujoco_robot import pose_noise, pusher_frames

torch.set_num_threads(1)

DT = 1e-3


def _gantry(root: Path, *settings: str) -> Path:
    from init_scene import write_scene

    from robogs.physics.init import init_physics, set_physics_values

    write_scene(root, seed=7)
    init_physics(root, objects=["box=material:wood"])
    set_physics_values(root, ["objects.pusher.geometry=robot", *settings])
    return root


@pytest.fixture(scope="module")
def gantry(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The gantry dataset with the robot pusher and a 6 mm primitive (the URDF sphere: 12 mm)."""
    return _gantry(tmp_path_factory.mktemp("h71") / "ds", "objects.pusher.radius_m=0.006")


def _rollout(physics: dict, meshes: dict, drive, start=None) -> np.ndarray:
    eng = MujocoEngine(physics, object_name="box", meshes=meshes, dt=DT, threads=1)
    return eng.rollout(drive, start).pos["box"][0]


def test_render_simulate_pushes_with_compare_s_robot_pusher(gantry: Path) -> None:
    from robogs.cli.render_cmd import simulate_objects, simulation_setup
    from robogs.format.kinematics import Chain
    from robogs.format.render_trajectory import episode_trajectory
    from robogs.physics.recording import load_recording

    ds = Dataset.open(gantry)
    ep = ds.episode("push0")
    traj = episode_trajectory(ep, Chain.from_urdf(ds.urdf(load_meshes=False)), {})
    traj = replace(traj, t_ns=traj.t_ns[:600], q=traj.q[:600])  # 3 s: approach and push
    poses, desc, notes = simulate_objects(ds, ep, traj)
    assert "simulated by the mujoco engine" in desc
    assert any("robot's links tool" in n and "commanded trajectory" in n for n in notes)
    st = simulation_setup(ds, ep, traj)
    rec = load_recording(ds)  # what compare reads
    mine, theirs = st.shapes.meshes["pusher"], rec.robot_pusher
    assert list(mine.frames) == list(theirs.frames) == ["tool"]
    assert np.abs(mine.frames["tool"] - theirs.frames["tool"]).max() < 1e-12
    want = _rollout(rec.physics, rec.shapes().meshes, st.drive, st.start)[0]
    got = poses["box"][1]
    assert np.linalg.norm(got[-1] - got[0]) > 0.05  # the box was pushed
    assert np.abs(got - want).max() < 1e-9
    # counterfactual: the primitive (6 mm sphere) leaves the box elsewhere
    prim = {**rec.physics, "objects": {**rec.physics["objects"]}}
    prim["objects"]["pusher"] = {
        k: v for k, v in prim["objects"]["pusher"].items() if k != "geometry"
    }
    other = _rollout(prim, {}, st.drive, st.start)[0]
    assert np.abs(other - want).max() > 3e-3


def _wrist_only(src: Path, dst: Path) -> None:
    """``dst``: ``src`` with each episode's joints replaced by ``ee_poses`` of link ``wrist``
    in closed form (the gantry's column frame is the joint values, the wrist yaws by jyaw)."""
    shutil.copytree(src, dst)
    ds = Dataset.open(dst)
    with ds.edit() as w:
        for ep in ds.episodes:
            js = ep.table("joint_states")
            t = js.column("t_ns").to_numpy()
            pos = np.stack([js.column(f"position.j{a}").to_numpy() for a in "xyz"], -1)
            yaw = js.column("position.jyaw").to_numpy()
            zero = np.zeros_like(yaw)
            quat = np.stack([np.cos(yaw / 2), zero, zero, np.sin(yaw / 2)], -1)
            cols = {"t_ns": pa.array(t, pa.int64()), "link": pa.array(["wrist"] * len(t))}
            cols.update({c: pos[:, i] for i, c in enumerate("xyz")})
            cols.update({c: quat[:, i] for i, c in enumerate(("qw", "qx", "qy", "qz"))})
            rel = f"episodes/{ep.id}/ee_poses.parquet"
            w.write_table(rel, pa.table(cols), kind="ee_poses")
            w.remove(ep.streams["joint_states"]["path"])
            streams = {k: v for k, v in ep.streams.items() if k != "joint_states"}
            streams["ee_poses"] = {**ep.streams["joint_states"], "kind": "ee_poses", "path": rel}
            w.add_episode(
                ep.id, start_ns=ep.start_ns, end_ns=ep.end_ns, streams=streams, segment=ep.segment
            )
        w.commit()


def test_ee_poses_only_gives_the_joint_states_path(tmp_path: Path) -> None:
    from robogs.physics.prepare import prepare
    from robogs.physics.recording import load_recording

    # the pusher link is the wrist; the tool (with the sphere) hangs from it by a fixed joint
    joints = _gantry(
        tmp_path / "joints", "objects.pusher.link=wrist", "objects.pusher.offset_m=[0.02,0,-0.04]"
    )
    _wrist_only(joints, tmp_path / "ee")
    assert not any(e.has("joint_states") for e in Dataset.open(tmp_path / "ee").episodes)
    paths, pushers = [], []
    for root in (joints, tmp_path / "ee"):
        rec = load_recording(root, split="none")
        prep = prepare(rec, dt=DT)
        paths.append(_rollout(rec.physics, rec.shapes().meshes, prep.drive))
        pushers.append(rec.robot_pusher)
    a, b = pushers
    assert list(a.frames) == list(b.frames) == ["wrist", "tool"]
    for n in a.frames:
        assert np.abs(a.frames[n] - b.frames[n]).max() < 1e-12
    # closed form: the tool origin 20 mm along x from the wrist, the pusher point at (20, 0, -40)
    assert np.abs(a.frames["tool"][:3, 3] - [0.0, 0.0, 0.04]).max() < 1e-12
    assert paths[0].shape == paths[1].shape and len(paths[0]) == 2
    assert min(np.linalg.norm(p[-1] - p[0]) for p in paths[0]) > 0.05  # both boxes pushed
    assert np.abs(paths[0] - paths[1]).max() < 1e-9


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_pose_noise_recovers_white_noise_on_a_smooth_path() -> None:
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 4.0, 2000)
    smooth = np.stack([0.1 * np.sin(2 * t), 0.05 * np.cos(3 * t), 0.02 * t], -1)
    sigma = np.array([1e-3, 5e-4, 2e-4])
    est = pose_noise(smooth + rng.normal(0.0, sigma, smooth.shape))
    assert est == pytest.approx(float(np.linalg.norm(sigma)), rel=0.08)
    assert pose_noise(smooth) < 1e-5  # the path alone: its curvature x step^2, 1 % of it
    assert pose_noise(smooth[:2]) == 0.0


def test_a_rigid_robot_with_noisy_ee_orientation_is_accepted() -> None:
    """1 deg of orientation noise on each axis of a yawing end effector (offset 40 mm, 12 mm
    sphere): its roll and pitch scatter moves the sphere's reach by ~6 mm, within the budget
    2 mm + 3 x its noise; noise-free, the same recording is rigid."""
    rng = np.random.default_rng(11)
    n = 2000
    yaw = np.linspace(-0.5, 0.8, n)
    rot = []
    for y in yaw:
        v = rng.normal(0.0, math.radians(1.0), 3)
        a = np.linalg.norm(v)
        k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / a
        rot.append(_rz(y) @ (np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * k @ k))
    offset = [0.0, 0.0, -0.04]
    _, rig = pusher_frames(np.stack(rot), offset, {"tool": np.eye(4)[None]}, reach_m=0.012)
    assert rig.spread_rad > 4e-3  # the former constant (0.23 deg) refused it
    assert rig.moved_m > 2e-3  # geometry.box3d_mm alone would refuse it
    assert rig.moved_m <= rig.budget_m and rig.noise_m > 1e-3
    assert rig.lever_m == pytest.approx(0.052, abs=1e-4)  # 40 mm offset + 12 mm reach
    _, clean = pusher_frames(
        np.stack([_rz(y) for y in yaw]), offset, {"tool": np.eye(4)[None]}, reach_m=0.012
    )
    assert clean.moved_m < 1e-9 and clean.budget_m == pytest.approx(2e-3)


FINGER = (
    '<link name="finger"><collision><origin xyz="0 0 -0.06"/><geometry><box size="0.01 0.01 '
    '0.02"/></geometry></collision></link><joint name="jf" type="prismatic"><parent link="tool"/>'
    '<child link="finger"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" '
    'velocity="1"/></joint>'
)


def _with_urdf(ds_root: Path, edit, finger: np.ndarray | None = None) -> None:
    """Rewrite the dataset's URDF by ``edit(text)``; with ``finger`` [200 Hz samples], add its
    joint ``jf`` to every episode's joint_states."""
    ds = Dataset.open(ds_root)
    urdf = ds.urdf_path
    with ds.edit() as w:
        w.write_text(urdf.relative_to(ds.root).as_posix(), edit(urdf.read_text()))
        for ep in ds.episodes if finger is not None else []:
            js = ep.table("joint_states")
            js = js.append_column("position.jf", pa.array(finger[: js.num_rows]))
            w.write_table(ep.streams["joint_states"]["path"], js, kind="joint_states")
        w.commit()


def test_a_moving_finger_is_modelled_on_every_path(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The finger sweeping 10 mm (5 mm from its mean, over the 2 mm budget) is a servo DOF
    (h78; h71 refused it): ``load_recording`` gives the joint its own body and each
    trajectory the joint's values at its EE stamps (the recorded ones: the EE comes from the
    same joint_states), ``prepare`` puts them on the grid, ``auto`` picks MuJoCo saying so and
    planar refuses naming the joint, ``compare`` runs, and ``render --simulate`` drives the
    finger with the commanded values."""
    from robogs.cli.main import main
    from robogs.cli.render_cmd import simulation_setup
    from robogs.format.kinematics import Chain
    from robogs.format.render_trajectory import episode_trajectory
    from robogs.physics.engine import recording_backend
    from robogs.physics.prepare import prepare
    from robogs.physics.recording import load_recording

    root = _gantry(tmp_path / "ds")
    sweep = np.linspace(0.0, 0.01, 800)  # the finger opens 10 mm over the 4 s episode

    def add_finger(text: str) -> str:
        return text.replace("</robot>", FINGER + "</robot>")

    _with_urdf(root, add_finger, sweep)
    rec = load_recording(root)
    rp = rec.robot_pusher
    assert rp.dofs == ["jf"] and [j.name for j in rp.joints] == ["jf"] and not rp.tilt
    assert rp.bodies == {"tool": "", "finger": "jf"} and rp.moved_m < 1e-9
    assert np.abs(rp.frames["finger"] - np.eye(4)).max() < 1e-12  # its own body's frame
    ds = Dataset.open(root)
    stamps = {e.id: e.table("joint_states").column("t_ns").to_numpy() for e in ds.episodes}
    for tr in rec.trajectories:
        t = stamps[tr.name.split("#")[0]]
        want = np.interp(tr.ee_t_ns, t, sweep[: len(t)])
        assert tr.pusher_dofs.shape == (len(tr.ee_t_ns), 1)
        assert np.abs(tr.pusher_dofs[:, 0] - want).max() < 1e-12
    prep = prepare(rec, dt=DT)
    assert prep.drive.pusher_dofs.shape == (*prep.drive.pusher.shape[:2], 1)
    name, why = recording_backend(rec, "auto")
    assert name == "mujoco" and "servo-driven: jf" in why
    with pytest.raises(InputError, match="moves jf") as err:
        recording_backend(rec, "planar")
    assert "grasp by contact" in str(err.value)
    capsys.readouterr()
    assert main(["compare", str(root), "--engine", "mujoco"]) == 0
    ep = ds.episode("push0")
    traj = episode_trajectory(ep, Chain.from_urdf(ds.urdf(load_meshes=False)), {})
    st = simulation_setup(ds, ep, traj)
    assert st.shapes.meshes["pusher"].dofs == ["jf"]
    grid = np.arange(st.drive.n_steps) * DT
    t_s = (traj.t_ns - traj.t_ns[0]) * 1e-9
    want = np.interp(grid, t_s, traj.q[:, traj.joint_names.index("jf")])
    assert np.abs(st.drive.pusher_dofs[0, :, 0].numpy() - want).max() < 1e-12
    # counterfactual: the finger held still is the one-body path (both links on the pusher)
    _with_urdf(root, lambda text: text)
    ds = Dataset.open(root)
    with ds.edit() as w:
        for ep in ds.episodes:
            js = ep.table("joint_states")
            held = pa.array(np.full(js.num_rows, 0.005))
            js = js.set_column(js.column_names.index("position.jf"), "position.jf", held)
            w.write_table(ep.streams["joint_states"]["path"], js, kind="joint_states")
        w.commit()
    rec = load_recording(root)
    rp = rec.robot_pusher
    assert list(rp.frames) == ["tool", "finger"] and rp.moved_m < 1e-9 and rp.dofs == []
    assert np.abs(rp.frames["finger"][:3, 3] - [0.0, 0.005, 0.04]).max() < 1e-12
    assert all(tr.pusher_dofs is None for tr in rec.trajectories)


def test_pusher_links_without_collision_geometry_are_one_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from robogs.cli.main import main

    root = _gantry(tmp_path / "ds")

    def strip_tool(text: str) -> str:
        a = text.index('<link name="tool">')
        b = text.index("</link>", a)
        return text[:a] + '<link name="tool">' + text[b:]

    _with_urdf(root, strip_tool)
    capsys.readouterr()
    assert main(["compare", str(root), "--engine", "mujoco"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert "link 'tool' has no collision geometry" in lines[0]
    assert "<collision>" in lines[0] and "geometry=primitive" in lines[0]

"""``robogs export mjcf`` with the robot pusher (``objects.pusher.geometry = "robot"``, h80).

The dataset: the gantry of ``tests/physics/init_scene.py`` (seed 7: prismatic x, y, z and a
yaw joint, the ``tool`` link 20 mm along the wrist's x; noise-free joints at 200 Hz; a box
pushed on a table tilted 2 deg, so the box is on a free joint) with the robot pusher, a 6 mm
primitive declared beside it (the counterfactual), and the URDF's tool edited in the test:

* a paddle: the tool's collision is a box 8 x 100 x 40 mm (one rigid body, no servo DOF);
* a two-finger gripper: two finger links below the tool on prismatic joints ``jl`` (+y) and
  ``jr`` (-y), closing 30 -> 10 mm from the tool axis over each episode (``joint_states``);
* the paddle as an STL mesh;
* the paddle pitching 0 -> 10 deg on a hinge (the end effector's tilt as servo DOFs).

Oracles:

* the engine's own rollout of the same scene (``MujocoEngine`` built from ``load_recording``'s
  shapes, what ``compare`` and ``fit`` run): the exported file loaded by plain MuJoCo and driven
  by ``mjcf_replay.drive_pusher`` (the pusher and each DOF servo) gives the same box path
  within 1e-9 m, on compare's drive and on a drive made from the exported file alone;
* the recording: the finger DOFs in ``robot_trajectory.npz`` are the recorded joint values
  (closed form, 1e-12), and the box replayed from the file alone is within the residual the
  engine reports on compare's drive (RMS within 5 % + 0.05 mm);
* the ``start`` keyframe (h86): each servo DOF's joint at its first recorded value (closed
  form: the recorded joint at the first end-effector stamp of the dataset's first episode,
  0.03 m for the fingers, 0 for the pitch and roll; 1e-12), its position servo there and its
  velocity servo at 0, so the scene reset to the key and stepped 50 steps holds the DOFs
  (measured: they do not move, 0.0); replayed from the keyframe (as docs/exports.md's block
  starts) the file gives the engine's box path as from qpos0 (the same gaps);
* counterfactuals: the primitive pusher's rollout (6 mm sphere) leaves the box > 1 mm away,
  the DOFs held at their first value (fingers open, paddle unpitched) > 0.1 mm; the export
  refuses a robot-pusher dataset without the measured pusher.

Measured (first trajectory): replay - engine 3.6e-16 m (paddle), 1.1e-16 (gripper, tilt),
6.8e-14 (mesh paddle); primitive 4.7 / 7.0 / 5.1 mm away; held DOFs 0.58 mm (fingers), 1.0 mm
(pitch).
"""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np
import pyarrow as pa
import pytest
import torch

from robogs.convert.export import export
from robogs.convert.export.mjcf import TRAJECTORY_FILE
from robogs.format import Dataset
from robogs.format.errors import InputError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "physics"))
from mjcf_replay import drive_pusher  # noqa: E402

torch.set_num_threads(1)

PADDLE = '<box size="0.008 0.1 0.04"/>'
FINGERS = "".join(
    f'<link name="finger_{s}"><collision><origin xyz="0 0 -0.04"/><geometry><box size="0.02 '
    f'0.008 0.03"/></geometry></collision></link><joint name="j{s}" type="prismatic"><parent '
    f'link="tool"/><child link="finger_{s}"/><axis xyz="0 {a} 0"/><limit lower="-1" '
    f'upper="1" effort="1" velocity="1"/></joint>'
    for s, a in (("l", 1), ("r", -1))
)


def _gantry(
    root: Path, edit, joints: dict[str, np.ndarray] | None = None, files: dict | None = None
) -> Path:
    """The gantry dataset with the robot pusher, its URDF rewritten by ``edit`` and, with
    ``joints`` (name -> values at the 200 Hz joint stamps), those joints in joint_states;
    ``files``: more files beside the URDF (name -> bytes)."""
    from init_scene import write_scene

    from robogs.physics.init import init_physics, set_physics_values

    write_scene(root, seed=7)
    init_physics(root, objects=["box=material:wood"])
    set_physics_values(root, ["objects.pusher.geometry=robot", "objects.pusher.radius_m=0.006"])
    ds = Dataset.open(root)
    with ds.edit() as w:
        urdf = ds.urdf_path
        w.write_text(urdf.relative_to(ds.root).as_posix(), edit(urdf.read_text()))
        for name, data in (files or {}).items():
            w.write_bytes((urdf.parent / name).relative_to(ds.root).as_posix(), data)
        for ep in ds.episodes if joints else []:
            js = ep.table("joint_states")
            for name, v in joints.items():
                js = js.append_column(f"position.{name}", pa.array(v[: js.num_rows]))
            w.write_table(ep.streams["joint_states"]["path"], js, kind="joint_states")
        w.commit()
    return root


def _paddle(text: str) -> str:
    a = text.index('<link name="tool">')
    b = text.index("</link>", a)
    tool = text[a:b]
    g0 = tool.index("<geometry>") + len("<geometry>")
    g1 = tool.index("</geometry>")
    return text[:a] + tool[:g0] + PADDLE + tool[g1:] + text[b:]


def _closing(n: int = 4000) -> dict[str, np.ndarray]:
    close = np.clip(np.linspace(0.03, 0.0, n), 0.01, 0.03)  # 30 -> 10 mm, then held
    return {"jl": close, "jr": close}


@pytest.fixture(scope="module")
def paddle(tmp_path_factory: pytest.TempPathFactory):
    return _case(tmp_path_factory.mktemp("h80_paddle"), _paddle, None)


@pytest.fixture(scope="module")
def gripper(tmp_path_factory: pytest.TempPathFactory):
    return _case(
        tmp_path_factory.mktemp("h80_gripper"),
        lambda t: t.replace("</robot>", FINGERS + "</robot>"),
        _closing(),
    )


@pytest.fixture(scope="module")
def mesh_paddle(tmp_path_factory: pytest.TempPathFactory):
    """The paddle as an STL mesh (a box of the paddle's size, 12 triangles)."""
    import trimesh

    stl = trimesh.creation.box(extents=(0.008, 0.1, 0.04)).export(file_type="stl")
    edit = lambda t: _paddle(t).replace(PADDLE, '<mesh filename="paddle.stl"/>')  # noqa: E731
    return _case(tmp_path_factory.mktemp("h80_mesh"), edit, None, {"paddle.stl": stl})


def _pitching(text: str) -> str:
    """The paddle on a pitch hinge: the tool's fixed joint made revolute about y."""
    hinge = (
        '<joint name="tool_fixed" type="revolute"><axis xyz="0 1 0"/><limit lower="-1" '
        'upper="1" effort="1" velocity="1"/>'
    )
    return _paddle(text.replace('<joint name="tool_fixed" type="fixed">', hinge))


PITCH = np.radians(np.clip(np.linspace(0.0, 20.0, 4000), 0.0, 10.0))  # 0 -> 10 deg, held


@pytest.fixture(scope="module")
def tilting(tmp_path_factory: pytest.TempPathFactory):
    return _case(tmp_path_factory.mktemp("h80_tilt"), _pitching, {"tool_fixed": PITCH})


def _case(tmp: Path, edit, joints, files=None):
    from robogs.physics.export_pusher import robot_pusher_paths

    root = _gantry(tmp / "ds", edit, joints, files)
    ds = Dataset.open(root)
    paths = robot_pusher_paths(ds)
    out = tmp / "scene_mjcf"
    report = export("mjcf", ds, out, robot_pusher=paths)
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    return root, out, report, model, paths


def _engine(root: Path, meshes: bool = True):
    from robogs.convert.export.urdf_scene import scene_state
    from robogs.physics.engines.mujoco_engine import MujocoEngine
    from robogs.physics.prepare import prepare
    from robogs.physics.recording import load_recording

    ds = Dataset.open(root)
    rec = load_recording(ds)  # what compare reads
    poses = {n: p.pose for n, p in scene_state(ds, ["box"]).objects.items()}
    physics = rec.physics
    if not meshes:  # the counterfactual: the primitive pusher of objects.pusher
        pusher = {k: v for k, v in physics["objects"]["pusher"].items() if k != "geometry"}
        physics = {**physics, "objects": {**physics["objects"], "pusher": pusher}}
    eng = MujocoEngine(
        physics, object_name="box", meshes=rec.shapes().meshes if meshes else {}, poses=poses
    )
    return eng, rec, prepare(rec, dt=eng.dt)


def _one(drive, t: int):
    """Trajectory ``t`` of ``drive`` as a drive of its own."""
    from robogs.physics.engines.base import make_drive

    dofs = None if drive.pusher_dofs is None else drive.pusher_dofs[t : t + 1].numpy()
    return make_drive(
        drive.dt,
        drive.pusher[t : t + 1].numpy(),
        drive.ee_yaw[t : t + 1].numpy(),
        np.arange(drive.n_steps)[None] * drive.dt,  # every step: the whole path
        drive.init_pos[t : t + 1].numpy(),
        drive.init_yaw[t : t + 1].numpy(),
        drive.sample_dt[t : t + 1].numpy(),
        dofs,
    )


def _replay(model, drive, servos, key: bool = False) -> np.ndarray:
    """The exported file driven by ``drive`` (one trajectory): box positions [S, 3] m; with
    ``key`` from the ``start`` keyframe (as docs/exports.md's block), else from qpos0."""
    from robogs.physics.engines.mujoco_engine import sample_steps

    data = mujoco.MjData(model)
    if key:
        mujoco.mj_resetDataKeyframe(model, data, model.key("start").id)
    box = model.joint("box")
    qb = int(box.qposadr[0])
    y0 = float(drive.init_yaw[0])
    data.qpos[qb : qb + 3] = drive.init_pos[0].numpy()
    data.qpos[qb + 3 : qb + 7] = (np.cos(y0 / 2), 0, 0, np.sin(y0 / 2))
    p, yaw, dt = drive.pusher[0].numpy(), drive.ee_yaw[0].numpy(), drive.dt
    qp, vp = model.joint("pusher_x").qposadr[0], model.joint("pusher_x").dofadr[0]
    data.qpos[qp : qp + 3], data.qpos[qp + 3] = p[0], yaw[0]
    data.qvel[vp : vp + 3], data.qvel[vp + 3] = (p[1] - p[0]) / dt, (yaw[1] - yaw[0]) / dt
    dofs = None if drive.pusher_dofs is None else drive.pusher_dofs[0].numpy()
    steps = float(sample_steps(drive)[0])
    return drive_pusher(model, data, qb, p, yaw, dt, steps, dofs, servos)


def _file_drive(out: Path, k: int, drive_c, t: int):
    """Episode ``k``'s drive made from ``robot_trajectory.npz`` alone (the docs' rule: the
    pusher point, yaw and DOFs linearly on the step grid from the trajectory start, the
    sample interval the median stamp spacing), with the start pose of compare's trajectory
    ``t``, observed at every step."""
    from robogs.physics.engines.base import make_drive

    f = np.load(out / TRAJECTORY_FILE)
    te = (f[f"pusher_t_ns_{k}"] - f[f"pusher_t_ns_{k}"][0]) * 1e-9
    dt = drive_c.dt
    grid = np.arange(int(np.ceil(te[-1] / dt)) + 1) * dt
    p = np.stack([np.interp(grid, te, f[f"pusher_p_{k}"][:, a]) for a in range(3)], -1)
    yaw = np.interp(grid, te, f[f"pusher_yaw_{k}"])
    q = f[f"pusher_q_{k}"]
    dofs = np.stack([np.interp(grid, te, q[:, j]) for j in range(q.shape[1])] or [grid], -1)
    return make_drive(
        dt,
        p[None],
        yaw[None],
        grid[None],
        drive_c.init_pos[t : t + 1].numpy(),
        drive_c.init_yaw[t : t + 1].numpy(),
        float(np.median(np.diff(te))),
        dofs[None] if q.shape[1] else None,
    )


def _box(eng, drive) -> np.ndarray:
    return eng.rollout(drive).pos["box"][0, 0]


def _check_start_key(case, ds: Dataset, recorded: dict[str, np.ndarray]) -> None:
    """The ``start`` keyframe holds each servo DOF at its first recorded value (closed form:
    the recorded joint at the first end-effector stamp of the scene's episode, the dataset's
    first), its position servo there and its velocity servo at 0."""
    root, out, report, model, paths = case
    f = np.load(out / TRAJECTORY_FILE)
    ep = ds.episodes[0].id
    k = list(f["pusher_episodes"]).index(ep)
    t = ds.episode(ep).table("joint_states").column("t_ns").to_numpy()
    key = model.key("start")
    for (joint, pos, vel), name in zip(f["pusher_servos"], f["pusher_dof_names"], strict=True):
        want = float(np.interp(f[f"pusher_t_ns_{k}"][0], t, recorded[str(name)][: len(t)]))
        got = key.qpos[model.joint(str(joint)).qposadr[0]]
        assert abs(got - want) < 1e-12
        assert key.ctrl[model.actuator(str(pos)).id] == got
        assert key.ctrl[model.actuator(str(vel)).id] == 0.0
    assert paths.pusher.start == list(f[f"pusher_q_{k}"][0])
    # a scene reset to the keyframe and stepped with the keyframe's controls holds the DOFs
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, key.id)
    adr = [model.joint(str(s[0])).qposadr[0] for s in f["pusher_servos"]]
    q0 = data.qpos[adr].copy()
    for _ in range(50):
        mujoco.mj_step(model, data)
    held = float(np.abs(data.qpos[adr] - q0).max())
    print("DOFs held from the keyframe within", held)
    assert held < 1e-9


def _check_case(case, n_dofs: int) -> dict[str, float]:
    root, out, report, model, paths = case
    eng, rec, prep = _engine(root)
    f = np.load(out / TRAJECTORY_FILE)
    servos = [tuple(s) for s in f["pusher_servos"]]
    assert len(servos) == n_dofs == len(paths.pusher.dofs)
    assert [s[0] for s in servos] == [s[0] for s in paths.pusher.servos]
    # the document's scene part is the engine's: same joints, actuators and pairs first
    for kind, n in (
        (mujoco.mjtObj.mjOBJ_JOINT, eng.model.njnt),
        (mujoco.mjtObj.mjOBJ_ACTUATOR, eng.model.nu),
    ):
        assert [mujoco.mj_id2name(model, kind, i) for i in range(n)] == [
            mujoco.mj_id2name(eng.model, kind, i) for i in range(n)
        ]
    np.testing.assert_array_equal(model.pair_geom1, eng.model.pair_geom1)
    np.testing.assert_array_equal(model.pair_geom2, eng.model.pair_geom2)
    np.testing.assert_array_equal(model.pair_friction, eng.model.pair_friction)
    # on compare's drive: the engine's rollout and the file's replay
    t = 0
    d1 = _one(prep.drive, t)
    want = _box(eng, d1)
    got = _replay(model, d1, servos)
    gap = float(np.abs(got - want).max())
    gap_key = float(np.abs(_replay(model, d1, servos, key=True) - want).max())
    moved = float(np.linalg.norm(want[-1] - want[0]))
    # from the file alone (the episode of trajectory t)
    ep = rec.trajectories[t].name.split("#")[0]
    k = list(f["pusher_episodes"]).index(ep)
    t_off = int(prep.t0_ns[t]) - int(f[f"pusher_t_ns_{k}"][0])
    assert t_off == 0  # the first trajectory starts with its episode's EE samples
    dfile = _file_drive(out, k, prep.drive, t)
    want_f = _box(eng, dfile)
    got_f = _replay(model, dfile, servos)
    gap_f = float(np.abs(got_f - want_f).max())
    # against the recording, at its stamps
    tr = rec.trajectories[t]
    ts = (tr.t_ns - prep.t0_ns[t]) * 1e-9
    grid = np.arange(len(want)) * prep.drive.dt
    grid_f = np.arange(len(want_f)) * prep.drive.dt

    def rms(path, g):
        at = np.stack([np.interp(ts, g, path[:, a]) for a in range(3)], -1)
        return float(np.sqrt(np.mean(np.sum((at - tr.object_pos) ** 2, -1))))

    # counterfactual: the primitive pusher of objects.pusher (6 mm sphere)
    eng_p, _, _ = _engine(root, meshes=False)
    prim = _box(eng_p, _one(prep.drive, t) if n_dofs == 0 else _strip(d1))
    held = None
    if n_dofs:  # counterfactual: the DOFs held at their first value (fingers open)
        from dataclasses import replace

        first = d1.pusher_dofs[:, :1].expand_as(d1.pusher_dofs).clone()
        held = float(np.abs(_box(eng, replace(d1, pusher_dofs=first)) - want).max())
    return {
        "held_open": held,
        "gap": gap,
        "gap_key": gap_key,
        "gap_file": gap_f,
        "moved": moved,
        "rms_engine": rms(want, grid),
        "rms_file": rms(got_f, grid_f),
        "primitive": float(np.abs(prim - want).max()),
    }


def _strip(drive):
    from dataclasses import replace

    return replace(drive, pusher_dofs=None)


def test_paddle_export_is_the_engines_scene_and_replays_its_rollout(paddle) -> None:
    root, out, report, model, paths = paddle
    names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(model.ngeom)]
    assert "pusher/tool/0" in names and "pusher" not in names
    assert report.facts["robot_pusher"]["geoms"] == ["pusher/tool/0"]
    assert report.facts["robot_pusher"]["dofs"] == []
    g = model.geom("pusher/tool/0")
    np.testing.assert_allclose(g.size, [0.004, 0.05, 0.02], atol=1e-15)  # the paddle, halved
    r = _check_case(paddle, 0)
    print(r)
    assert r["moved"] > 0.02
    assert r["gap"] < 1e-9 and r["gap_file"] < 1e-9
    assert r["rms_file"] < 1.05 * r["rms_engine"] + 5e-5
    assert r["primitive"] > 1e-3


def test_gripper_export_drives_the_fingers(gripper) -> None:
    root, out, report, model, paths = gripper
    facts = report.facts["robot_pusher"]
    assert facts["dofs"] == ["jl", "jr"]
    assert facts["bodies"] == {"tool": "", "finger_l": "jl", "finger_r": "jr"}
    for j in ("jl", "jr"):
        assert model.joint(f"pusher/{j}").type[0] == mujoco.mjtJoint.mjJNT_SLIDE
        assert model.actuator(f"pusher/{j}").id < model.actuator(f"pusher/v/{j}").id
    f = np.load(out / TRAJECTORY_FILE)
    ds = Dataset.open(root)
    close = _closing()["jl"]
    for k, ep in enumerate(f["pusher_episodes"]):
        js = ds.episode(str(ep)).table("joint_states")
        t = js.column("t_ns").to_numpy()
        want = np.interp(f[f"pusher_t_ns_{k}"], t, close[: len(t)])
        q = f[f"pusher_q_{k}"]
        assert q.shape == (len(want), 2)
        assert np.abs(q - want[:, None]).max() < 1e-12
    key = model.key("start").qpos  # the robot at its first joint_states row
    for j, v in report.facts["robot"]["start_q"].items():
        assert key[model.joint(j).qposadr[0]] == v
    _check_start_key(gripper, ds, {"jl": close, "jr": close})
    r = _check_case(gripper, 2)
    print(r)
    assert r["gap"] < 1e-9 and r["gap_file"] < 1e-9 and r["gap_key"] < 1e-9
    assert r["held_open"] > 1e-4  # the closing fingers move the box (0.58 mm measured)
    assert r["rms_file"] < 1.05 * r["rms_engine"] + 5e-5


def test_a_robot_pusher_dataset_without_the_measured_pusher_is_refused(paddle, tmp_path) -> None:
    root = paddle[0]
    with pytest.raises(InputError, match="robot_pusher_paths"):
        export("mjcf", Dataset.open(root), tmp_path / "x")


def test_the_docs_robot_pusher_replay_block_runs(gripper, tmp_path, monkeypatch) -> None:
    """docs/exports.md's robot-pusher replay, run as written next to the gripper's export: the
    fingers follow their servo targets."""
    import re
    import shutil

    out = gripper[1]
    doc = (Path(__file__).resolve().parents[2] / "docs" / "exports.md").read_text()
    section = doc[doc.index("## MJCF with the robot pusher") :]
    section = section[: section.index("\n## ", 1)]
    (block,) = re.findall(r"```python\n(.*?)```", section, re.S)
    shutil.copytree(out, tmp_path / "scene_mjcf")
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "__docs__"}
    exec(compile(block, "docs/exports.md (MJCF robot pusher replay)", "exec"), ns)
    print("docs block: worst DOF tracking", ns["worst"])
    assert len(ns["grid"]) > 500 and ns["servos"][0][0] == "pusher/jl"
    assert ns["worst"] < 1e-4


def test_a_mesh_paddle_goes_under_meshes_robot_once(mesh_paddle) -> None:
    """The pusher's mesh is written where the robot's meshes go (``meshes/robot/``), one file
    for the pusher geom and the kinematic robot's link (the same conversion of the same URDF
    mesh), under two mesh names (``robot/<mesh>`` for the pusher); the file replays the
    engine's rollout as the primitive paddle does."""
    root, out, report, model, paths = mesh_paddle
    facts = report.facts["robot_pusher"]
    (rel,) = facts["meshes"]
    assert rel.startswith("meshes/robot/") and (out / rel).is_file()
    assert report.files.count(rel) == 1
    assert any(m["file"] == rel for m in report.facts["robot"]["meshes"])
    g = model.geom("pusher/tool/0")
    assert g.type[0] == mujoco.mjtGeom.mjGEOM_MESH
    mesh = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_MESH, int(g.dataid[0]))
    assert mesh.startswith("robot/")
    r = _check_case(mesh_paddle, 0)
    print(r)
    assert r["gap"] < 1e-9 and r["gap_file"] < 1e-9 and r["primitive"] > 1e-3


def test_a_pitching_paddle_exports_the_tilt_hinges(tilting) -> None:
    """The pusher link itself pitches (0 -> 10 deg on a hinge about y under the yaw): the
    engine models the end effector's tilt (hinges ``pusher_pitch``, ``pusher_roll``); the file's
    DOFs are the recorded pitch and zero roll (closed form: ``R = Rz(yaw) Ry(pitch)``), and
    the file replays the engine's rollout."""
    root, out, report, model, paths = tilting
    assert report.facts["robot_pusher"]["dofs"] == ["pitch", "roll"]
    assert report.facts["robot_pusher"]["tilt"] is True
    names = [model.joint(i).name for i in range(model.njnt)]
    assert names[names.index("pusher_yaw") + 1 : names.index("pusher_yaw") + 3] == [
        "pusher_pitch",
        "pusher_roll",
    ]
    f = np.load(out / TRAJECTORY_FILE)
    ds = Dataset.open(root)
    for k, ep in enumerate(f["pusher_episodes"]):
        t = ds.episode(str(ep)).table("joint_states").column("t_ns").to_numpy()
        want = np.interp(f[f"pusher_t_ns_{k}"], t, PITCH[: len(t)])
        q = f[f"pusher_q_{k}"]
        assert np.abs(q[:, 0] - want).max() < 1e-12 and np.abs(q[:, 1]).max() < 1e-12
    _check_start_key(tilting, ds, {"pitch": PITCH, "roll": np.zeros_like(PITCH)})
    r = _check_case(tilting, 2)
    print(r)
    assert r["gap"] < 1e-9 and r["gap_file"] < 1e-9 and r["gap_key"] < 1e-9
    assert r["held_open"] > 1e-4  # the pitch moves the box (1.0 mm measured)


def test_a_robot_that_needs_a_prefix_beside_the_robot_pusher_takes_arm(tmp_path) -> None:
    """A URDF link named as a scene joint (``pusher_x``) makes the kinematic robot need a
    prefix; beside the robot pusher, whose meshes are ``robot/<mesh>``, it is ``arm/``: the
    document compiles, with the pusher's mesh and the robot's under two names and one file."""
    import trimesh

    from robogs.physics.export_pusher import robot_pusher_paths

    stl = trimesh.creation.box(extents=(0.008, 0.1, 0.04)).export(file_type="stl")

    def edit(text: str) -> str:
        text = _paddle(text).replace(PADDLE, '<mesh filename="paddle.stl"/>')
        return text.replace('"carriage_x"', '"pusher_x"')

    root = _gantry(tmp_path / "ds", edit, None, {"paddle.stl": stl})
    ds = Dataset.open(root)
    out = tmp_path / "scene_mjcf"
    report = export("mjcf", ds, out, robot_pusher=robot_pusher_paths(ds))
    assert report.facts["robot"]["prefix"] == "arm/"
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    meshes = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_MESH, i) for i in range(model.nmesh)}
    assert {m.split("/")[0] for m in meshes} == {"robot", "arm"}
    assert model.joint("arm/jx").id > model.joint("pusher_yaw").id
    assert model.body("arm/pusher_x").id > model.body("pusher").id


def test_the_cli_export_measures_the_robot_pusher_itself(gripper, tmp_path) -> None:
    """``robogs export mjcf`` on a robot-pusher dataset writes the scene the API writes with
    :func:`robot_pusher_paths` (same scene.xml bytes and pusher trajectory), not a refusal."""
    from robogs.cli.main import main

    root, out_api = gripper[0], gripper[1]
    out = tmp_path / "cli_mjcf"
    assert main(["export", "mjcf", str(root), str(out)]) == 0
    assert (out / "scene.xml").read_bytes() == (out_api / "scene.xml").read_bytes()
    a, b = np.load(out / "robot_trajectory.npz"), np.load(out_api / "robot_trajectory.npz")
    assert sorted(a.files) == sorted(b.files) and any(k.startswith("pusher_q") for k in a.files)
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k])


def test_a_start_that_is_not_one_value_per_dof_is_refused(gripper, tmp_path) -> None:
    """``RobotPusher.start`` (the keyframe's DOF values) must be one finite value per DOF."""
    from dataclasses import replace

    root, _, _, _, paths = gripper
    for bad in ([0.03], [0.03, float("nan")]):
        given = replace(paths, pusher=replace(paths.pusher, start=bad))
        with pytest.raises(InputError, match=r"one finite value per servo DOF \(jl, jr\)"):
            export("mjcf", Dataset.open(root), tmp_path / f"x{len(bad)}", robot_pusher=given)

"""Moving fingers of the robot pusher (``objects.pusher.geometry = "robot"``, issue 16, h78).

Each joint below the pusher link that the recording moves gets its own servo-driven body in
MuJoCo (``mujoco_robot.pusher_model`` / ``robot_pusher_scene``). The fixtures are generated in
closed form here: the URDFs are written by hand and each link's pose is the analytic forward
kinematics of the joint values (a translation along the prismatic axis), not the engine's.

Oracles:

* (a) a two-finger parallel gripper (prismatic fingers, the second a ``<mimic>`` of the first)
  closing on a box placed off-centre between them, on a nearly frictionless table (mu 0.05):
  the box ends centred between the fingers (closed form: the midpoint of the finger faces,
  here y = 0, whatever its start) within 0.01 mm, and the fingers' final gap in MuJoCo is the
  box's width within the contacts' own penetration (+ 1 um of servo tracking). Why 0.01 mm:
  the box is held by two soft contacts each compressed by well under 2 um (measured 0.24 um
  at mu 0.05, 1.5 um at mu 0.4): the centre can only be off by the difference of the two
  compressions. Counterfactual: the fingers held open (the one-body path) leave the box where
  it was;
* (b) one finger, on a prismatic joint along the hand's x, sweeps a box sideways by a known
  amount while the end effector stays still: a cosine profile of 100 mm whose deceleration
  (0.49 m/s^2) stays below mu g (3.9 m/s^2), so the box stays on the finger face and ends at
  ``D + finger half + box half`` (closed form) within 0.01 mm (the soft contact's compression
  under the friction load mu m g = 1.6 N and its relaxation once the finger stops: 1.8 um
  measured); centred on the finger, its y and yaw do not move (1e-9), and the hand (whose palm
  has collision geometry too) stays where the drive holds it, within 1 um. (Pushed 10 mm
  off-centre by the 20 mm wide finger the box turns 0.29 deg and drifts 0.18 mm sideways:
  not a closed form, so not asserted);
* nested joints: a hinge (``wrist``, URDF origin with a 0.3 rad roll) below the pusher link
  and a prismatic ``tip`` below it, with a ``pad`` fixed to the tip, under a moving, yawing
  end effector: each link's geom in MuJoCo is at its closed-form forward-kinematics pose
  (``[Rz(yaw) | p] T(o) Rx(0.3) Rz(q1) T(0.05, 0, 0) T(q2 x) ...``) at every step within
  1e-9 (float error of the dead-beat servos: 1.5e-10 measured), the joints' values read back
  from the links' poses (``dof_values``) are q1 and q2 within 1e-12, and the pad rides on the
  tip's body;
* the finger's servo targets go through the pusher's knot smoothing: on a 500 Hz path
  (``sample_dt`` 2 ms, 1 ms steps) the finger's position targets are ``smooth_knots(q, 2)``
  of the drive (the pusher's spacing) and its velocity targets have no staircase.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from robogs.format.kinematics import Chain
from robogs.format.urdf import load_urdf
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine, smooth_knots
from robogs.physics.engines.mujoco_robot import (
    RobotPusher,
    distal_joints,
    dof_values,
    pusher_model,
)

torch.set_num_threads(1)

DT = 1e-3
HALF = 0.025  # the box's half size [m]
FINGER = (0.01, 0.004, 0.015)  # a finger's half sizes [m]: its face is FINGER[1] from its origin
INERT = (
    '<inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" '
    'izz="1e-4"/></inertial>'
)


def _box(half: tuple[float, float, float], xyz: str = "0 0 0") -> str:
    size = " ".join(str(2 * h) for h in half)
    return f'<collision><origin xyz="{xyz}"/><geometry><box size="{size}"/></geometry></collision>'


def _write(tmp: Path, body: str) -> Path:
    path = tmp / "robot" / "hand.urdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        '<?xml version="1.0"?><robot name="hand"><link name="base"/>'
        '<joint name="mount" type="fixed"><parent link="base"/><child link="hand"/></joint>'
        + body
        + "</robot>"
    )
    return path


def _gripper(tmp: Path) -> Path:
    """The hand and two fingers: ``left`` at ``+q`` along y, ``right`` (mimic) at ``-q``."""
    prism = '<limit lower="0" upper="0.1" effort="1" velocity="1"/>'
    return _write(
        tmp,
        f'<link name="hand">{INERT}</link>'
        f'<link name="left">{INERT}{_box(FINGER)}</link>'
        f'<link name="right">{INERT}{_box(FINGER)}</link>'
        '<joint name="jl" type="prismatic"><parent link="hand"/><child link="left"/>'
        f'<axis xyz="0 1 0"/>{prism}</joint>'
        '<joint name="jr" type="prismatic"><parent link="hand"/><child link="right"/>'
        f'<axis xyz="0 -1 0"/>{prism}<mimic joint="jl"/></joint>',
    )


def _sweeper(tmp: Path) -> Path:
    """The hand with a palm (a box 60 mm behind its origin) and one finger along its x."""
    prism = '<limit lower="-0.2" upper="0.2" effort="1" velocity="1"/>'
    finger = (FINGER[1], FINGER[0], FINGER[2])  # thin along x: its face is FINGER[1] ahead
    return _write(
        tmp,
        f'<link name="hand">{INERT}{_box((0.01, 0.01, 0.01), "-0.06 0 0.03")}</link>'
        f'<link name="finger">{INERT}{_box(finger)}</link>'
        '<joint name="jf" type="prismatic"><parent link="hand"/><child link="finger"/>'
        f'<axis xyz="1 0 0"/>{prism}</joint>',
    )


def _shift(v: np.ndarray, axis: int) -> np.ndarray:
    """[N, 4, 4] translations by ``v`` [N] along ``axis`` (closed-form prismatic FK)."""
    out = np.repeat(np.eye(4)[None], len(v), 0)
    out[:, axis, 3] = v
    return out


def _physics(mu_table: float) -> dict:
    return {
        "revision": 1,
        "objects": {
            "box": {
                "equation": "rigid",
                "size_m": [2 * HALF] * 3,
                "mass_kg": 0.4,
                "friction_dynamic": mu_table,
            },
            "table": {"equation": "static", "plane_z_m": 0.0},
            "pusher": {
                "equation": "kinematic",
                "radius_m": 0.01,
                "friction_dynamic": 0.0,
                "geometry": "robot",
                "link": "hand",
            },
        },
    }


def _robot(urdf: Path, links: dict[str, np.ndarray]) -> RobotPusher:
    """The robot pusher of a still end effector (yaw 0) whose links move as ``links``."""
    chain = Chain.from_urdf(load_urdf(urdf, load_meshes=False))
    n = len(next(iter(links.values())))
    frames, bodies, tilt, joints, rig = pusher_model(
        np.repeat(np.eye(3)[None], n, 0), None, links, distal_joints(chain, "hand")
    )
    assert not tilt and rig.moved_m < 1e-12  # every link rigid in its own body
    return RobotPusher(
        urdf, "hand", frames, root=urdf.parents[1], tilt=tilt, joints=joints, bodies=bodies
    )


def _drive(n: int, q: np.ndarray, box_xy: tuple[float, float], sample_dt=None):
    """The hand still at (0, 0, HALF), the fingers' values ``q`` [n, J], the box at rest."""
    t = np.arange(n) * DT
    return make_drive(
        DT,
        np.tile([0.0, 0.0, HALF], (1, n, 1)),
        np.zeros((1, n)),
        t[None],
        np.array([[box_xy[0], box_xy[1], HALF]]),
        np.zeros(1),
        sample_dt=sample_dt,
        pusher_dofs=q[None],
    )


def _last(eng: MujocoEngine, drive) -> mujoco.MjData:
    *_, (_, _, data) = eng.step_states(drive)
    return data


def _geom(eng: MujocoEngine, name: str) -> int:
    return mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_GEOM, name)


@pytest.mark.parametrize("y0, mu", [(0.008, 0.05), (-0.005, 0.05), (0.008, 0.4)])
def test_a_parallel_gripper_centres_an_off_centre_box(tmp_path: Path, y0: float, mu: float):
    urdf = _gripper(tmp_path)
    n = 1500
    t = np.arange(n) * DT
    q = np.clip(0.06 - (0.06 - (HALF + FINGER[1])) * t, HALF + FINGER[1], None)  # closes, holds
    links = {"hand": _shift(np.zeros(n), 1), "left": _shift(q, 1), "right": _shift(-q, 1)}
    rp = _robot(urdf, links)
    assert rp.dofs == ["jl", "jr"] and rp.bodies == {"hand": "", "left": "jl", "right": "jr"}
    eng = MujocoEngine(_physics(mu), dt=DT, meshes={"pusher": rp})
    assert eng.pusher_dofs == ["jl", "jr"]
    drive = _drive(n, np.stack([q, q], -1), (0.0, y0))
    out = eng.rollout(drive)
    pos, quat = out.pos["box"][0, 0], out.quat["box"][0, 0]
    assert abs(pos[0, 1] - y0) < 1e-9 and abs(pos[-1, 1]) < 1e-5  # centred: the midpoint y = 0
    assert abs(2 * math.atan2(quat[-1, 3], quat[-1, 0])) < 1e-6
    d = _last(eng, drive)
    left, right = (
        d.geom_xpos[_geom(eng, "pusher/left/0")],
        d.geom_xpos[_geom(eng, "pusher/right/0")],
    )
    gap = (left[1] - FINGER[1]) - (right[1] + FINGER[1])
    box_geom = _geom(eng, "box")
    pen = [
        -d.contact[i].dist
        for i in range(d.ncon)
        if box_geom in (d.contact[i].geom1, d.contact[i].geom2)
        and {_geom(eng, "pusher/left/0"), _geom(eng, "pusher/right/0")}
        & {d.contact[i].geom1, d.contact[i].geom2}
    ]
    assert len(pen) >= 2 and max(pen) < 2e-6  # both fingers touch it
    assert abs(gap - 2 * HALF) <= max(pen) + 1e-6
    # counterfactual: the fingers held open are the one-body path, and the box stays put
    held = np.full(n, 0.06)
    still = _robot(
        urdf, {"hand": links["hand"], "left": _shift(held, 1), "right": _shift(-held, 1)}
    )
    assert still.dofs == [] and set(still.bodies.values()) == {""}
    eng0 = MujocoEngine(_physics(mu), dt=DT, meshes={"pusher": still})
    p0 = eng0.rollout(_drive(n, np.stack([held, held], -1), (0.0, y0))).pos["box"][0, 0]
    assert abs(p0[-1, 1] - y0) < 1e-6


def test_b_a_finger_sweeps_a_box_by_a_known_amount(tmp_path: Path) -> None:
    urdf = _sweeper(tmp_path)
    n, span, sweep = 1600, 1.0, 0.1
    t = np.arange(n) * DT
    q = 0.5 * sweep * (1 - np.cos(np.pi * np.clip(t / span, 0.0, 1.0)))  # 0 -> 100 mm, at rest
    assert 0.5 * sweep * (np.pi / span) ** 2 < 0.4 * 9.81  # the box cannot outrun the finger
    rp = _robot(urdf, {"hand": _shift(np.zeros(n), 0), "finger": _shift(q, 0)})
    assert rp.dofs == ["jf"]
    eng = MujocoEngine(_physics(0.4), dt=DT, meshes={"pusher": rp})
    x0 = 0.04  # the box's back face 15 mm ahead of the finger face (at x = 4 mm)
    drive = _drive(n, q[:, None], (x0, 0.0))
    out = eng.rollout(drive)
    pos, quat = out.pos["box"][0, 0], out.quat["box"][0, 0]
    want = sweep + FINGER[1] + HALF  # closed form: the box on the finger face where it stops
    assert want - x0 == pytest.approx(0.089)  # the amount it is swept
    assert abs(pos[-1, 0] - want) < 1e-5
    assert abs(pos[-1, 1]) < 1e-9 and abs(2 * math.atan2(quat[-1, 3], quat[-1, 0])) < 1e-9
    d = _last(eng, drive)
    palm = d.geom_xpos[_geom(eng, "pusher/hand/0")]
    assert np.abs(palm - [-0.06, 0.0, HALF + 0.03]).max() < 1e-6  # the end effector held still
    finger = d.geom_xpos[_geom(eng, "pusher/finger/0")]
    assert abs(finger[0] - sweep) < 1e-6 and abs(finger[1]) < 1e-9


def test_finger_targets_share_the_pushers_knot_smoothing(tmp_path: Path) -> None:
    """A finger path linearly interpolated from 500 Hz samples onto 1 ms steps (a velocity
    staircase): the engine's position targets are ``smooth_knots(q, 2)``, the spacing
    ``sample_dt / dt`` of the pusher's, and its velocity targets change every step by the
    same amount where the raw path's alternate between 2x and 0 (a constant acceleration)."""
    urdf = _sweeper(tmp_path)
    n = 400
    t = np.arange(n) * DT
    ts = t[::2]  # the 500 Hz samples
    q = np.interp(t, ts, 0.5 * 2.0 * ts**2)  # 2 m/s^2 from rest, piecewise linear on the grid
    rp = _robot(urdf, {"hand": _shift(np.zeros(n), 0), "finger": _shift(q, 0)})
    eng = MujocoEngine(_physics(0.4), dt=DT, meshes={"pusher": rp})
    drive = _drive(n, q[:, None], (0.5, 0.0), sample_dt=0.002)
    ctrl = eng._controls(drive)[0]
    a = mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_ACTUATOR, "pusher/jf")
    b = mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_ACTUATOR, "pusher/v/jf")
    want = smooth_knots(q[None], 2)[0]
    np.testing.assert_array_equal(ctrl[:, a], want[:-1])
    acc = np.diff(ctrl[10:-10, b]) / DT
    assert np.abs(acc - 2.0).max() < 1e-6  # smoothed: 2 m/s^2 every step
    raw = np.diff(np.diff(q[10:-10]) / DT) / DT
    assert raw.max() > 3.9 and raw.min() < 0.1  # the staircase it replaces


def _rot(axis: int, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    i, j = [k for k in range(3) if k != axis]
    out = np.eye(4)
    out[i, i], out[i, j], out[j, i], out[j, j] = c, -s, s, c
    return out


def _move(xyz) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = xyz
    return out


def test_nested_joint_bodies_follow_the_forward_kinematics(tmp_path: Path) -> None:
    wrist_origin = _move([0.02, 0.0, -0.03]) @ _rot(0, 0.3)  # xyz + rpy (0.3, 0, 0)
    urdf = _write(
        tmp_path,
        f'<link name="hand">{INERT}</link><link name="wrist">{INERT}</link>'
        f'<link name="tip">{INERT}{_box(FINGER)}</link>'
        f'<link name="pad">{INERT}{_box((0.006, 0.006, 0.003), "0.01 0 0")}</link>'
        '<joint name="jw" type="revolute"><parent link="hand"/><child link="wrist"/>'
        '<origin xyz="0.02 0 -0.03" rpy="0.3 0 0"/><axis xyz="0 0 1"/>'
        '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        '<joint name="jt" type="prismatic"><parent link="wrist"/><child link="tip"/>'
        '<origin xyz="0.05 0 0"/><axis xyz="1 0 0"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        '<joint name="jp" type="fixed"><parent link="tip"/><child link="pad"/>'
        '<origin xyz="0 0 -0.01"/></joint>',
    )
    n = 700
    t = np.arange(n) * DT
    q1, q2 = 1.2 * np.sin(3.0 * t), 0.02 * (1 - np.cos(4.0 * t))
    wrist = np.stack([wrist_origin @ _rot(2, a) for a in q1])
    tip = wrist @ _move([0.05, 0.0, 0.0]) @ _shift(q2, 0)
    pad = tip @ _move([0.0, 0.0, -0.01])
    links = {"hand": np.repeat(np.eye(4)[None], n, 0), "wrist": wrist, "tip": tip, "pad": pad}
    rp = _robot(urdf, links)
    assert rp.dofs == ["jw", "jt"]
    assert rp.bodies == {"hand": "", "wrist": "jw", "tip": "jt", "pad": "jt"}
    rot = np.repeat(np.eye(3)[None], n, 0)
    got = dof_values(rp, rot, links)
    assert np.abs(got - np.stack([q1, q2], -1)).max() < 1e-12
    yaw = 0.4 + 0.5 * t
    hand = np.stack([0.3 + 0.1 * t, -0.2 + 0.05 * np.sin(t), 0.2 + 0 * t], -1)  # off the box
    eng = MujocoEngine(_physics(0.4), dt=DT, meshes={"pusher": rp})
    drive = make_drive(
        DT,
        hand[None],
        yaw[None],
        t[None],
        np.array([[0.0, 0.0, HALF]]),
        np.zeros(1),
        pusher_dofs=got[None],
    )
    geoms = {
        n: (_geom(eng, f"pusher/{n}/0"), g) for n, g in (("tip", (0, 0, 0)), ("pad", (0.01, 0, 0)))
    }
    err = 0.0
    for k, m, d in eng.step_states(drive):
        mujoco.mj_kinematics(m, d)  # the state after step k
        world = _move(hand[k + 1]) @ _rot(2, yaw[k + 1])
        for name, (g, off) in geoms.items():
            want = world @ links[name][k + 1] @ _move(off)
            err = max(err, float(np.abs(d.geom_xpos[g] - want[:3, 3]).max()))
            err = max(err, float(np.abs(d.geom_xmat[g].reshape(3, 3) - want[:3, :3]).max()))
    assert err < 1e-9

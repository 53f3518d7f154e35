"""A rolling and pitching end effector in the MuJoCo robot pusher (issue 16, h78).

When the recorded end effector's roll and pitch move its links over their budget, the pusher
body gets two hinge servos after its yaw hinge (``R_ee = Rz(yaw) Ry(pitch) Rx(roll)``,
``mujoco_robot.pusher_model`` / ``ee_tilt``). Fixtures in closed form: the URDF is written
here, the end-effector orientation is built from its angles by matrix products.

Oracles:

* composition: yaw, pitch and roll all moving (sinusoids, pitch up to 35 deg) with a 30 mm
  pusher offset, no contact: at every step the tool geom's world pose in MuJoCo is the
  recorded ``[R_ee | x_ee]`` (closed form) within 1 um and 1 urad (the dead-beat servos
  track to float error, 1e-12 m measured; the wrong gimbal order, ``Rx Ry Rz``, is off by
  > 5 mm at the same steps);
* (c) a paddle (8 x 100 x 40 mm box) on a tool heading 0.5 rad, pitched from 0 to 20 deg
  before it reaches the box, pushes it along the heading with its top front edge: after
  contact the box's centre is ``s + 4 cos 20 + 20 sin 20 + 25`` mm along the heading (s the
  pusher point's), within 0.02 mm (the soft contact's compression under mu m g = 1.6 N along
  the push: 7.0 um measured), and the contact points sit at the edge's height ``z_p - 4 sin 20
  + 20 cos 20`` mm within 1 um (the compression is along the push, not across the edge:
  1e-10 m measured); the box keeps its heading (face-on: 1e-6 rad) and its lateral position
  (1 um). Counterfactual: the same push unpitched leads by the paddle's half thickness only
  (6.6 mm less; its own relation within 0.05 mm, 3.5 um measured);
* the gimbal guard: a pitch of 85 deg is refused naming the angle; a constant pitch is not a
  DOF (the one-body path carries it).
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch

from robogs.format.errors import InputError
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.engines.mujoco_robot import (
    RobotPusher,
    dof_values,
    ee_tilt,
    pusher_model,
)

torch.set_num_threads(1)

DT = 1e-3
HALF = 0.025  # the box's half size [m]
PADDLE = (0.004, 0.05, 0.02)  # half sizes [m]
HEADING = 0.5


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _urdf(tmp: Path) -> Path:
    size = " ".join(str(2 * h) for h in PADDLE)
    path = tmp / "robot" / "tool.urdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        '<?xml version="1.0"?><robot name="tool"><link name="base"/>'
        '<link name="tool"><inertial><mass value="0.1"/><inertia ixx="1e-4" ixy="0" ixz="0" '
        'iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
        f'<collision><geometry><box size="{size}"/></geometry></collision></link>'
        '<joint name="mount" type="fixed"><parent link="base"/><child link="tool"/></joint>'
        "</robot>"
    )
    return path


def _physics(offset=None) -> dict:
    pusher = {
        "equation": "kinematic",
        "radius_m": 0.01,
        "friction_dynamic": 0.0,
        "geometry": "robot",
        "link": "tool",
    }
    if offset is not None:
        pusher["offset_m"] = list(offset)
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


def _robot(urdf: Path, rot: np.ndarray, offset=None) -> RobotPusher:
    reach = float(np.linalg.norm(PADDLE))
    frames, bodies, tilt, joints, _ = pusher_model(
        rot, offset, {"tool": np.eye(4)[None]}, reach_m=reach
    )
    return RobotPusher(
        urdf, "tool", frames, root=urdf.parents[1], tilt=tilt, joints=joints, bodies=bodies
    )


def _drive(point: np.ndarray, yaw: np.ndarray, dofs: np.ndarray, box: np.ndarray):
    n = len(point)
    return make_drive(
        DT,
        point[None],
        yaw[None],
        (np.arange(n) * DT)[None],
        box[None],
        np.full(1, HEADING),
        pusher_dofs=dofs[None],
    )


def test_tilt_hinges_compose_as_the_recorded_orientation(tmp_path: Path) -> None:
    urdf = _urdf(tmp_path)
    n = 800
    t = np.arange(n) * DT
    yaw = 0.3 + 0.8 * np.sin(2.0 * t)
    pitch = math.radians(35.0) * np.sin(3.0 * t)
    roll = math.pi - 0.6 * np.sin(2.5 * t)  # a tool pointing down rolls about pi
    rot = np.stack([_rz(a) @ _ry(b) @ _rx(c) for a, b, c in zip(yaw, pitch, roll, strict=True)])
    off = np.array([0.01, -0.02, 0.03])
    rp = _robot(urdf, rot, off)
    assert rp.tilt and rp.dofs == ["pitch", "roll"] and rp.joints == []
    assert np.abs(rp.frames["tool"][:3, 3] + off).max() < 1e-12  # [I | -offset]
    got_p, got_r = ee_tilt(rot)
    np.testing.assert_allclose(got_p, pitch, atol=1e-12)
    wraps = (got_r - roll) / (2 * math.pi)  # roll near pi: unwrapped, one turn at most
    assert np.abs(wraps - np.round(wraps[0])).max() < 1e-9
    dofs = dof_values(rp, rot)
    x_ee = np.stack([0.3 * np.cos(t), 0.2 * np.sin(t), 0.4 + 0.05 * t], -1)  # far from the box
    point = x_ee + rot @ off
    eng = MujocoEngine(_physics(off), dt=DT, meshes={"pusher": rp})
    drive = _drive(point, yaw, dofs, np.array([1.0, 1.0, HALF]))
    g = mujoco.mj_name2id(eng.model, mujoco.mjtObj.mjOBJ_GEOM, "pusher/tool/0")
    err_p, err_r, wrong = 0.0, 0.0, 0.0
    for k, m, d in eng.step_states(drive):
        mujoco.mj_kinematics(m, d)  # the poses of the state after step k (t = (k + 1) dt)
        err_p = max(err_p, float(np.abs(d.geom_xpos[g] - x_ee[k + 1]).max()))
        err_r = max(err_r, float(np.abs(d.geom_xmat[g].reshape(3, 3) - rot[k + 1]).max()))
        flip = _rx(roll[k + 1]) @ _ry(pitch[k + 1]) @ _rz(yaw[k + 1])
        wrong = max(wrong, float(np.abs(point[k + 1] - flip @ off - x_ee[k + 1]).max()))
    assert err_p < 1e-6 and err_r < 1e-6
    assert wrong > 5e-3  # the other gimbal order puts the tool elsewhere


def _pitched_push(urdf: Path, pitch_deg: float):
    """The paddle heading 0.5 rad, pitched 0 -> ``pitch_deg`` in the first 0.3 s (cosine),
    still until 0.4 s, then pushing at 0.1 m/s along its heading, the pusher point 25 mm up."""
    n = 1500
    t = np.arange(n) * DT
    theta = math.radians(pitch_deg) * 0.5 * (1 - np.cos(np.pi * np.clip(t / 0.3, 0.0, 1.0)))
    rot = np.stack([_rz(HEADING) @ _ry(a) for a in theta])
    s = 0.1 * np.clip(t - 0.4, 0.0, None)
    h = np.array([math.cos(HEADING), math.sin(HEADING), 0.0])
    point = s[:, None] * h + [0.0, 0.0, 0.025]
    rp = _robot(urdf, rot)
    eng = MujocoEngine(_physics(), dt=DT, meshes={"pusher": rp})
    dofs = dof_values(rp, rot) if rp.dofs else np.zeros((n, 0))
    drive = _drive(point, np.full(n, HEADING), dofs, 0.06 * h + [0.0, 0.0, HALF])
    out = eng.rollout(drive)
    pos, quat = out.pos["box"][0, 0], out.quat["box"][0, 0]
    along = pos @ h
    side = pos @ np.array([-h[1], h[0], 0.0])
    return rp, eng, drive, s, along, side, quat


def test_c_a_pitched_paddle_pushes_with_its_top_edge(tmp_path: Path) -> None:
    urdf = _urdf(tmp_path)
    rp, eng, drive, s, along, side, quat = _pitched_push(urdf, 20.0)
    assert rp.tilt
    th = math.radians(20.0)
    lead = PADDLE[0] * math.cos(th) + PADDLE[2] * math.sin(th)  # the top front edge [m]
    late = slice(1000, None)  # contact from s = 24.4 mm (t = 0.64 s) on
    assert np.abs(along[late] - (s[late] + lead + HALF)).max() < 2e-5
    assert np.abs(side).max() < 1e-6
    yaw = 2 * np.arctan2(quat[:, 3], quat[:, 0])
    assert np.abs(yaw - HEADING).max() < 1e-6
    *_, (_, m, d) = eng.step_states(drive)
    box = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "box")
    paddle = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pusher/tool/0")
    z = [
        d.contact[i].pos[2]
        for i in range(d.ncon)
        if {d.contact[i].geom1, d.contact[i].geom2} == {box, paddle}
    ]
    edge = 0.025 - PADDLE[0] * math.sin(th) + PADDLE[2] * math.cos(th)
    assert z and np.abs(np.array(z) - edge).max() < 1e-6
    assert edge < 2 * HALF  # below the box's top: the edge, not the face, touches
    # counterfactual: unpitched, the paddle leads by its half thickness only
    flat, _, _, s0, along0, _, _ = _pitched_push(urdf, 0.0)
    assert not flat.tilt and flat.dofs == []
    assert np.abs(along0[late] - (s0[late] + PADDLE[0] + HALF)).max() < 5e-5
    assert np.abs(along[late] - along0[late]).min() > 6e-3


def test_the_gimbal_guard_and_a_constant_pitch(tmp_path: Path) -> None:
    n = 50
    up = np.stack([_ry(a) for a in np.linspace(0.0, math.radians(85.0), n)])
    with pytest.raises(InputError, match="pitches to 85.0 deg") as err:
        pusher_model(up, None, {"tool": np.eye(4)[None]}, reach_m=0.05)
    assert "gimbal" in str(err.value) and "objects.pusher.link" in (err.value.hint or "")
    still = np.repeat((_rz(0.2) @ _ry(math.radians(30.0)))[None], n, 0)
    frames, bodies, tilt, joints, rig = pusher_model(
        still, None, {"tool": np.eye(4)[None]}, reach_m=0.05
    )
    assert not tilt and not joints and rig.moved_m < 1e-12
    np.testing.assert_allclose(frames["tool"][:3, :3], _ry(math.radians(30.0)), atol=1e-12)

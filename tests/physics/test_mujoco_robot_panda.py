"""The robot pusher on a real third-party gripper: the Franka Panda hand (issue 16, h86).

The Panda URDF of the real-data folder (example-robot-data 6.0.0; the hand's collision a
``package://`` STL mesh, each finger four collision boxes, ``panda_finger_joint2`` a ``<mimic>``
of ``panda_finger_joint1``) with the pusher link ``panda_hand``. The recording is synthesised
here: the arm at the Panda's ready pose (hand pointing down) or turning slowly about its first
and last joints (the hand circles and yaws; pitch and roll stay), ``panda_finger_joint1``
closing 0.04 -> 0.01 m over 1 s, then held; 1 kHz on the engine's 1 ms grid. The robot pusher
is measured from the project's forward kinematics (``Chain``) as ``load_recording`` measures it
(``pusher_model`` of the links' poses in the hand frame) and built by the MuJoCo engine.

Oracles:

* forward kinematics by a third party (yourdfpy, the URDF read on its own): the two finger
  bodies of the MuJoCo model (``pusher/panda_finger_joint1``, ``..2``, whose frame is the
  finger link's) and each finger's rubber-tip geom are at yourdfpy's ``T_link0_finger`` at every
  100th step within 1e-11 m while nothing touches them (float error of the dead-beat servos:
  7.4e-13 m measured, 5.4e-13 with the edited mimic); the mimic is followed: the DOF values read back from the links'
  poses are ``q1`` and ``multiplier * q1 + offset`` within 1e-12 (the Panda's 1 and 0, and the
  URDF edited to 0.5 and 5 mm, a mutated fixture), as are the finger joints of the MuJoCo state
  within 1e-9; the ``start`` keyframe of the engine's document holds the first values when
  given them (0.04 and 0.04 / 0.025 m);
* a box between the fingers (a cube of the fingers' closed gap, 19.96 mm: each rubber tip's
  inner face is 0.02 mm inside its finger's origin) placed 6 mm or 4 mm off-centre along the
  closing axis on a table at the tips' height ends centred between the fingers (closed form:
  the hand's axis) within 0.01 mm (measured 0.23 um at table mu 0.05, 1.5 um at mu 0.4: the
  soft contact's compression), its position across the closing axis and its yaw unchanged
  within 1e-9 m and 1e-9 rad; the fingers, clamping it, stay at the URDF forward kinematics
  within 1.5 F / kp + 1e-11 m, the finger servo's static deflection under the largest contact
  force F on a finger (kp 3e8 N/m; the servos hold the recorded value against the contact,
  but a position servo yields F / kp): measured 1.6e-10 m and 1.3e-9 m against F / kp 2.6e-9 m
  and 3.3e-9 m (F 0.78 N and 0.99 N).
  Counterfactual: with the fingers held open (the one-body path, no servo DOF) the box does
  not move (1e-9 m).

What ``pusher_model`` does with the mimic: nothing special. Each joint below the pusher link is
measured from its links' forward-kinematics poses (``joint_value``), and the project's
forward kinematics applies the ``<mimic>`` (``Chain``: ``multiplier * q + offset``), so the
mimic's recorded value is its leader's through the URDF; it is its own servo DOF following it.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import torch
import yourdfpy

from robogs.format.frames import matrix_to_quat_np
from robogs.format.kinematics import Chain
from robogs.format.urdf import load_urdf
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import MujocoEngine
from robogs.physics.engines.mujoco_robot import (
    RobotPusher,
    distal_joints,
    dof_values,
    pusher_model,
)
from robogs.physics.recording import yaw_of

pytestmark = pytest.mark.realdata

torch.set_num_threads(1)

DT = 1e-3
HAND = "panda_hand"
FINGERS = ("panda_leftfinger", "panda_rightfinger")
JOINTS = ("panda_finger_joint1", "panda_finger_joint2")
READY = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])  # the hand points down
TIP = np.array([0.0, 7.58e-3, 45.25e-3])  # the left rubber tip's centre in its finger's frame
TIP_HALF_Y = 7.6e-3  # its half thickness along the closing axis
FINGER_Z = 0.0584  # the finger joints' origin along the hand's z
MIMIC = '<mimic joint="panda_finger_joint1"/>'


@pytest.fixture(scope="module")
def panda(real_data: Path) -> tuple[Path, Path, dict[str, Path]]:
    """(URDF, allowed root, package roots) of the real Panda."""
    root = real_data / "franka_panda"
    urdf = root / "robots" / "panda_description" / "urdf" / "panda.urdf"
    return urdf, root, {"example-robot-data": root}


def _urdf(panda, tmp: Path, mimic: tuple[float, float] | None) -> Path:
    """The Panda's URDF, or a copy with the finger mimic's multiplier and offset edited."""
    urdf = panda[0]
    if mimic is None:
        return urdf
    text = urdf.read_text()
    assert text.count(MIMIC) == 1
    edited = MIMIC.replace("/>", f' multiplier="{mimic[0]!r}" offset="{mimic[1]!r}"/>')
    out = tmp / "panda_mimic.urdf"
    out.write_text(text.replace(MIMIC, edited))
    return out


def _closing(n: int) -> np.ndarray:
    """``panda_finger_joint1`` [n] m: 0.04 -> 0.01 over 1 s, then held."""
    return np.clip(0.04 - 0.03 * np.arange(n) * DT, 0.01, None)


def _robot(panda, urdf: Path, q: np.ndarray, moving: bool = True):
    """The robot pusher of the joint trajectory ``q`` [N, 8] (arm, finger 1), measured from the
    project's forward kinematics as ``load_recording`` measures it: (robot pusher, hand poses
    [N, 4, 4] in the base frame, links' poses in the hand frame). ``moving``: the fingers move
    (two servo DOFs), else the hand and fingers are one body."""
    _, root, pkgs = panda
    chain = Chain.from_urdf(load_urdf(urdf, root=root, package_roots=pkgs, load_meshes=False))
    assert chain.joint_names == [*(f"panda_joint{k}" for k in range(1, 8)), JOINTS[0]]
    T = chain.forward(torch.as_tensor(q, dtype=torch.float64)).numpy()
    hand = T[:, chain.link_index(HAND)]
    inv = np.linalg.inv(hand)
    links = {n: inv @ T[:, chain.link_index(n)] for n in (HAND, "panda_hand_tcp", *FINGERS)}
    frames, bodies, tilt, joints, rig = pusher_model(
        hand[:, :3, :3], None, links, distal_joints(chain, HAND)
    )
    assert not tilt and rig.moved_m < 1e-12  # every link rigid in the body that carries it
    if moving:
        assert [j.name for j in joints] == list(JOINTS)
        assert bodies == {HAND: "", "panda_hand_tcp": "", **dict(zip(FINGERS, JOINTS, strict=True))}
    else:
        assert joints == [] and set(bodies.values()) == {""}
    rp = RobotPusher(
        urdf, HAND, frames, root=root, package_roots=pkgs, tilt=tilt, joints=joints, bodies=bodies
    )
    return rp, hand, links


def _physics(half: float, table_z: float, mu_table: float) -> dict:
    return {
        "revision": 1,
        "objects": {
            "box": {
                "equation": "rigid",
                "size_m": [2 * half] * 3,
                "mass_kg": 0.05,
                "friction_dynamic": mu_table,
            },
            "table": {"equation": "static", "plane_z_m": table_z},
            "pusher": {
                "equation": "kinematic",
                "radius_m": 0.01,
                "friction_dynamic": 0.5,
                "geometry": "robot",
                "link": HAND,
            },
        },
    }


def _drive(hand: np.ndarray, dofs: np.ndarray | None, box: np.ndarray, box_yaw: float):
    """The hand's path (origin and yaw, the pusher point at the hand origin), the DOFs."""
    n = len(hand)
    yaw = np.unwrap(yaw_of(matrix_to_quat_np(hand[:, :3, :3])))
    return make_drive(
        DT,
        hand[None, :, :3, 3],
        yaw[None],
        (np.arange(n) * DT)[None],
        box[None],
        np.array([box_yaw]),
        pusher_dofs=None if dofs is None else dofs[None],
    )


def _fk_error(
    eng: MujocoEngine, drive, q: np.ndarray, urdf: Path, every: int = 100
) -> tuple[float, float]:
    """Largest distance [m] (and rotation-matrix entry difference) over every ``every``-th
    step between the MuJoCo finger bodies and left tip geom and yourdfpy's forward kinematics
    of the recorded joints, in the base frame (the world); and the servos' static deflection
    under the largest contact force on a finger over every step, ``F / kp`` [m] (the sum of the
    normal forces of its contacts over the finger servo's position gain)."""
    ref = yourdfpy.URDF.load(
        str(urdf), load_meshes=False, build_collision_scene_graph=False, load_collision_meshes=False
    )
    m = eng.model
    body = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"pusher/{j}") for j in JOINTS]
    tip = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"pusher/{FINGERS[0]}/3")
    assert min(body) >= 0 and tip >= 0
    np.testing.assert_allclose(m.geom_size[tip], [8.75e-3, TIP_HALF_Y, 9.25e-3], atol=1e-12)
    kp = float(m.actuator_gainprm[m.actuator(f"pusher/{JOINTS[0]}").id, 0])
    fingers = {
        g
        for g in range(m.ngeom)
        if (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "").split("/")[1:2]
        in ([FINGERS[0]], [FINGERS[1]])
    }
    assert len(fingers) == 8  # four collision boxes each
    err, force, checked = 0.0, 0.0, 0
    f6 = np.zeros(6)
    for k, _, d in eng.step_states(drive):
        for side in FINGERS:
            total = 0.0
            for i in range(d.ncon):
                c = d.contact[i]
                if {c.geom1, c.geom2} & {g for g in fingers if side in m.geom(g).name}:
                    mujoco.mj_contactForce(m, d, i, f6)
                    total += abs(f6[0])
            force = max(force, total)
        if (k + 1) % every:
            continue
        mujoco.mj_kinematics(m, d)  # the state after step k
        ref.update_cfg(q[k + 1])
        for b, name in zip(body, FINGERS, strict=True):
            want = ref.get_transform(name, "panda_link0")
            err = max(err, float(np.abs(d.xpos[b] - want[:3, 3]).max()))
            err = max(err, float(np.abs(d.xmat[b].reshape(3, 3) - want[:3, :3]).max()))
        want = ref.get_transform(FINGERS[0], "panda_link0") @ np.append(TIP, 1.0)
        err = max(err, float(np.abs(d.geom_xpos[tip] - want[:3]).max()))
        checked += 1
    assert checked >= len(q) // every - 1
    return err, force / kp


@pytest.mark.parametrize("mimic", [None, (0.5, 0.005)], ids=["panda", "mimic_0.5_5mm"])
def test_panda_fingers_follow_the_urdf_forward_kinematics(panda, tmp_path: Path, mimic) -> None:
    urdf = _urdf(panda, tmp_path, mimic)
    mul, off = mimic or (1.0, 0.0)
    n = 1500
    t = np.arange(n) * DT
    q = np.tile(np.append(READY, 0.0), (n, 1))
    q[:, 0] += 0.2 * t  # the arm turns slowly about its base (the hand circles and yaws)
    q[:, 6] -= 0.3 * t  # and about its flange (the hand yaws)
    q[:, 7] = _closing(n)
    rp, hand, links = _robot(panda, urdf, q)
    dofs = dof_values(rp, hand[:, :3, :3], links)
    assert np.abs(dofs[:, 0] - q[:, 7]).max() < 1e-12
    assert np.abs(dofs[:, 1] - (mul * q[:, 7] + off)).max() < 1e-12  # the mimic followed
    rp.start = [float(v) for v in dofs[0]]
    eng = MujocoEngine(_physics(0.01, 0.0, 0.4), dt=DT, meshes={"pusher": rp})
    assert eng.pusher_dofs == list(JOINTS)
    adr = [eng.model.joint(f"pusher/{j}").qposadr[0] for j in JOINTS]
    key = eng.model.key("start")
    np.testing.assert_allclose(key.qpos[adr], [0.04, mul * 0.04 + off], rtol=0, atol=1e-15)
    drive = _drive(hand, dofs, np.array([2.0, 2.0, 0.01]), 0.0)  # the box out of reach
    err, deflection = _fk_error(eng, drive, q, urdf)
    print(f"mimic {mimic}: MuJoCo fingers vs yourdfpy FK {err:.2e}")
    assert deflection == 0.0 and err < 1e-11  # nothing touches the fingers
    *_, (_, _, last) = eng.step_states(drive)
    q1, q2 = last.qpos[adr]
    assert abs(q1 - 0.01) < 1e-9 and abs(q2 - (mul * q1 + off)) < 1e-9


@pytest.mark.parametrize("y0, mu", [(0.006, 0.05), (-0.004, 0.4)])
def test_panda_fingers_centre_a_box(panda, y0: float, mu: float) -> None:
    n = 1500
    q = np.tile(np.append(READY, 0.0), (n, 1))
    q[:, 7] = _closing(n)
    urdf = panda[0]
    rp, hand, links = _robot(panda, urdf, q)
    dofs = dof_values(rp, hand[:, :3, :3], links)
    h = hand[0]
    assert abs(h[2, 2] + 1.0) < 1e-6  # the hand points down: its closing axis (y) horizontal
    half = 0.01 - (TIP_HALF_Y - TIP[1])  # the closed tips' inner faces are 19.96 mm apart
    assert half == pytest.approx(9.98e-3, abs=1e-12)
    centre = (h @ np.array([0.0, 0.0, FINGER_Z + TIP[2], 1.0]))[:3]  # between the tips
    box0 = centre + y0 * h[:3, 1]
    yaw0 = float(yaw_of(matrix_to_quat_np(h[None, :3, :3]))[0])
    physics = _physics(half, float(centre[2] - half), mu)
    eng = MujocoEngine(physics, dt=DT, meshes={"pusher": rp})
    drive = _drive(hand, dofs, box0, yaw0)
    out = eng.rollout(drive)
    pos, quat = out.pos["box"][0, 0], out.quat["box"][0, 0]
    rel = pos - centre
    along, across = rel @ h[:3, 1], rel @ h[:3, 0]
    print(f"y0 {y0}, mu {mu}: box off the hand's axis by {along[-1]:.2e} m")
    assert abs(along[0] - y0) < 1e-9
    assert abs(along[-1]) < 1e-5  # centred between the fingers
    assert np.abs(across).max() < 1e-9
    assert abs(2 * math.atan2(quat[-1, 3], quat[-1, 0]) - yaw0) < 1e-9
    err, deflection = _fk_error(eng, drive, q, urdf)
    print(f"clamping: MuJoCo fingers vs yourdfpy FK {err:.2e}, F/kp {deflection:.2e}")
    assert 0.0 < deflection < 1e-8  # the fingers touch it; their servos barely give
    assert err < 1.5 * deflection + 1e-11  # where the recording puts them, but for that
    # counterfactual: the fingers held open are one rigid body, and the box stays put
    q_open = q.copy()
    q_open[:, 7] = 0.04
    still, hand_o, _ = _robot(panda, urdf, q_open, moving=False)
    eng0 = MujocoEngine(physics, dt=DT, meshes={"pusher": still})
    p0 = eng0.rollout(_drive(hand_o, None, box0, yaw0)).pos["box"][0, 0]
    assert np.abs(p0[-1, :2] - p0[0, :2]).max() < 1e-9  # (z: it settles into the table)

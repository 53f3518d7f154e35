"""Oracle tests of the arm inverse dynamics (RNEA and its regressor)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from robogs.format.errors import InputError
from robogs.format.kinematics import Chain
from robogs.format.urdf import load_urdf
from robogs.physics.arm.rnea import ArmModel, inertial_vector, inverse_dynamics, regressor
from robogs.synth.armlogs.dynamics import parse_arm, world_inverse_dynamics

UR5_REL = "ur5/robots/ur_description/urdf/ur5_robot.urdf"  # inside the real-data folder

# two links in the x-z plane, joints about -y (positive angles lift the links), no base inertia
L1, LC1, LC2, M1, M2, I1, I2 = 0.7, 0.3, 0.25, 2.0, 1.5, 0.05, 0.03
PLANAR = f"""<robot name="planar">
 <link name="base"/>
 <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 -1 0"/>
  <limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
 <link name="l1"><inertial><origin xyz="{LC1} 0 0"/><mass value="{M1}"/>
  <inertia ixx="0.01" ixy="0" ixz="0" iyy="{I1}" iyz="0" izz="0.01"/></inertial></link>
 <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="{L1} 0 0"/>
  <axis xyz="0 -1 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
 <link name="l2"><inertial><origin xyz="{LC2} 0 0"/><mass value="{M2}"/>
  <inertia ixx="0.01" ixy="0" ixz="0" iyy="{I2}" iyz="0" izz="0.01"/></inertial></link>
</robot>
"""

# revolute with a tilted axis, a fixed link with rotated inertia folded in, a prismatic joint,
# a continuous joint and a mimic joint
MIXED = """<robot name="mixed">
 <link name="base"><inertial><mass value="2"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
 <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0.1 0.2 0.3" rpy="0.3 -0.2 0.5"/>
  <axis xyz="0.3 0.4 0.866"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
 <link name="l1"><inertial><origin xyz="0.05 -0.02 0.1" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
  <inertia ixx="0.02" ixy="0.001" ixz="-0.002" iyy="0.03" iyz="0.003" izz="0.025"/></inertial></link>
 <joint name="jf" type="fixed"><parent link="l1"/><child link="lf"/><origin xyz="0.0 0.1 0.2" rpy="0.4 0 -0.3"/></joint>
 <link name="lf"><inertial><origin xyz="0.01 0.02 0.03" rpy="0 0.5 0"/><mass value="0.7"/>
  <inertia ixx="0.004" ixy="0.0" ixz="0.0" iyy="0.005" iyz="0.0" izz="0.006"/></inertial></link>
 <joint name="j2" type="prismatic"><parent link="lf"/><child link="l2"/><origin xyz="0.2 0 0.05" rpy="0 0.7 0"/>
  <axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
 <link name="l2"><inertial><origin xyz="0.1 0.0 -0.05"/><mass value="1.1"/>
  <inertia ixx="0.01" ixy="0.0" ixz="0.0" iyy="0.012" iyz="0.0" izz="0.014"/></inertial></link>
 <joint name="j3" type="continuous"><parent link="l2"/><child link="l3"/><origin xyz="0.0 0.15 0.0" rpy="1.0 0 0"/>
  <axis xyz="0 1 0"/></joint>
 <link name="l3"><inertial><origin xyz="0.0 0.0 0.12"/><mass value="0.8"/>
  <inertia ixx="0.006" ixy="0.0" ixz="0.0" iyy="0.006" iyz="0.0" izz="0.002"/></inertial></link>
 <joint name="jm" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0.0 0.0 0.2"/>
  <axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="10" velocity="1"/>
  <mimic joint="j1" multiplier="0.5" offset="0.1"/></joint>
 <link name="l4"><inertial><origin xyz="0.0 0.05 0.05"/><mass value="0.4"/>
  <inertia ixx="0.002" ixy="0.0" ixz="0.0" iyy="0.003" iyz="0.0" izz="0.002"/></inertial></link>
</robot>
"""


def _urdf(tmp_path: Path, text: str, name: str):
    p = tmp_path / f"{name}.urdf"
    p.write_text(text)
    return load_urdf(p, load_meshes=False), p


def _states(rng: np.random.Generator, n: int, j: int):
    return (
        torch.tensor(rng.uniform(-1.5, 1.5, (n, j))),
        torch.tensor(rng.uniform(-2, 2, (n, j))),
        torch.tensor(rng.uniform(-4, 4, (n, j))),
    )


def test_two_link_planar_closed_form(tmp_path):
    urdf, _ = _urdf(tmp_path, PLANAR, "planar")
    model = ArmModel.from_urdf(urdf)
    q, qd, qdd = _states(np.random.default_rng(0), 64, 2)
    tau = inverse_dynamics(model, q, qd, qdd).numpy()
    q1, q2 = q[:, 0].numpy(), q[:, 1].numpy()
    d1, d2 = qd[:, 0].numpy(), qd[:, 1].numpy()
    a1, a2 = qdd[:, 0].numpy(), qdd[:, 1].numpy()
    g = 9.81
    c2, s2 = np.cos(q2), np.sin(q2)
    m11 = I1 + I2 + M1 * LC1**2 + M2 * (L1**2 + LC2**2 + 2 * L1 * LC2 * c2)
    m12 = I2 + M2 * (LC2**2 + L1 * LC2 * c2)
    m22 = I2 + M2 * LC2**2
    h = M2 * L1 * LC2 * s2
    g1 = (M1 * LC1 + M2 * L1) * g * np.cos(q1) + M2 * LC2 * g * np.cos(q1 + q2)
    g2 = M2 * LC2 * g * np.cos(q1 + q2)
    t1 = m11 * a1 + m12 * a2 - h * (2 * d1 * d2 + d2**2) + g1
    t2 = m12 * a1 + m22 * a2 + h * d1**2 + g2
    np.testing.assert_allclose(tau, np.stack([t1, t2], 1), atol=1e-11)


def _lagrangian_torque(chain: Chain, urdf, q, qd, qdd, g=9.81):
    """tau = d/dt dL/dqd - dL/dq by automatic differentiation of L = T - V built on Chain.forward."""
    links = {lk.name: lk for lk in urdf.robot.links}
    bodies = []
    for k, name in enumerate(chain.link_names):
        ine = links[name].inertial
        if ine is None or not ine.mass or k == 0:
            continue
        o = np.eye(4) if ine.origin is None else np.asarray(ine.origin, float)
        bodies.append(
            (k, float(ine.mass), torch.tensor(o), torch.tensor(np.asarray(ine.inertia, float)))
        )
    nj = chain.num_joints

    def lagr(x):
        qq, vv = x[:nj], x[nj:]

        def poses(z):
            t = chain.forward(z)
            return torch.stack([t[k] @ o for k, _, o, _ in bodies])

        p, dp = torch.autograd.functional.jvp(poses, (qq,), (vv,), create_graph=True)
        out = 0.0
        for i, (_, m, _, ic) in enumerate(bodies):
            r, dr, v = p[i, :3, :3], dp[i, :3, :3], dp[i, :3, 3]
            w_hat = dr @ r.T
            w = torch.stack([w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]])
            out = out + 0.5 * m * v @ v + 0.5 * w @ (r @ ic @ r.T) @ w - m * g * p[i, 2, 3]
        return out

    x = torch.cat([q, qd])
    hess = torch.autograd.functional.hessian(lagr, x)
    xg = x.clone().requires_grad_(True)
    grad = torch.autograd.grad(lagr(xg), xg)[0]
    return hess[nj:, :nj] @ qd + hess[nj:, nj:] @ qdd - grad[:nj]


def test_mixed_tree_matches_autodiff_lagrangian(tmp_path):
    urdf, _ = _urdf(tmp_path, MIXED, "mixed")
    model = ArmModel.from_urdf(urdf)
    chain = Chain.from_urdf(urdf)
    assert model.joint_names == ("j1", "j2", "j3")
    assert model.body_names == ("l1", "l2", "l3", "l4")  # lf folded into l1
    q, qd, qdd = _states(np.random.default_rng(1), 4, 3)
    tau = inverse_dynamics(model, q, qd, qdd)
    for i in range(4):
        ref = _lagrangian_torque(chain, urdf, q[i], qd[i], qdd[i])
        torch.testing.assert_close(tau[i], ref, atol=1e-10, rtol=1e-10)


def test_regressor_reproduces_rnea(tmp_path):
    urdf, _ = _urdf(tmp_path, MIXED, "mixed")
    model = ArmModel.from_urdf(urdf)
    q, qd, qdd = _states(np.random.default_rng(2), 32, 3)
    y = regressor(model, q, qd, qdd)
    pi = torch.as_tensor(inertial_vector(model.inertials))
    torch.testing.assert_close(
        torch.einsum("njbk,bk->nj", y, pi), inverse_dynamics(model, q, qd, qdd), atol=1e-11, rtol=0
    )
    # linear in the parameters: doubling all inertials doubles the torques
    torch.testing.assert_close(
        inverse_dynamics(model, q, qd, qdd, inertials=model.inertials.scaled(2.0)),
        2 * inverse_dynamics(model, q, qd, qdd),
        atol=1e-11,
        rtol=0,
    )


def test_independent_world_frame_implementation_agrees(tmp_path):
    """The generator's world-frame Newton-Euler (unfolded links) gives the same torques."""
    urdf, path = _urdf(
        tmp_path,
        MIXED.replace('<mimic joint="j1" multiplier="0.5" offset="0.1"/>', "").replace(
            'name="jm" type="revolute"', 'name="jm" type="fixed"'
        ),
        "nomimic",
    )
    model = ArmModel.from_urdf(urdf)
    q, qd, qdd = _states(np.random.default_rng(3), 50, 3)
    ref = world_inverse_dynamics(parse_arm(path), q.numpy(), qd.numpy(), qdd.numpy())
    np.testing.assert_allclose(inverse_dynamics(model, q, qd, qdd).numpy(), ref, atol=1e-11)


@pytest.mark.realdata
def test_real_ur5_regressor_and_independent_oracle(real_data: Path):
    UR5_REAL = real_data / UR5_REL
    model = ArmModel.from_urdf(load_urdf(UR5_REAL, load_meshes=False))
    assert model.last_link == "wrist_3_link"
    q, qd, qdd = _states(np.random.default_rng(4), 40, 6)
    tau = inverse_dynamics(model, q, qd, qdd)
    ref = world_inverse_dynamics(parse_arm(UR5_REAL), q.numpy(), qd.numpy(), qdd.numpy())
    np.testing.assert_allclose(tau.numpy(), ref, atol=1e-10)
    y = regressor(model, q, qd, qdd)
    pi = torch.as_tensor(inertial_vector(model.inertials))
    torch.testing.assert_close(torch.einsum("njbk,bk->nj", y, pi), tau, atol=1e-10, rtol=0)
    # static pose with the arm stretched horizontally: shoulder-lift torque = sum m g x_com
    zero = torch.zeros(1, 6)
    stretched = torch.tensor([[0.0, -np.pi / 2, 0.0, -np.pi / 2, 0.0, 0.0]], dtype=torch.float64)
    t_static = inverse_dynamics(model, stretched, zero.double(), zero.double())
    assert abs(float(t_static[0, 0])) < 1e-9  # gravity has no moment about the vertical pan axis


def test_shape_errors_are_input_errors(tmp_path):
    urdf, _ = _urdf(tmp_path, PLANAR, "planar")
    model = ArmModel.from_urdf(urdf)
    with pytest.raises(InputError, match="expected"):
        inverse_dynamics(model, torch.zeros(5, 3), torch.zeros(5, 3), torch.zeros(5, 3))

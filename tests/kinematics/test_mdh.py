"""Modified-DH tables: elementary products, closed forms, the UR5 table against URDF frames, JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from robogs.format import frames as F
from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics import (
    Chain,
    MDHTable,
    load_mdh_json,
    mdh_transform,
    save_mdh_json,
    ur5_mdh,
)
from robogs.format.urdf import load_urdf

HALF_PI = repr(math.pi / 2)


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def rot(R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    return T


def test_mdh_transform_is_the_elementary_product() -> None:
    rng = np.random.default_rng(0)
    a, al, d, th = rng.normal(size=(4, 50))
    got = mdh_transform(*(torch.from_numpy(x) for x in (a, al, d, th))).numpy()
    for k in range(50):
        ref = rot(F.rot_x(al[k])) @ trans(x=a[k]) @ rot(F.rot_z(th[k])) @ trans(z=d[k])
        assert np.abs(got[k] - ref).max() < 1e-15


def test_planar_closed_form_and_frames() -> None:
    l1, l2 = 0.5, 0.25
    table = MDHTable(
        a_m=[0.0, l1, l2], alpha_rad=[0.0, 0.0, 0.0], d_m=[0.0, 0.0, 0.0],
        theta_offset_rad=[0.0, 0.0, 0.0], joint_names=["j1", "j2", "tip"],
    )  # fmt: skip
    q = torch.tensor([[0.4, -0.9, 0.0], [math.pi, 0.5, 0.0]], dtype=torch.float64)
    frames = table.forward(q)
    assert frames.shape == (2, 4, 4, 4)
    assert torch.equal(frames[:, 0], torch.eye(4, dtype=torch.float64).expand(2, 4, 4))
    q1, q2 = q[:, 0], q[:, 1]
    tip = frames[:, 3, :3, 3]
    expect = torch.stack(
        [
            l1 * torch.cos(q1) + l2 * torch.cos(q1 + q2),
            l1 * torch.sin(q1) + l2 * torch.sin(q1 + q2),
            0 * q1,
        ],
        -1,
    )
    assert torch.abs(tip - expect).max() < 1e-15
    # a theta offset is the same as adding it to q
    shifted = MDHTable(**{**_fields(table), "theta_offset_rad": [0.2, 0.0, 0.0]})
    assert (
        torch.abs(
            shifted.forward(q) - table.forward(q + torch.tensor([0.2, 0, 0], dtype=torch.float64))
        ).max()
        < 1e-15
    )


def _fields(t: MDHTable) -> dict:
    return {
        "a_m": t.a_m, "alpha_rad": t.alpha_rad, "d_m": t.d_m, "theta_offset_rad": t.theta_offset_rad,
        "joint_names": t.joint_names, "T_base": t.T_base, "T_tool": t.T_tool,
    }  # fmt: skip


def test_from_standard_dh_preserves_the_tool_pose() -> None:
    rng = np.random.default_rng(1)
    n = 6
    a, alpha, d, off = rng.normal(size=(4, n))
    T_base = F.make_T(F.rotvec_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    T_tool = F.make_T(F.rotvec_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    table = MDHTable.from_standard_dh(a, alpha, d, off, [f"j{i}" for i in range(n)], T_base, T_tool)
    for _ in range(5):
        q = rng.uniform(-3, 3, n)
        ref = T_base.copy()
        for i in range(n):  # standard DH: RotZ TransZ TransX RotX
            ref = (
                ref
                @ rot(F.rot_z(q[i] + off[i]))
                @ trans(z=d[i])
                @ trans(x=a[i])
                @ rot(F.rot_x(alpha[i]))
            )
        ref = ref @ T_tool
        assert np.abs(table.tool_pose(torch.from_numpy(q)).numpy() - ref).max() < 1e-13


def _pose_errors(T_a: torch.Tensor, T_b: torch.Tensor) -> tuple[float, float]:
    dp = float((T_a[..., :3, 3] - T_b[..., :3, 3]).norm(dim=-1).max())
    rel = T_a[..., :3, :3].transpose(-1, -2) @ T_b[..., :3, :3]
    return dp, float(F.rotation_angle(rel).max())


INLINE_UR5 = f"""<?xml version="1.0"?>
<robot name="ur5_inline">
  <link name="base_link"/><link name="shoulder_link"/><link name="upper_arm_link"/>
  <link name="forearm_link"/><link name="wrist_1_link"/><link name="wrist_2_link"/>
  <link name="wrist_3_link"/><link name="tool0"/>
  <joint name="shoulder_pan_joint" type="revolute"><parent link="base_link"/><child link="shoulder_link"/>
    <origin xyz="0 0 0.089159"/><axis xyz="0 0 1"/></joint>
  <joint name="shoulder_lift_joint" type="revolute"><parent link="shoulder_link"/><child link="upper_arm_link"/>
    <origin xyz="0 0.10915 0" rpy="0 {HALF_PI} 0"/><axis xyz="0 1 0"/></joint>
  <joint name="elbow_joint" type="revolute"><parent link="upper_arm_link"/><child link="forearm_link"/>
    <origin xyz="0 0 0.425"/><axis xyz="0 1 0"/></joint>
  <joint name="wrist_1_joint" type="revolute"><parent link="forearm_link"/><child link="wrist_1_link"/>
    <origin xyz="0 0 0.39225" rpy="0 {HALF_PI} 0"/><axis xyz="0 1 0"/></joint>
  <joint name="wrist_2_joint" type="revolute"><parent link="wrist_1_link"/><child link="wrist_2_link"/>
    <origin xyz="0 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="wrist_3_joint" type="revolute"><parent link="wrist_2_link"/><child link="wrist_3_link"/>
    <origin xyz="0 0 0.09465"/><axis xyz="0 1 0"/></joint>
  <joint name="flange" type="fixed"><parent link="wrist_3_link"/><child link="tool0"/>
    <origin xyz="0 0.0823 0" rpy="-{HALF_PI} 0 0"/></joint>
</robot>
"""
# The URDF follows the ROS ur_description layout built only from the published DH numbers: the
# offsets along the (parallel) shoulder/elbow/wrist-1 axes are lumped into one d4 = 0.10915 m.


def _check_ur5_agreement(chain: Chain, n: int, seed: int) -> None:
    table = ur5_mdh()
    assert list(table.joint_names) == chain.joint_names
    q = torch.from_numpy(np.random.default_rng(seed).uniform(-math.pi, math.pi, size=(n, 6)))
    T_urdf = chain.forward(q)[:, chain.link_index("tool0")]
    dp, dr = _pose_errors(T_urdf, table.tool_pose(q))
    assert dp <= 1e-6 and dr <= 1e-6, (dp, dr)
    # intermediate frames: MDH frame i sits on joint i's axis (z_i parallel to the URDF axis)
    frames = table.forward(q)
    for i, name in enumerate(chain.joint_names):
        k = chain.tree_joint_names.index(name) + 1
        T_child = chain.forward(q)[:, k]
        axis_world = T_child[:, :3, :3] @ torch.from_numpy(chain.axes[k - 1])
        z_mdh = frames[:, i + 1, :3, 2]
        assert torch.abs(torch.abs((axis_world * z_mdh).sum(-1)) - 1).max() < 1e-9
        diff = frames[:, i + 1, :3, 3] - T_child[:, :3, 3]
        off_axis = diff - (diff * axis_world).sum(-1, keepdim=True) * axis_world
        assert off_axis.norm(dim=-1).max() < 1e-6


def test_ur5_table_matches_inline_urdf(tmp_path: Path) -> None:
    p = tmp_path / "ur5.urdf"
    p.write_text(INLINE_UR5)
    _check_ur5_agreement(Chain.from_urdf(load_urdf(p, load_meshes=False)), 200, 5)


@pytest.mark.realdata
def test_ur5_table_matches_real_urdf(real_urdf_args) -> None:
    path, root, pkgs = real_urdf_args("ur5")
    _check_ur5_agreement(
        Chain.from_urdf(load_urdf(path, root=root, package_roots=pkgs, load_meshes=False)), 200, 6
    )


def test_mdh_gradients_and_dtype() -> None:
    table = ur5_mdh()
    q = torch.rand(3, 6, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: table.tool_pose(x)[..., :3, :], (q,))
    assert table.forward(q.detach().float()).dtype == torch.float32
    with pytest.raises(InputError):
        table.forward(torch.zeros(5))


def test_json_round_trip(tmp_path: Path) -> None:
    table = ur5_mdh()
    table.T_tool = F.make_T(
        F.rotvec_to_matrix(np.array([0.1, -0.2, 0.3])), np.array([0.01, 0.02, 0.1])
    )
    p = tmp_path / "mdh.json"
    save_mdh_json(table, p)
    back = load_mdh_json(p)
    for key in ("a_m", "alpha_rad", "d_m", "theta_offset_rad", "T_base", "T_tool"):
        assert np.array_equal(getattr(back, key), getattr(table, key)), key
    assert back.joint_names == table.joint_names
    q = torch.rand(4, 6, dtype=torch.float64)
    assert torch.equal(back.tool_pose(q), table.tool_pose(q))
    data = json.loads(p.read_text())
    assert set(data) == {
        "convention",
        "joint_names",
        "a_m",
        "alpha_rad",
        "d_m",
        "theta_offset_rad",
        "T_base",
        "T_tool",
    }
    # optional transforms default to identity
    del data["T_base"], data["T_tool"], data["convention"]
    assert np.array_equal(MDHTable.from_dict(data).T_base, np.eye(4))


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("d_m"), "misses"),
        (lambda d: d.update(a_m=d["a_m"][:-1]), "entries"),
        (
            lambda d: d.update(T_base=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
            "rigid",
        ),
        (lambda d: d.update(T_tool=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]), "4x4"),
        (lambda d: d.update(convention="standard_dh"), "convention"),
        (lambda d: d.update(alpha_rad=["x"] * 6), "non-numeric"),
        (lambda d: d.update(theta_offset_rad=[float("nan")] * 6), "non-finite"),
        (lambda d: d.update(joint_names=["a"] * 6), "duplicates"),
    ],
)
def test_json_invalid_tables(tmp_path: Path, mutate, match: str) -> None:
    data = ur5_mdh().to_dict()
    mutate(data)
    p = tmp_path / "mdh.json"
    p.write_text(json.dumps(data))
    with pytest.raises(FormatError, match=match) as ei:
        load_mdh_json(p)
    assert ei.value.path == str(p)


def test_json_not_json(tmp_path: Path) -> None:
    p = tmp_path / "mdh.json"
    p.write_text("{not json")
    with pytest.raises(FormatError, match="JSON"):
        load_mdh_json(p)
    with pytest.raises(InputError):
        load_mdh_json(tmp_path / "absent.json")

"""Chain forward kinematics against yourdfpy's scene graph, closed forms and finite differences."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics import Chain
from robogs.format.urdf import load_urdf

from .conftest import REAL_URDFS

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def chain_of(tmp_path: Path, body: str, **kw) -> Chain:
    p = tmp_path / "r.urdf"
    p.write_text(f'<?xml version="1.0"?>\n<robot name="r">\n{body}\n</robot>\n')
    return Chain.from_urdf(load_urdf(p, load_meshes=False), **kw)


def joint(name: str, parent: str, child: str, jtype: str = "revolute", xyz: str = "0 0 0",
          rpy: str = "0 0 0", axis: str = "0 0 1", extra: str = "") -> str:  # fmt: skip
    return (
        f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
        f'<limit lower="-3" upper="3" effort="1" velocity="1"/>{extra}</joint>'
    )


def links(*names: str) -> str:
    return "".join(f'<link name="{n}"/>' for n in names)


# --------------------------------------------------------------------------- oracle: yourdfpy


@pytest.mark.realdata
@pytest.mark.parametrize("name", sorted(REAL_URDFS))
def test_forward_matches_yourdfpy_scene_graph(name: str, real_urdf_args) -> None:
    path, root, pkgs = real_urdf_args(name)
    urdf = load_urdf(path, root=root, package_roots=pkgs, load_meshes=False)
    chain = Chain.from_urdf(urdf)
    assert chain.joint_names == urdf.actuated_joint_names
    assert set(chain.link_names) == set(urdf.link_map)
    assert chain.link_names[0] == urdf.base_link
    rng = np.random.default_rng(11)
    lo = np.where(np.isfinite(chain.joint_lower), chain.joint_lower, -math.pi)
    hi = np.where(np.isfinite(chain.joint_upper), chain.joint_upper, math.pi)
    qs = rng.uniform(lo, hi, size=(25, chain.num_joints))
    T = chain.forward(torch.from_numpy(qs)).numpy()
    worst = 0.0
    for b, q in enumerate(qs):
        urdf.update_cfg(q)
        for k, link in enumerate(chain.link_names):
            ref = urdf.get_transform(link, chain.link_names[0])
            worst = max(worst, float(np.abs(ref - T[b, k]).max()))
    assert worst <= 1e-9


# --------------------------------------------------------------------------- closed forms


def test_planar_two_link_closed_form(tmp_path: Path) -> None:
    l1, l2, h = 0.4, 0.3, 0.1
    body = links("base", "l1", "l2", "ee") + joint("j1", "base", "l1", xyz=f"0 0 {h}")
    body += joint("j2", "l1", "l2", xyz=f"{l1} 0 0") + joint(
        "fix", "l2", "ee", "fixed", xyz=f"{l2} 0 0"
    )
    chain = chain_of(tmp_path, body)
    q = torch.tensor([[0.3, -1.1], [2.5, 0.7], [0.0, 0.0]], dtype=torch.float64)
    T = chain.forward(q)[:, chain.link_index("ee")]
    q1, q2 = q[:, 0], q[:, 1]
    expect = torch.stack(
        [
            l1 * torch.cos(q1) + l2 * torch.cos(q1 + q2),
            l1 * torch.sin(q1) + l2 * torch.sin(q1 + q2),
            torch.full_like(q1, h),
        ],
        dim=-1,
    )
    assert torch.abs(T[:, :3, 3] - expect).max() < 1e-15
    yaw = torch.atan2(T[:, 1, 0], T[:, 0, 0])
    assert (
        torch.abs(torch.remainder(yaw - (q1 + q2) + math.pi, 2 * math.pi) - math.pi).max() < 1e-14
    )


def test_prismatic_mimic_and_continuous(tmp_path: Path) -> None:
    body = links("base", "hand", "fl", "fr", "wheel", "flap")
    body += joint("turn", "base", "hand", "continuous", xyz="0 0 0.5", axis="0 0 2")
    body += joint("f1", "hand", "fl", "prismatic", xyz="0 0 0.1", axis="0 1 0")
    body += joint(
        "f2", "hand", "fr", "prismatic", xyz="0 0 0.1", axis="0 -1 0", extra='<mimic joint="f1"/>'
    )
    body += joint("w", "hand", "wheel", axis="1 0 0")
    body += joint(
        "m", "hand", "flap", axis="1 0 0", extra='<mimic joint="w" multiplier="-2" offset="0.1"/>'
    )
    chain = chain_of(tmp_path, body)
    assert chain.joint_names == ["turn", "f1", "w"]
    assert np.isinf(chain.joint_lower[0]) and chain.joint_lower[1] == -3
    q = torch.tensor([0.7, 0.02, 0.3], dtype=torch.float64)
    T = chain.forward(q)
    c, s = math.cos(0.7), math.sin(0.7)
    y_hand = np.array([-s, c, 0.0])
    fl = T[chain.link_index("fl")].numpy()
    fr = T[chain.link_index("fr")].numpy()
    assert np.abs(fl[:3, 3] - (np.array([0, 0, 0.6]) + 0.02 * y_hand)).max() < 1e-15
    assert np.abs(fr[:3, 3] - (np.array([0, 0, 0.6]) - 0.02 * y_hand)).max() < 1e-15
    flap = T[chain.link_index("flap")].numpy()
    hand = T[chain.link_index("hand")].numpy()
    rel = hand[:3, :3].T @ flap[:3, :3]
    angle = math.atan2(rel[2, 1], rel[1, 1])
    assert abs(angle - (-2 * 0.3 + 0.1)) < 1e-15


def test_joint_names_follow_urdf_order_not_tree_order(tmp_path: Path) -> None:
    body = links("a", "b", "c") + joint("jc", "b", "c") + joint("jb", "a", "b", xyz="1 0 0")
    chain = chain_of(tmp_path, body)
    assert chain.joint_names == ["jc", "jb"]
    assert chain.link_names == ["a", "b", "c"]
    T = chain.forward(torch.tensor([math.pi / 2, 0.0], dtype=torch.float64))
    # jc (the first q entry) turns c, not b
    assert torch.abs(T[1] - torch.eye(4, dtype=torch.float64) - _tx(1.0)).max() < 1e-15
    assert abs(float(T[2, 1, 0]) - 1.0) < 1e-15


def _tx(x: float) -> torch.Tensor:
    M = torch.zeros(4, 4, dtype=torch.float64)
    M[0, 3] = x
    return M


def test_unsupported_joints_and_bad_mimic(tmp_path: Path) -> None:
    body = (
        links("a", "b", "c")
        + joint("free", "a", "b", "floating", xyz="1 2 3")
        + joint("j", "b", "c")
    )
    with pytest.raises(FormatError, match="floating_as_fixed"):
        chain_of(tmp_path, body)
    chain = chain_of(tmp_path, body, floating_as_fixed=True)
    assert chain.joint_names == ["j"]
    T = chain.forward(torch.zeros(1, dtype=torch.float64))
    assert torch.equal(
        T[chain.link_index("b"), :3, 3], torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    )
    bad = (
        links("a", "b", "c")
        + joint("fx", "a", "b", "fixed")
        + joint("m", "b", "c", extra='<mimic joint="fx"/>')
    )
    with pytest.raises(FormatError, match="mimic"):
        chain_of(tmp_path, bad)
    zero_axis = links("a", "b") + joint("j", "a", "b", axis="0 0 0")
    with pytest.raises(FormatError, match="axis"):
        chain_of(tmp_path, zero_axis)


def test_bad_q_shapes(tmp_path: Path) -> None:
    chain = chain_of(tmp_path, links("a", "b") + joint("j", "a", "b"))
    with pytest.raises(InputError, match="expected"):
        chain.forward(torch.zeros(3, 2))
    with pytest.raises(InputError):
        chain.forward(torch.tensor(0.0))
    with pytest.raises(InputError, match="unknown link"):
        chain.link_index("nope")
    # integer and numpy inputs become float64
    assert chain.forward(np.array([1])).dtype == torch.float64


# --------------------------------------------------------------------------- batching, dtype, grads

UR5_BODY = (
    links("base_link", "shoulder", "upper", "fore", "w1", "w2", "w3", "tool0")
    + joint("pan", "base_link", "shoulder", xyz="0 0 0.089159")
    + joint(
        "lift", "shoulder", "upper", xyz="0 0.13585 0", rpy="0 1.5707963267948966 0", axis="0 1 0"
    )
    + joint("elbow", "upper", "fore", xyz="0 -0.1197 0.425", axis="0 1 0")
    + joint("wr1", "fore", "w1", xyz="0 0 0.39225", rpy="0 1.5707963267948966 0", axis="0 1 0")
    + joint("wr2", "w1", "w2", xyz="0 0.093 0")
    + joint("wr3", "w2", "w3", xyz="0 0 0.09465", axis="0 1 0")
    + joint("tool", "w3", "tool0", "fixed", xyz="0 0.0823 0", rpy="-1.5707963267948966 0 0")
)


@pytest.mark.parametrize("device", DEVICES)
def test_batched_shapes_dtypes_devices(tmp_path: Path, device: str) -> None:
    chain = chain_of(tmp_path, UR5_BODY)
    q = torch.rand(4, 5, 6, dtype=torch.float64, device=device) * 6 - 3
    T = chain.forward(q)
    assert T.shape == (4, 5, 8, 4, 4) and T.device.type == device
    loop = torch.stack([torch.stack([chain.forward(q[i, j]) for j in range(5)]) for i in range(4)])
    assert torch.abs(T - loop).max() < 1e-15
    T32 = chain.forward(q.float())
    assert T32.dtype == torch.float32
    assert torch.abs(T32.double() - T).max() < 5e-6
    assert torch.equal(
        T[..., 3, :],
        torch.tensor([0, 0, 0, 1.0], dtype=torch.float64, device=device).expand(4, 5, 8, 4),
    )


def test_jacobian_autograd_matches_finite_differences(tmp_path: Path) -> None:
    chain = chain_of(tmp_path, UR5_BODY)
    tool = chain.link_index("tool0")

    def f(q: torch.Tensor) -> torch.Tensor:
        T = chain.forward(q)[tool]
        return torch.cat([T[:3, 3], T[:3, :3].reshape(-1)])

    rng = np.random.default_rng(3)
    for _ in range(3):
        q = torch.tensor(rng.uniform(-3, 3, 6), dtype=torch.float64)
        J = torch.autograd.functional.jacobian(f, q)
        h = 1e-6
        J_fd = torch.stack(
            [(f(q + h * e) - f(q - h * e)) / (2 * h) for e in torch.eye(6, dtype=torch.float64)],
            dim=1,
        )
        assert torch.abs(J - J_fd).max() < 1e-8
    assert torch.autograd.gradcheck(
        lambda q: chain.forward(q)[..., tool, :3, 3],
        (torch.rand(2, 6, dtype=torch.float64, requires_grad=True),),
    )

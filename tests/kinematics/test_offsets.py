"""Fitted joint offsets baked into a Chain, against the independent numpy forward kinematics of
:mod:`robogs.synth.armlogs.kinematic` (its own URDF parser and perpendicular), and mimics against
the nominal chain fed shifted joint values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from robogs.format.errors import FormatError
from robogs.format.kinematics import (
    Chain,
    JointOffsets,
    chain_with_offsets,
    offset_origin,
    read_joint_offsets,
)
from robogs.format.urdf import load_urdf
from robogs.synth.armlogs import ur5_urdf
from robogs.synth.armlogs.dynamics import parse_arm
from robogs.synth.armlogs.kinematic import urdf_fk

_LINK = '<link name="{}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'


def _joint(name, parent, child, jtype, xyz, rpy, axis, extra=""):
    return (
        f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="{axis}"/>'
        f'<limit lower="-3" upper="3" effort="1" velocity="1"/>{extra}</joint>'
    )


def _write(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "r.urdf"
    p.write_text(f'<?xml version="1.0"?>\n<robot name="r">\n{body}\n</robot>\n')
    return p


def _offsets(rng, names) -> dict[str, JointOffsets]:
    return {j: JointOffsets(rng.uniform(-0.05, 0.05), *rng.uniform(-0.02, 0.02, 2)) for j in names}


def _against_fixture(urdf: Path, link: str, seed: int) -> float:
    chain = Chain.from_urdf(load_urdf(urdf, load_meshes=False))
    rng = np.random.default_rng(seed)
    off = _offsets(rng, chain.joint_names)
    q = rng.uniform(-2.5, 2.5, (40, chain.num_joints))
    T = chain_with_offsets(chain, off).forward(torch.as_tensor(q))[:, chain.link_index(link)]
    dth, dd, da = (
        np.array([getattr(off[j], k) for j in chain.joint_names]) for k in ("dtheta", "dd", "da")
    )
    arm = parse_arm(urdf)
    assert list(arm.actuated) == chain.joint_names
    p_ref, r_ref = urdf_fk(arm, q + dth, link, da=da, dd=dd)
    np.testing.assert_allclose(T[:, :3, 3].numpy(), p_ref, atol=1e-12)
    np.testing.assert_allclose(T[:, :3, :3].numpy(), r_ref, atol=1e-12)
    T0 = chain.forward(torch.as_tensor(q))[:, chain.link_index(link)]
    return float(np.abs(T0[:, :3, 3].numpy() - p_ref).max())


def test_ur5_offsets_match_the_independent_fixture_fk(tmp_path: Path) -> None:
    p = tmp_path / "ur5.urdf"
    p.write_text(ur5_urdf())
    assert _against_fixture(p, "tool0", 0) > 0.01  # the offsets do move the tool


def test_tilted_x_axis_and_prismatic_joints_match_the_fixture_fk(tmp_path: Path) -> None:
    """Axis along x (perpendicular = y), a tilted axis, a prismatic joint (dtheta in m) and
    rotated origins."""
    body = "".join(_LINK.format(n) for n in ("base", "a", "b", "c", "d", "tool"))
    body += _joint("j1", "base", "a", "revolute", "0.1 0 0.2", "0.3 -0.2 0.1", "1 0 0")
    body += _joint("j2", "a", "b", "continuous", "0 0.2 0.1", "0 0.5 0", "0.3 -0.5 0.8")
    body += _joint("j3", "b", "c", "prismatic", "0.05 0 0.3", "0.2 0 -0.4", "0 1 1")
    body += _joint("j4", "c", "d", "revolute", "0 0 0.1", "0 0 0", "0 0 -1")
    body += _joint("jt", "d", "tool", "fixed", "0.01 0.02 0.1", "0.1 0.2 0.3", "1 0 0")
    assert _against_fixture(_write(tmp_path, body), "tool", 1) > 0.01


def test_mimic_joints_follow_their_source_link_angle(tmp_path: Path) -> None:
    """dtheta of a joint with mimics equals feeding q + dtheta to the nominal chain (which
    applies multiplier and offset); dd and da do not move the mimic's frame."""
    body = "".join(_LINK.format(n) for n in ("base", "a", "b", "c"))
    body += _joint("w", "base", "a", "revolute", "0 0 0.1", "0 0 0", "0 0 1")
    body += _joint("m", "a", "b", "revolute", "0.1 0 0", "0 0.3 0", "1 0 0",
                   '<mimic joint="w" multiplier="-2" offset="0.1"/>')  # fmt: skip
    body += _joint("s", "b", "c", "prismatic", "0 0 0.2", "0 0 0", "0 1 0",
                   '<mimic joint="w" multiplier="0.5"/>')  # fmt: skip
    chain = Chain.from_urdf(load_urdf(_write(tmp_path, body), load_meshes=False))
    assert chain.joint_names == ["w"]
    q = torch.linspace(-2, 2, 9, dtype=torch.float64)[:, None]
    got = chain_with_offsets(chain, {"w": JointOffsets(dtheta=0.03)}).forward(q)
    np.testing.assert_allclose(got.numpy(), chain.forward(q + 0.03).numpy(), atol=1e-14)
    # dd/da of "w" translate only w's own frame: the mimics' origins are unchanged
    moved = chain_with_offsets(chain, {"w": JointOffsets(dd=0.01, da=0.02)})
    np.testing.assert_array_equal(moved.origins[1:], chain.origins[1:])
    np.testing.assert_allclose(moved.origins[0][:3, 3], chain.origins[0][:3, 3] + [0.02, 0, 0.01])


def test_offset_origin_is_a_constant_change_of_the_motion() -> None:
    """origin' . Rot(z, q) = origin . Trans(da u + dd z) . Rot(z, q + dtheta), brute force."""
    rng = np.random.default_rng(5)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    origin = np.eye(4)
    origin[:3, 3] = rng.normal(size=3)
    new = offset_origin(origin, axis, "revolute", dtheta=0.2, dd=0.01, da=-0.03)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])

    def rot(a):
        T = np.eye(4)
        T[:3, :3] = np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k
        return T

    u = np.array([1.0, 0, 0]) - axis[0] * axis
    u /= np.linalg.norm(u)
    shift = np.eye(4)
    shift[:3, 3] = -0.03 * u + 0.01 * axis
    for q in (-1.0, 0.3, 2.0):
        np.testing.assert_allclose(new @ rot(q), origin @ shift @ rot(q + 0.2), atol=1e-14)
    with pytest.raises(FormatError):
        offset_origin(origin, axis, "fixed", dd=0.1)


def test_read_joint_offsets_keeps_known_nonzero_joints_and_rejects_nan() -> None:
    doc = {
        "joints": {
            "a": {"offsets": {"dtheta_rad": 0.01, "da_m": -0.002}},
            "b": {"offsets": {"dtheta_rad": 0.0}},
            "c": {"damping": 1.0},
            "ghost": {"offsets": {"dd_m": 0.1}},
        }
    }
    assert read_joint_offsets(doc, ["a", "b", "c"]) == {"a": JointOffsets(0.01, 0.0, -0.002)}
    assert read_joint_offsets(None, ["a"]) == {}
    bad = {"joints": {"a": {"offsets": {"dd_m": float("nan")}}}}
    with pytest.raises(FormatError) as exc:
        read_joint_offsets(bad, ["a"], path="physics.json")
    assert "joints.a.offsets.dd_m" in str(exc.value) and "physics.json" in str(exc.value)

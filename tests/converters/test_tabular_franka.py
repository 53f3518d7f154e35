"""A Franka log converts with no map: joints from ``q_i``/``dq_i``/``tau_J_i`` and end-effector
poses from libfranka's column-major ``O_T_EE_0..15`` (issue 18 item 6).

Oracles: the 4x4 matrices are built here from poses given as scipy ``Rotation`` objects
(positions from the independent numpy forward kinematics of
:func:`robogs.synth.armlogs.kinematic.urdf_fk`, or hand-picked rotations whose quaternion is
known in closed form), written column by column with ``repr``; the expected quaternion is
scipy's, reordered to (w, x, y, z).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.synth.armlogs.dynamics import parse_arm
from robogs.synth.armlogs.kinematic import urdf_fk

PI = math.pi
# Franka Panda kinematics (franka_description panda_arm.xacro): xyz, rpy, lower, upper
PANDA = (
    ((0, 0, 0.333), (0, 0, 0), -2.8973, 2.8973),
    ((0, 0, 0), (-PI / 2, 0, 0), -1.7628, 1.7628),
    ((0, -0.316, 0), (PI / 2, 0, 0), -2.8973, 2.8973),
    ((0.0825, 0, 0), (PI / 2, 0, 0), -3.0718, -0.0698),
    ((-0.0825, 0.384, 0), (-PI / 2, 0, 0), -2.8973, 2.8973),
    ((0, 0, 0), (PI / 2, 0, 0), -0.0175, 3.7525),
    ((0.088, 0, 0), (PI / 2, 0, 0), -2.8973, 2.8973),
)
Q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])


def _link(name: str) -> str:
    return (
        f'<link name="{name}"><inertial><mass value="1"/><origin xyz="0 0 0.02"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
    )


def _fixed(name: str, parent: str, child: str, xyz: str = "0 0 0", rpy: str = "0 0 0") -> str:
    return (
        f'<joint name="{name}" type="fixed"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="{xyz}" rpy="{rpy}"/></joint>'
    )


def _panda_urdf(path: Path, *, hand: bool = True, tcp: bool = True) -> Path:
    parts = ['<robot name="panda">', _link("panda_link0")]
    for i, (xyz, rpy, lo, hi) in enumerate(PANDA):
        parts.append(
            f'<joint name="panda_joint{i + 1}" type="revolute"><parent link="panda_link{i}"/>'
            f'<child link="panda_link{i + 1}"/><origin xyz="{" ".join(map(repr, xyz))}" '
            f'rpy="{" ".join(map(repr, rpy))}"/><axis xyz="0 0 1"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="87" velocity="2.1"/></joint>'
        )
        parts.append(_link(f"panda_link{i + 1}"))
    parts += [
        _fixed("panda_joint8", "panda_link7", "panda_link8", "0 0 0.107"),
        _link("panda_link8"),
    ]
    if hand:
        parts += [
            _fixed("panda_hand_joint", "panda_link8", "panda_hand", rpy=f"0 0 {-PI / 4!r}"),
            _link("panda_hand"),
        ]
        if tcp:
            parts += [
                _fixed("panda_hand_tcp_joint", "panda_hand", "panda_hand_tcp", "0 0 0.1034"),
                _link("panda_hand_tcp"),
            ]
    path.write_text("".join(parts) + "</robot>")
    return path


def _wxyz(rot: Rotation) -> np.ndarray:
    """scipy's (x, y, z, w) as (w, x, y, z) with w >= 0 (the dataset's convention)."""
    q = rot.as_quat()[:, [3, 0, 1, 2]]
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


def _o_t_ee(p: np.ndarray, rot: Rotation, *, column_major: bool = True) -> np.ndarray:
    """[N, 16] libfranka O_T_EE: the 4x4 of each pose, column by column (row by row if not)."""
    M = np.tile(np.eye(4), (len(p), 1, 1))
    M[:, :3, :3] = rot.as_matrix()
    M[:, :3, 3] = p
    return (M.transpose(0, 2, 1) if column_major else M).reshape(len(p), 16)


def _franka_csv(path: Path, t: np.ndarray, q, dq, tau, ee: np.ndarray) -> None:
    header = ["time"] + [f"{k}_{i}" for k in ("q", "dq", "tau_J") for i in range(7)]
    header += [f"O_T_EE_{k}" for k in range(16)]
    lines = [",".join(header)]
    for k in range(len(t)):
        vals = [*q[k], *dq[k], *tau[k], *ee[k]]
        lines.append(f"{t[k]:.3f}," + ",".join(repr(float(v)) for v in vals))
    path.write_text("\n".join(lines) + "\n")


def _motion(n: int):
    t = np.arange(n) * 0.001  # 1 kHz, libfranka's control rate
    w = 2 * PI * 0.5
    amp = 0.2 * np.linspace(0.5, 1.0, 7)
    q = Q0 + amp * np.sin(w * t[:, None] + np.arange(7))
    dq = amp * w * np.cos(w * t[:, None] + np.arange(7))
    tau = np.stack([np.sin(t + i) for i in range(7)], 1)
    return t, q, dq, tau


def test_franka_log_with_o_t_ee_converts_without_a_map(tmp_path: Path) -> None:
    urdf = _panda_urdf(tmp_path / "panda.urdf")
    t, q, dq, tau = _motion(400)
    p, R = urdf_fk(parse_arm(urdf), q, "panda_hand_tcp")
    rot = Rotation.from_matrix(R)
    _franka_csv(tmp_path / "franka.csv", t, q, dq, tau, _o_t_ee(p, rot))

    ds = convert_path(tmp_path / "franka.csv", tmp_path / "out", options=ConvertOptions(urdf=urdf))

    js = ds.episode().table("joint_states")
    np.testing.assert_array_equal(js.column("t_ns").to_numpy(), np.arange(400) * 1_000_000)
    for i in range(7):
        np.testing.assert_array_equal(js.column(f"position.panda_joint{i + 1}").to_numpy(), q[:, i])
        np.testing.assert_array_equal(
            js.column(f"velocity.panda_joint{i + 1}").to_numpy(), dq[:, i]
        )
        np.testing.assert_array_equal(js.column(f"effort.panda_joint{i + 1}").to_numpy(), tau[:, i])
    ee = ds.episode().table("ee_poses")
    assert set(ee.column("link").to_pylist()) == {"panda_hand_tcp"}
    np.testing.assert_array_equal(ee.column("t_ns").to_numpy(), js.column("t_ns").to_numpy())
    xyz = np.stack([ee.column(c).to_numpy() for c in ("x", "y", "z")], 1)
    np.testing.assert_allclose(xyz, p, rtol=0, atol=1e-9)
    wxyz = np.stack([ee.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], 1)
    np.testing.assert_allclose(wxyz, _wxyz(rot), rtol=0, atol=1e-9)
    assert ds.manifest["robot"]["ee_link"] == "panda_hand_tcp"
    prov = ds.manifest["provenance"]
    m = prov["mapping"]["franka.csv"]
    assert m["layout"] == "franka" and m["time"]["unit"] == "s"
    assert m["ee_pose"] == {
        "link": "panda_hand_tcp",
        "format": "matrix_colmajor",
        "columns": [f"O_T_EE_{k}" for k in range(16)],
        "unit": "m",
    }
    assert any("libfranka O_T_EE" in n and "'panda_hand_tcp'" in n for n in prov["notes"])
    assert prov["topics"]["franka.csv#ee_pose"]["written"] == 400


def test_quaternion_order_of_known_rotations_and_the_flange_without_a_hand(tmp_path: Path) -> None:
    urdf = _panda_urdf(tmp_path / "arm.urdf", hand=False)
    t, q, dq, tau = _motion(20)
    # closed form: a turn of a about unit axis u is (cos a/2, sin a/2 u) in (w, x, y, z)
    c, s = math.cos(PI / 4), math.sin(PI / 4)
    known = {
        0: ((1.0, 0.0, 0.0, 0.0), Rotation.identity()),
        1: ((c, s, 0.0, 0.0), Rotation.from_euler("x", 90, degrees=True)),
        2: ((c, 0.0, s, 0.0), Rotation.from_euler("y", 90, degrees=True)),
        3: ((c, 0.0, 0.0, s), Rotation.from_euler("z", 90, degrees=True)),
        4: ((0.0, 1.0, 0.0, 0.0), Rotation.from_euler("x", 180, degrees=True)),
    }
    rots = [known[k % 5][1] for k in range(20)]
    rot = Rotation.concatenate(rots)
    p = np.stack([0.3 + 0.01 * np.arange(20), -0.2 * np.ones(20), 0.5 * np.ones(20)], 1)
    _franka_csv(tmp_path / "f.csv", t, q, dq, tau, _o_t_ee(p, rot))

    ds = convert_path(tmp_path / "f.csv", tmp_path / "out", options=ConvertOptions(urdf=urdf))

    ee = ds.episode().table("ee_poses")
    assert set(ee.column("link").to_pylist()) == {"panda_link8"}  # no hand: the flange
    wxyz = np.stack([ee.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], 1)
    expected = np.array([known[k % 5][0] for k in range(20)])
    np.testing.assert_allclose(wxyz, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(
        np.stack([ee.column(c).to_numpy() for c in ("x", "y", "z")], 1), p, rtol=0, atol=1e-12
    )
    assert any("flange" in n for n in ds.manifest["provenance"]["notes"])


def test_row_major_matrices_are_refused_with_the_right_format_named(tmp_path: Path) -> None:
    urdf = _panda_urdf(tmp_path / "panda.urdf")
    t, q, dq, tau = _motion(30)
    p, R = urdf_fk(parse_arm(urdf), q, "panda_hand_tcp")
    _franka_csv(
        tmp_path / "f.csv", t, q, dq, tau, _o_t_ee(p, Rotation.from_matrix(R), column_major=False)
    )
    with pytest.raises(InputError, match="not a rigid transform") as exc:
        convert_path(tmp_path / "f.csv", tmp_path / "out", options=ConvertOptions(urdf=urdf))
    assert "matrix_rowmajor" in (exc.value.hint or "") and "line 2" in (exc.value.where or "")
    assert not (tmp_path / "out").exists()


def test_a_hand_without_a_tcp_link_is_not_guessed(tmp_path: Path) -> None:
    urdf = _panda_urdf(tmp_path / "panda.urdf", tcp=False)
    t, q, dq, tau = _motion(30)
    p, R = urdf_fk(parse_arm(urdf), q, "panda_hand")
    _franka_csv(tmp_path / "f.csv", t, q, dq, tau, _o_t_ee(p, Rotation.from_matrix(R)))
    ds = convert_path(tmp_path / "f.csv", tmp_path / "out", options=ConvertOptions(urdf=urdf))
    assert "ee_poses" not in ds.episode().streams
    assert "ee_link" not in ds.manifest["robot"]
    assert any("O_T_EE* ignored" in n for n in ds.manifest["provenance"]["notes"])


def test_a_map_ee_pose_overrides_the_guess(tmp_path: Path) -> None:
    urdf = _panda_urdf(tmp_path / "panda.urdf")
    t, q, dq, tau = _motion(30)
    p, R = urdf_fk(parse_arm(urdf), q, "panda_link8")
    _franka_csv(tmp_path / "f.csv", t, q, dq, tau, _o_t_ee(p, Rotation.from_matrix(R)))
    (tmp_path / "map.yaml").write_text("ee_pose: {link: panda_link8, format: matrix_colmajor}\n")
    opts = ConvertOptions(urdf=urdf, mapping=tmp_path / "map.yaml")
    ds = convert_path(tmp_path / "f.csv", tmp_path / "out", options=opts)
    ee = ds.episode().table("ee_poses")
    assert set(ee.column("link").to_pylist()) == {"panda_link8"}
    np.testing.assert_allclose(
        np.stack([ee.column(c).to_numpy() for c in ("x", "y", "z")], 1), p, rtol=0, atol=1e-9
    )
    assert not any("link guessed" in n for n in ds.manifest["provenance"]["notes"])
    assert Dataset.open(tmp_path / "out").manifest["robot"]["ee_link"] == "panda_link8"


def test_the_guessed_link_is_checked_against_fk(tmp_path: Path) -> None:
    """The guess is only as good as the robot's configuration: a log of flange poses (no hand
    configured) against a URDF with a hand TCP is caught by G008 (FK vs recorded pose), off by
    the TCP's 103.4 mm; the right link validates clean."""
    from robogs.format.validate import validate

    urdf = _panda_urdf(tmp_path / "panda.urdf")
    t, q, dq, tau = _motion(300)
    arm = parse_arm(urdf)
    for link, out in (("panda_hand_tcp", "good"), ("panda_link8", "bad")):
        p, R = urdf_fk(arm, q, link)
        _franka_csv(tmp_path / f"{out}.csv", t, q, dq, tau, _o_t_ee(p, Rotation.from_matrix(R)))
        convert_path(tmp_path / f"{out}.csv", tmp_path / out, options=ConvertOptions(urdf=urdf))
    assert validate(tmp_path / "good", select=["G008"]).findings == []
    bad = validate(tmp_path / "bad", select=["G008"]).findings
    assert [f.severity for f in bad] == ["error"]
    assert bad[0].value == pytest.approx(103.4, abs=0.5)  # mm: the hand's TCP offset

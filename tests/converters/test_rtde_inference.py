"""UR RTDE ``actual_TCP_pose_0..5`` read with no map: ``x y z`` (m) and a rotation vector (rad)
of ``tool0`` in UR's ``base`` frame (``base_link`` turned by pi about z), stored in the world as
``x y z`` and ``qw qx qy qz``.

The logs are generated here and share no code with the converter: the joint path and ``tool0``
come from the synthetic arm's own numpy forward kinematics (:mod:`robogs.synth.armlogs`), the
rotation vectors from ``scipy.spatial.transform``, and ``T_base_baselink = RotZ(pi)`` is written
out by hand.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.dataset import Dataset
from robogs.format.validate import validate
from robogs.synth.armlogs import ur5_urdf
from robogs.synth.armlogs.dynamics import parse_arm
from robogs.synth.armlogs.generate import excitation
from robogs.synth.armlogs.kinematic import urdf_fk

BASE = (
    '<joint name="base_link-base_fixed_joint" type="fixed"><parent link="base_link"/>'
    '<child link="base"/><origin xyz="0 0 0" rpy="0 0 3.141592653589793"/></joint>'
    '<link name="base"/>'
)
#: rotation of ``base`` in ``base_link`` (and back): RotZ(pi)
RZ = np.diag([-1.0, -1.0, 1.0])


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _urdf(tmp: Path, with_base: bool) -> Path:
    p = tmp / ("ur5_base.urdf" if with_base else "ur5.urdf")
    p.write_text(ur5_urdf().replace("</robot>", (BASE if with_base else "") + "\n</robot>"))
    return p


def _convert(log: Path, out: Path, urdf: Path) -> Path:
    convert_path(log, out, options=ConvertOptions(urdf=urdf))
    return out


def _rtde_log(path: Path, urdf: Path, seed: int, in_base: bool, n: int = 250):
    """An RTDE CSV (timestamp s, actual_q/qd, actual_TCP_pose) and the oracle: ``tool0`` in the
    world (base_link), positions [N, 3] m and quaternions [N, 4] (w, x, y, z, w >= 0)."""
    arm = parse_arm(urdf)
    t = np.arange(n) / 125.0
    q, qd, _ = excitation(arm, np.random.default_rng(seed))(t)
    p, R = urdf_fk(arm, q, "tool0")
    Rb = RZ if in_base else np.eye(3)
    rotvec = Rotation.from_matrix(Rb @ R).as_rotvec()
    header = ["timestamp", *(f"actual_q_{i}" for i in range(6))]
    header += [*(f"actual_qd_{i}" for i in range(6)), *(f"actual_TCP_pose_{i}" for i in range(6))]
    rows = np.concatenate([t[:, None] + 5000.0, q, qd, p @ Rb.T, rotvec], axis=1)
    lines = [",".join(header)] + [",".join(repr(float(v)) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    quat = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    return p, quat * np.where(quat[:, :1] < 0, -1.0, 1.0)


@pytest.mark.parametrize("with_base", [True, False])
def test_rtde_tcp_pose_converts_with_no_map(tmp_path: Path, with_base: bool) -> None:
    urdf = _urdf(tmp_path, with_base)
    log = tmp_path / "rtde.csv"
    p, quat = _rtde_log(log, urdf, seed=3, in_base=with_base)
    ds = _convert(log, tmp_path / "ds", urdf)
    d = Dataset.open(ds)
    ee = d.episodes[0].table("ee_poses")
    assert set(ee.column("link").to_pylist()) == {"tool0"} and ee.num_rows == len(p)
    got_p = np.stack([ee.column(c).to_numpy() for c in "xyz"], 1)
    got_q = np.stack([ee.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], 1)
    assert np.abs(got_p - p).max() < 1e-9
    assert np.abs(got_q - quat).max() < 1e-9
    notes = " ".join(d.manifest["provenance"]["notes"])
    assert "UR RTDE TCP pose" in notes
    assert ("link 'base'" in notes) is with_base
    # the joints and the poses agree through forward kinematics (G008 with a zero budget)
    (f,) = validate(ds, select=["G008"], budgets={"geometry.fk_ee_mm": 0.0}).findings
    assert f.value < 1e-6  # mm


def test_rtde_pose_read_in_the_wrong_frame_is_caught(tmp_path: Path) -> None:
    """Mutation: a log written in base_link but converted against a URDF with ``base`` is read
    turned by pi: G008 sees the TCP off by twice its distance from the z axis."""
    urdf = _urdf(tmp_path, True)
    log = tmp_path / "rtde.csv"
    p, _ = _rtde_log(log, urdf, seed=4, in_base=False)
    ds = _convert(log, tmp_path / "ds", urdf)
    (f,) = [x for x in validate(ds, select=["G008"]).findings if x.code == "G008"]
    want_mm = 2e3 * np.linalg.norm(p[:, :2], axis=1).max()
    assert f.severity == "error" and f.value == pytest.approx(want_mm, rel=1e-6)


def test_rtde_needs_all_six_columns(tmp_path: Path) -> None:
    urdf = _urdf(tmp_path, True)
    log = tmp_path / "rtde.csv"
    _rtde_log(log, urdf, seed=5, in_base=True)
    text = log.read_text().splitlines()
    cut = [",".join(line.split(",")[:-1]) for line in text]  # drop actual_TCP_pose_5
    log.write_text("\n".join(cut) + "\n")
    d = Dataset.open(_convert(log, tmp_path / "ds", urdf))
    assert "ee_poses" not in d.episodes[0].streams
    assert any("actual_TCP_pose* ignored" in n for n in d.manifest["provenance"]["notes"])

"""Tabular import of recorded TCP poses (map section ``ee_pose``): UR RTDE axis-angle poses in
the UR ``base`` frame and Franka column-major ``O_T_EE`` matrices become an ``ee_poses``
stream; the kinematic model diagnoses hidden joint offsets from the plain CSV; malformed
values give clear errors.

Oracles: the CSVs are written here from the independent numpy forward kinematics of
:func:`robogs.synth.armlogs.kinematic.urdf_fk`, rotations converted by ``scipy.spatial.transform``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.ingest.tabular import TabularOptions
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.format.validate import validate
from robogs.synth.armlogs import UR5_JOINTS, ur5_urdf
from robogs.synth.armlogs.dynamics import parse_arm
from robogs.synth.armlogs.generate import excitation
from robogs.synth.armlogs.kinematic import urdf_fk

RZ_PI = 3.141592653589793
BASE = (
    '<joint name="base_link-base_fixed_joint" type="fixed"><parent link="base_link"/>'
    f'<child link="base"/><origin xyz="0 0 0" rpy="0 0 {RZ_PI!r}"/></joint><link name="base"/>'
)
"""The UR convention: RTDE poses are in ``base``, turned by pi about z from ``base_link``."""


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def ur5(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("robot") / "ur5.urdf"
    p.write_text(ur5_urdf().replace("</robot>", BASE + "\n</robot>"))
    return p


def _write_csv(path: Path, header: list[str], rows: np.ndarray, text: dict | None = None) -> None:
    """Rows of floats written with repr (exact); ``text`` overrides cells {(row, col): str}."""
    lines = [",".join(header)]
    for i, r in enumerate(rows):
        cells = [repr(float(v)) for v in r]
        for (ri, ci), s in (text or {}).items():
            if ri == i:
                cells[ci] = s
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")


def _trajectory(ur5: Path, seed: int, n: int = 300, rate: float = 125.0):
    arm = parse_arm(ur5)
    t = np.arange(n) / rate
    q, qd, _ = excitation(arm, np.random.default_rng(seed))(t)
    return arm, t, q, qd


def _rtde_csv(path, ur5, seed, *, dtheta=None, da=None, dd=None, noise=(0.0, 0.0), text=None):
    """An RTDE-style log: joints, and actual_TCP_pose (m, rotation vector) of tool0 in ``base``;
    ``noise``: (mm, deg) per axis on the pose."""
    arm, t, q, qd = _trajectory(ur5, seed)
    theta = q + (0.0 if dtheta is None else np.asarray(dtheta))
    p, R = urdf_fk(arm, theta, "tool0", da=da, dd=dd)
    rng = np.random.default_rng(seed + 100)
    p = p + rng.normal(0, noise[0] * 1e-3, p.shape)
    R = Rotation.from_rotvec(rng.normal(0, np.radians(noise[1]), p.shape)).as_matrix() @ R
    rz = np.diag([-1.0, -1.0, 1.0])  # T_base_baselink = RotZ(pi)
    rotvec = Rotation.from_matrix(rz @ R).as_rotvec()
    header = ["timestamp"] + [f"actual_q_{i}" for i in range(6)]
    header += [f"actual_qd_{i}" for i in range(6)] + [f"actual_TCP_pose_{i}" for i in range(6)]
    rows = np.concatenate([t[:, None] + 1000.0, q, qd, p @ rz.T, rotvec], axis=1)
    _write_csv(path, header, rows, text)
    return p, R


def _map(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _convert(log: Path, out: Path, urdf: Path, mapping: Path) -> Path:
    """The one driver (``convert_path``) on a tabular log with a column map; the dataset folder."""
    opts = ConvertOptions(urdf=urdf, source=TabularOptions(mapping=mapping))
    return convert_path(log, out, fmt="tabular", options=opts).root


def _ee(ds: Path, episode: str | None = None):
    d = Dataset.open(ds)
    ep = d.episodes[0] if episode is None else next(e for e in d.episodes if e.id == episode)
    return d, ep.table("ee_poses")


def test_rtde_axis_angle_poses_in_the_base_frame(tmp_path, ur5):
    log = tmp_path / "rtde.csv"
    p, R = _rtde_csv(log, ur5, seed=1)
    m = _map(tmp_path / "map.yaml", "ee_pose: {link: tool0, format: axis_angle, frame: base}\n")
    ds = _convert(log, tmp_path / "ds", ur5, mapping=m)
    d, ee = _ee(ds)
    assert d.manifest["robot"]["ee_link"] == "tool0"
    assert set(ee.column("link").to_pylist()) == {"tool0"}
    pos = np.stack([ee.column(c).to_numpy() for c in "xyz"], 1)
    quat = np.stack([ee.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], 1)
    np.testing.assert_allclose(pos, p, atol=1e-12)  # back in base_link (the world)
    ref = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    ref *= np.where(ref[:, :1] < 0, -1.0, 1.0)
    np.testing.assert_allclose(quat, ref, atol=1e-12)
    assert (quat[:, 0] >= 0).all()
    # the joint log and the poses agree through forward kinematics (G008, 0 mm budget)
    (f,) = [x for x in validate(ds, select=["G008"], budgets={"geometry.fk_ee_mm": 0.0}).findings]
    assert f.value < 1e-6  # mm
    assert not [x for x in validate(ds).findings if x.severity == "error"]
    prov = d.manifest["provenance"]
    assert prov["mapping"]["rtde.csv"]["ee_pose"]["frame"] == "base"


def test_franka_column_major_matrix_and_a_bad_cell(tmp_path, ur5):
    arm, t, q, _ = _trajectory(ur5, seed=2, n=200)
    p, R = urdf_fk(arm, q, "wrist_3_link")
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, p * 1000.0  # position in mm
    col_major = T.transpose(0, 2, 1).reshape(len(t), 16)
    header = ["time"] + [f"q{i}" for i in range(6)] + [f"O_T_EE[{i}]" for i in range(16)]
    log = tmp_path / "franka.csv"
    _write_csv(log, header, np.concatenate([t[:, None], q, col_major], 1), {(7, 10): "nan"})
    m = _map(
        tmp_path / "map.yaml",
        "ee_pose:\n  link: wrist_3_link\n  format: matrix_colmajor\n"
        "  columns: 'O_T_EE[{i}]'\n  unit: mm\n",
    )
    ds = _convert(log, tmp_path / "ds", ur5, mapping=m)
    d, ee = _ee(ds)
    js = d.episodes[0].table("joint_states")
    assert js.num_rows == 200 and ee.num_rows == 199  # the bad pose cell drops the pose only
    keep = np.arange(200) != 7
    pos = np.stack([ee.column(c).to_numpy() for c in "xyz"], 1)
    np.testing.assert_allclose(pos, p[keep], atol=1e-12)
    assert ee.column("t_ns").to_numpy()[7] == js.column("t_ns").to_numpy()[8]
    prov = d.manifest["provenance"]
    assert prov["topics"]["franka.csv#ee_pose"]["dropped"] == {
        "empty, NaN or unparseable pose value": 1
    }
    assert any("line 9" in n and "joint rows are kept" in n for n in prov["notes"])


def test_hidden_offsets_are_diagnosed_from_a_plain_csv(tmp_path, ur5):
    from robogs.physics.arm import diagnose_arm

    logs = tmp_path / "logs"
    logs.mkdir()
    dth = [2e-3, -1.5e-3, 2.5e-3, -2e-3, 1.5e-3, 1e-3]
    da = [1e-3, -1e-3, 1.5e-3, -1e-3, 1e-3, 0.5e-3]
    for s in range(3):
        _rtde_csv(logs / f"run{s}.csv", ur5, seed=10 + s, dtheta=dth, da=da, noise=(0.2, 0.05))
    m = _map(tmp_path / "map.yaml", "ee_pose: {link: tool0, frame: base}\n")
    ds = _convert(logs, tmp_path / "ds", ur5, mapping=m)
    assert "G008" in validate(ds, select=["G008"]).codes()
    rep = diagnose_arm(ds, candidates=["kinematic_offsets", "backlash", "joint_elasticity"])
    assert rep["selected"] == ["kinematic_offsets"], [
        (e["name"], e["delta_bic"]) for e in rep["effects"]
    ]
    p = rep["effects"][0]["params"]
    for i, j in enumerate(UR5_JOINTS):  # 900 poses, 0.2 mm and 0.05 deg noise: measured
        assert abs(p[f"dtheta.{j}"]["value"] - dth[i]) < 2e-4, (j, p[f"dtheta.{j}"])  # < 7e-5
        assert abs(p[f"da.{j}"]["value"] - da[i]) < 1.5e-4, (j, p[f"da.{j}"])  # < 6e-5


@pytest.mark.parametrize(
    ("map_text", "where", "words"),
    [
        ("ee_pose: {format: axis_angle}", "ee_pose/link", "needs the URDF link"),
        ("ee_pose: {link: tool0, format: euler}", "ee_pose/format", "unknown ee_pose format"),
        ("ee_pose: {link: tool0, columns: [a, b, c]}", "ee_pose/columns", "needs 6 distinct"),
        ("ee_pose: {link: tool0, unit: cm}", "ee_pose/unit", "unknown ee_pose position unit"),
        ("ee_pose: {link: tool0, format: quaternion}", "ee_pose/columns", "no default column"),
        ("ee_pose: {link: flange}", "ee_pose/link", "not a link of the URDF"),
        ("ee_pose: {link: tool0, frame: upper_arm_link}", "ee_pose/frame", "moves with joint"),
        ("ee_pose: [tool0]", "ee_pose", "must be a mapping"),
    ],
)
def test_malformed_ee_pose_maps(tmp_path, ur5, map_text, where, words):
    log = tmp_path / "rtde.csv"
    _rtde_csv(log, ur5, seed=3)
    m = _map(tmp_path / "map.yaml", map_text + "\n")
    with pytest.raises(InputError) as exc:
        _convert(log, tmp_path / "ds", ur5, mapping=m)
    assert exc.value.where == where and words in exc.value.message, str(exc.value)
    assert str(m) in str(exc.value)


def test_malformed_pose_values(tmp_path, ur5):
    arm, t, q, _ = _trajectory(ur5, seed=4, n=50)
    p, R = urdf_fk(arm, q, "tool0")
    T = np.tile(np.eye(4), (len(t), 1, 1))
    T[:, :3, :3], T[:, :3, 3] = R, p
    header = ["time"] + [f"q{i}" for i in range(6)] + [f"O_T_EE_{i}" for i in range(16)]
    log = tmp_path / "franka.csv"
    _write_csv(log, header, np.concatenate([t[:, None], q, T.reshape(len(t), 16)], 1))  # row-major
    m = _map(tmp_path / "map.yaml", "ee_pose: {link: tool0, format: matrix_colmajor}\n")
    with pytest.raises(InputError) as exc:
        _convert(log, tmp_path / "ds", ur5, mapping=m)
    e = exc.value
    assert "not a rigid transform" in e.message and e.where.startswith("line 2, columns")
    assert "format: matrix_rowmajor" in e.hint and str(log) in str(e)
    # a quaternion of norm 2
    quat = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    quat[5] *= 2.0
    header = ["time"] + [f"q{i}" for i in range(6)] + ["x", "y", "z", "qw", "qx", "qy", "qz"]
    _write_csv(log, header, np.concatenate([t[:, None], q, p, quat], 1))
    m = _map(
        tmp_path / "map.yaml",
        "ee_pose: {link: tool0, format: quaternion, columns: [x, y, z, qw, qx, qy, qz]}\n",
    )
    with pytest.raises(InputError) as exc:
        _convert(log, tmp_path / "ds2", ur5, mapping=m)
    assert "quaternion norm 2" in exc.value.message and exc.value.where.startswith("line 7")
    # a map column the file lacks
    m = _map(tmp_path / "map.yaml", "ee_pose: {link: tool0, format: axis_angle}\n")
    with pytest.raises(InputError) as exc:
        _convert(log, tmp_path / "ds3", ur5, mapping=m)
    assert "'actual_TCP_pose_0'" in exc.value.message and "missing" in exc.value.message

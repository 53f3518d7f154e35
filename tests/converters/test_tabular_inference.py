"""Tabular logs that convert with no map: column names, time units and named segments.

Every CSV is written here with numpy; the expected stamps are exact integers computed from the
written decimal text, the expected values are the written numbers.
"""

from __future__ import annotations

from decimal import Decimal
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.ingest.tabular import guess_time_unit
from robogs.format.dataset import Dataset
from robogs.format.validate import validate

UR5_REL = "ur5/robots/ur_description/urdf/ur5_robot.urdf"
J6 = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def _chain_urdf(n: int) -> str:
    parts = ['<robot name="chain"><link name="base"/>']
    for i in range(n):
        parent = "base" if i == 0 else f"l{i - 1}"
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" effort="50" velocity="2"/></joint>'
            f'<link name="l{i}"><inertial><mass value="1"/><origin xyz="0 0 0.05"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        )
    return "".join(parts) + "</robot>"


def _write(path: Path, header: list[str], cols: list[np.ndarray | list], fmts: list[str]) -> None:
    lines = [",".join(header)]
    for row in zip(*cols, strict=True):
        lines.append(
            ",".join(f % v if "%" in f else str(v) for f, v in zip(fmts, row, strict=True))
        )
    path.write_text("\n".join(lines) + "\n")


def _convert(src: Path, out: Path, urdf: Path) -> Dataset:
    return convert_path(src, out, options=ConvertOptions(urdf=urdf))


def _rtde(path: Path, n: int = 300, t0: float = 4321.25, hz: float = 500.0) -> dict:
    k = np.arange(n)
    t = t0 + k / hz
    q = np.stack([0.3 * np.sin(0.01 * k + i) for i in range(6)], 1)
    qd = np.stack([0.003 * hz * np.cos(0.01 * k + i) for i in range(6)], 1)
    cur = np.stack([0.5 + 0.1 * i + 0.0 * k for i in range(6)], 1)
    tau = np.stack([1.5 * i + 0.01 * k for i in range(6)], 1)
    header = ["timestamp"]
    cols: list = [t]
    fmts = ["%.3f"]
    for name, arr in (
        ("actual_q", q),
        ("actual_qd", qd),
        ("actual_current", cur),
        ("target_moment", tau),
    ):
        header += [f"{name}_{i}" for i in range(6)]
        cols += [arr[:, i] for i in range(6)]
        fmts += ["%.17g"] * 6
    _write(path, header, cols, fmts)
    return {"t_ns": np.round(t * 1000).astype(np.int64) * 1_000_000, "q": q, "qd": qd, "tau": tau}


@pytest.mark.realdata
def test_ur_rtde_csv_and_real_ur5_convert_without_map_or_package(
    tmp_path: Path, real_data: Path
) -> None:
    truth = _rtde(tmp_path / "rtde.csv")
    ds = _convert(tmp_path / "rtde.csv", tmp_path / "out", real_data / UR5_REL)
    tab = ds.episode().table("joint_states")
    np.testing.assert_array_equal(tab.column("t_ns").to_numpy(), truth["t_ns"])
    for i, j in enumerate(J6):
        np.testing.assert_array_equal(tab.column(f"position.{j}").to_numpy(), truth["q"][:, i])
        np.testing.assert_array_equal(tab.column(f"velocity.{j}").to_numpy(), truth["qd"][:, i])
        np.testing.assert_array_equal(tab.column(f"effort.{j}").to_numpy(), truth["tau"][:, i])
    prov = ds.manifest["provenance"]
    assert prov["mapping"]["rtde.csv"]["layout"] == "rtde"
    assert prov["mapping"]["rtde.csv"]["time"]["unit"] == "s"
    robot = prov["robot"]
    assert robot["meshes"] == 14 and robot["packages"]["example-robot-data"]["path"] == str(
        (real_data / "ur5").resolve()
    )
    assert all(Path(p).is_file() for p in robot["mesh_files"].values())
    assert len(ds.urdf(load_meshes=True).robogs_mesh_refs) == 14
    assert [f for f in validate(tmp_path / "out").findings if f.severity == "error"] == []


def test_generic_columns_with_named_segments(tmp_path: Path) -> None:
    urdf = tmp_path / "chain3.urdf"
    urdf.write_text(_chain_urdf(3))
    names = ["push_a"] * 120 + ["push_b"] * 80 + ["push_a"] * 60  # time restarts per segment
    local = np.concatenate([np.arange(120), np.arange(80), np.arange(60)]) * 0.004  # 250 Hz
    q = np.stack([np.sin(local + i) for i in range(3)], 1)
    dq = np.stack([np.cos(local + i) for i in range(3)], 1)
    tau = np.stack([0.5 * i + local for i in range(3)], 1)
    header = ["t_s", "q1", "q2", "q3", "dq1", "dq2", "dq3", "tau1", "tau2", "tau3", "segment"]
    cols = [local, *q.T, *dq.T, *tau.T, names]
    _write(tmp_path / "log.csv", header, cols, ["%.3f"] + ["%.17g"] * 9 + ["s"])
    ds = _convert(tmp_path / "log.csv", tmp_path / "out", urdf)
    assert sorted((e.id, e.segment) for e in ds.episodes) == [
        ("push_a_s00", "push_a"),
        ("push_a_s01", "push_a"),
        ("push_b", "push_b"),
    ]
    bounds = {"push_a_s00": (0, 120), "push_b": (120, 200), "push_a_s01": (200, 260)}
    for eid, (a, b) in bounds.items():
        ep = ds.episode(eid)
        tab = ep.table("joint_states")
        np.testing.assert_array_equal(
            tab.column("t_ns").to_numpy(), np.round(local[a:b] * 1000).astype(np.int64) * 10**6
        )
        for i in range(3):
            j = f"joint{i + 1}"
            np.testing.assert_array_equal(tab.column(f"position.{j}").to_numpy(), q[a:b, i])
            np.testing.assert_array_equal(tab.column(f"velocity.{j}").to_numpy(), dq[a:b, i])
            np.testing.assert_array_equal(tab.column(f"effort.{j}").to_numpy(), tau[a:b, i])
    prov = ds.manifest["provenance"]
    m = prov["mapping"]["log.csv"]
    assert m["segment_column"] == "segment" and m["time"]["unit"] == "s"
    assert m["joints"]["joint2"]["position"] == "q2" and m["joints"]["joint3"]["effort"] == "tau3"
    assert "dropped" not in prov  # restarts at a segment change are not "stamps going back"


@pytest.mark.parametrize(
    ("column", "scale", "t0", "step", "unit"),
    [
        ("time", 1e3, 0, 2, "ms"),  # 500 Hz in ms
        ("time", 1.0, 12.5, 0.008, "s"),  # 125 Hz in s
        ("timestamp", 1e6, 0, 1000, "us"),  # 1 kHz in us
        ("t", 1e9, 0, 4_000_000, "ns"),  # 250 Hz in ns
        ("timestamp", 1e9, 1_700_000_000_000_000_000, 10_000_000, "ns"),  # Unix epoch ns
        ("time", 1.0, 1_700_000_000.0, 0.01, "s"),  # Unix epoch s
    ],
)
def test_time_unit_is_guessed_and_said(
    tmp_path: Path, column: str, scale: float, t0: float, step: float, unit: str
) -> None:
    urdf = tmp_path / "c2.urdf"
    urdf.write_text(_chain_urdf(2))
    n = 50
    isint = float(step).is_integer() and float(t0).is_integer()
    raw = (
        [int(t0) + k * int(step) for k in range(n)] if isint else [t0 + k * step for k in range(n)]
    )
    text = [str(v) if isint else f"{v:.3f}" for v in raw]
    q = np.linspace(0, 0.5, n)
    _write(tmp_path / "l.csv", [column, "q_0", "q_1"], [text, q, -q], ["s", "%.17g", "%.17g"])
    ds = _convert(tmp_path / "l.csv", tmp_path / "o", urdf)
    t = ds.episode().table("joint_states").column("t_ns").to_numpy()
    per_unit_ns = int(round(1e9 / scale))
    want = [int(Decimal(v) * per_unit_ns) for v in text]  # exact, from the written text
    assert t.tolist() == want
    prov = ds.manifest["provenance"]
    assert prov["mapping"]["l.csv"]["time"]["unit"] == unit
    assert any(f"read in {unit} (guessed" in n for n in prov["notes"])


def test_guess_time_unit_refuses_what_it_cannot_tell() -> None:
    with pytest.raises(ValueError, match="increasing"):
        guess_time_unit(np.array([3.0, 3.0, 3.0]))
    with pytest.raises(ValueError, match="1 Hz and 20 kHz"):
        guess_time_unit(np.arange(10) * 1e-9)  # a step of 1e-9 units: over 1 GHz in any unit


def test_franka_names_one_based_and_bracketed(tmp_path: Path) -> None:
    urdf = tmp_path / "c7.urdf"
    urdf.write_text(_chain_urdf(7))
    n = 40
    t = np.arange(n) * 0.001
    q = np.stack([0.1 * i + 0.01 * np.sin(t + i) for i in range(7)], 1)
    header = ["time"] + [f"q[{i}]" for i in range(7)] + [f"tau_J_{i + 1}" for i in range(7)]
    header += [f"O_T_EE_{k}" for k in range(16)]
    tau = np.tile(np.arange(7.0), (n, 1))
    eye = np.tile(np.eye(4).reshape(-1, order="F"), (n, 1))
    cols = [t, *q.T, *tau.T, *eye.T]
    _write(tmp_path / "f.csv", header, cols, ["%.3f"] + ["%.17g"] * 30)
    ds = _convert(tmp_path / "f.csv", tmp_path / "o", urdf)
    tab = ds.episode().table("joint_states")
    np.testing.assert_array_equal(tab.column("position.joint7").to_numpy(), q[:, 6])
    np.testing.assert_array_equal(tab.column("effort.joint5").to_numpy(), np.full(n, 4.0))
    m = ds.manifest["provenance"]["mapping"]["f.csv"]
    assert m["layout"] == "franka" and m["time"]["unit"] == "s"
    assert m["joints"]["joint1"]["position"] == "q[0]"
    assert any("O_T_EE" in n for n in ds.manifest["provenance"]["notes"])
    assert ds.episode().stream("joint_states")["derived"] == [
        f"velocity.joint{i + 1}" for i in range(7)
    ]

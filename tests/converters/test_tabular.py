"""Import of tabular joint logs (CSV/Parquet): layouts, mapping files and bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.ingest.tabular import TabularOptions, auto_mapping, detect_tabular
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf

UR5_REL = "ur5/robots/ur_description/urdf/ur5_robot.urdf"  # inside the real-data folder
J6 = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def _convert(
    src: Path, out: Path, urdf: Path, package_roots: dict | None = None, **tabular: Any
) -> Dataset:
    """The one driver (``convert_path``) on a tabular log; ``tabular``: TabularOptions fields."""
    opts = ConvertOptions(urdf=urdf, package_roots=package_roots, source=TabularOptions(**tabular))
    return convert_path(src, out, fmt="tabular", options=opts)


def _chain_urdf(n: int, limit: float = 2.8) -> str:
    parts = ['<robot name="chain"><link name="base"/>']
    for i in range(n):
        parent = "base" if i == 0 else f"l{i - 1}"
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="{parent}"/><child link="l{i}"/>'
            f'<origin xyz="0 0 0.1"/><axis xyz="0 {i % 2} {1 - i % 2}"/>'
            f'<limit lower="{-limit}" upper="{limit}" effort="50" velocity="2"/>'
            f'<dynamics damping="0.{i + 1}" friction="0.0{i + 1}"/></joint>'
            f'<link name="l{i}"><inertial><mass value="1"/><origin xyz="0 0 0.05"/>'
            f'<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        )
    parts.append("</robot>")
    return "".join(parts)


@pytest.fixture(scope="module")
def ur5(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("robot") / "ur5.urdf"
    p.write_text(ur5_urdf())
    return p


@pytest.fixture
def chain3(tmp_path) -> Path:
    p = tmp_path / "chain3.urdf"
    p.write_text(_chain_urdf(3))
    return p


def _write_csv(path: Path, header: list[str], rows, prefix: str = "") -> Path:
    lines = [prefix] if prefix else []
    lines.append(",".join(header))
    for r in rows:
        lines.append(
            r
            if isinstance(r, str)
            else ",".join(f"{v:.9g}" if isinstance(v, float) else str(v) for v in r)
        )
    path.write_text("\n".join(lines) + "\n")
    return path


def _generic_rows(n: int = 200, step_ns: int = 10_000_000, t0: int = 5_000_000_000):
    t = t0 + np.arange(n, dtype=np.int64) * step_ns
    ts = (t - t0) * 1e-9
    q = np.stack([0.5 * np.sin(1.0 * ts), 0.3 * np.cos(0.7 * ts), 0.2 * np.sin(1.3 * ts + 0.4)], 1)
    qd = np.stack(
        [0.5 * np.cos(1.0 * ts), -0.21 * np.sin(0.7 * ts), 0.26 * np.cos(1.3 * ts + 0.4)], 1
    )
    tau = np.stack([np.sin(ts), np.cos(ts), ts], 1)
    return t, q, qd, tau


def _provenance(ds: Dataset) -> dict:
    return ds.manifest["provenance"]


# --------------------------------------------------------------------------- layouts


def test_rtde_layout_auto_mapped(tmp_path, ur5):
    truth = generate_armlog(
        tmp_path / "logs", ur5, ArmLogSpec(effect="none", segments=2, duration_s=2.0)
    )
    assert detect_tabular(tmp_path / "logs")
    ds = _convert(tmp_path / "logs", tmp_path / "out", ur5)
    assert [e.id for e in ds.episodes] == ["segment_00", "segment_01"]
    ep = ds.episode("segment_00")
    assert ep.segment == "segment_00.csv#0"
    table = ep.table("joint_states")
    raw = np.loadtxt(tmp_path / "logs" / "segment_00.csv", delimiter=",", skiprows=1)
    t = table.column("t_ns").to_numpy()
    assert t[0] == 1_234_500_000_000 and t[1] - t[0] == 8_000_000  # exact decimal seconds -> ns
    for i, j in enumerate(J6):
        np.testing.assert_array_equal(table.column(f"position.{j}").to_numpy(), raw[:, 1 + i])
        np.testing.assert_array_equal(table.column(f"velocity.{j}").to_numpy(), raw[:, 7 + i])
        np.testing.assert_array_equal(
            table.column(f"effort.{j}").to_numpy(), raw[:, 19 + i]
        )  # target_moment
    prov = _provenance(ds)
    assert prov["mapping"]["segment_00.csv"]["layout"] == "rtde"
    assert any("actual_current" in n for n in prov["notes"])
    assert prov["topics"]["segment_00.csv"]["written"] == 250
    assert "derived" not in ep.stream("joint_states")
    assert ds.physics()["objects"] == {}
    assert (ds.root / "robot" / "robot.urdf").is_file()
    assert truth["files"] == prov["files"]


def test_time_gap_inside_a_file_starts_a_segment(tmp_path, ur5):
    generate_armlog(
        tmp_path / "logs", ur5, ArmLogSpec(segments=3, duration_s=1.0, single_file=True, gap_s=5.0)
    )
    ds = _convert(tmp_path / "logs" / "log.csv", tmp_path / "out", ur5)
    assert [e.segment for e in ds.episodes] == ["log.csv#0", "log.csv#1", "log.csv#2"]
    assert [e.table("joint_states").num_rows for e in ds.episodes] == [125, 125, 125]
    assert any("split the file into 3 segments" in n for n in _provenance(ds)["notes"])


def test_franka_layout_and_parquet(tmp_path):
    urdf = tmp_path / "chain7.urdf"
    urdf.write_text(_chain_urdf(7))
    n = 50
    t = np.arange(n) * 0.001
    cols = {"time": t}
    for i in range(7):
        cols[f"q{i}"] = 0.1 * i + 0.01 * np.sin(t)
        cols[f"dq{i}"] = 0.01 * np.cos(t)
        cols[f"tau_J{i}"] = np.full(n, float(i))
    pq.write_table(pa.table(cols), tmp_path / "franka.parquet")
    ds = _convert(tmp_path / "franka.parquet", tmp_path / "out", urdf)
    table = ds.episode().table("joint_states")
    assert table.column("t_ns").to_pylist()[:3] == [0, 1_000_000, 2_000_000]
    np.testing.assert_array_equal(table.column("effort.joint5").to_numpy(), np.full(n, 4.0))
    np.testing.assert_allclose(table.column("position.joint7").to_numpy(), cols["q6"])
    assert _provenance(ds)["mapping"]["franka.parquet"]["layout"] == "franka"
    assert ds.physics()["joints"]["joint3"] == {"damping": 0.3, "friction": 0.03}  # URDF <dynamics>


def test_generic_layout_derives_missing_velocity_and_keeps_no_effort(tmp_path, chain3):
    t, q, qd, _ = _generic_rows()
    header = ["t_ns"] + [f"position.joint{i + 1}" for i in range(3)]
    _write_csv(
        tmp_path / "gen.csv", header, [[int(a), *map(float, b)] for a, b in zip(t, q, strict=True)]
    )
    ds = _convert(tmp_path / "gen.csv", tmp_path / "out", chain3)
    ep = ds.episode()
    stream = ep.stream("joint_states")
    assert stream["derived"] == ["velocity.joint1", "velocity.joint2", "velocity.joint3"]
    table = ep.table("joint_states")
    assert not [c for c in table.schema.names if c.startswith("effort.")]
    v = np.stack([table.column(f"velocity.joint{i + 1}").to_numpy() for i in range(3)], 1)
    np.testing.assert_allclose(v[5:-5], qd[5:-5], atol=2e-5)
    notes = _provenance(ds)["notes"]
    assert any("savitzky_golay" in n for n in notes) and any(
        "no effort columns" in n for n in notes
    )


def test_yaml_map_units_and_motor_current(tmp_path, chain3):
    t, q, qd, tau = _generic_rows()
    kt, gear = 0.05, 100.0
    header = (
        ["stamp_ms"]
        + [f"a{i}" for i in range(3)]
        + [f"w{i}" for i in range(3)]
        + [f"i{i}" for i in range(3)]
    )
    rows = [
        [
            f"{(a - t[0]) / 1e6:.3f}",
            *map(float, np.degrees(b)),
            *map(float, np.degrees(c)),
            *map(float, d / (kt * gear)),
        ]
        for a, b, c, d in zip(t, q, qd, tau, strict=True)
    ]
    _write_csv(tmp_path / "log.csv", header, rows)
    mp = tmp_path / "map.yaml"
    lines = [
        "time: {column: stamp_ms, unit: ms, epoch_ns: 1000}",
        "effort_kind: current",
        "joints:",
    ]
    for i in range(3):
        lines += [
            f"  joint{i + 1}:",
            f"    position: {{column: a{i}, unit: deg}}",
            f"    velocity: {{column: w{i}, unit: deg/s}}",
            f"    effort: {{column: i{i}, unit: A, torque_constant: {kt}, gear_ratio: {gear}}}",
        ]
    mp.write_text("\n".join(lines) + "\n")
    ds = _convert(tmp_path / "log.csv", tmp_path / "out", chain3, mapping=mp)
    table = ds.episode().table("joint_states")
    np.testing.assert_array_equal(table.column("t_ns").to_numpy(), t - t[0] + 1000)
    np.testing.assert_allclose(table.column("position.joint2").to_numpy(), q[:, 1], atol=1e-8)
    np.testing.assert_allclose(table.column("velocity.joint3").to_numpy(), qd[:, 2], atol=1e-8)
    np.testing.assert_allclose(table.column("effort.joint1").to_numpy(), tau[:, 0], atol=1e-7)
    m = _provenance(ds)["mapping"]["log.csv"]
    assert m["layout"] == "map" and m["joints"]["joint1"]["units"]["effort"] == "A"


def test_bad_mapping_names_the_missing_column(tmp_path, chain3):
    t, q, _, _ = _generic_rows()
    _write_csv(
        tmp_path / "log.csv",
        ["t", "a", "b", "c"],
        [[float(a) * 1e-9, *map(float, b)] for a, b in zip(t, q, strict=True)],
    )
    mp = tmp_path / "map.yaml"
    mp.write_text(
        "time: t\njoints:\n  joint1: {position: a}\n  joint2: {position: b}\n  joint3: {position: qq3}\n"
    )
    with pytest.raises(InputError, match="'qq3'") as exc:
        _convert(tmp_path / "log.csv", tmp_path / "out", chain3, mapping=mp)
    assert "log.csv" in str(exc.value) and not (tmp_path / "out").exists()
    mp.write_text("time: t\njoints:\n  joint1: {position: a}\n  elbow: {position: b}\n")
    with pytest.raises(InputError, match="not in the URDF"):
        _convert(tmp_path / "log.csv", tmp_path / "out", chain3, mapping=mp)


def test_joint_name_mismatch_lists_both_sets(tmp_path, chain3):
    t, q, _, _ = _generic_rows(20)
    _write_csv(
        tmp_path / "log.csv",
        ["t_ns", "q_shoulder", "q_elbow", "q_wrist"],
        [[int(a), *map(float, b)] for a, b in zip(t, q, strict=True)],
    )
    with pytest.raises(InputError) as exc:
        _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    msg = str(exc.value)
    assert "q_shoulder" not in msg and "'shoulder'" in msg and "'joint1'" in msg
    with pytest.raises(InputError, match="URDF has"):
        auto_mapping(
            ["timestamp", *(f"actual_q_{i}" for i in range(6))],
            ["joint1", "joint2", "joint3"],
            tmp_path / "x.csv",
        )


# --------------------------------------------------------------------------- bad input


def _generic_csv(tmp_path: Path, n: int = 100):
    t, q, qd, tau = _generic_rows(n)
    header = ["t_ns"] + [
        f"{k}.joint{i + 1}" for k in ("position", "velocity", "effort") for i in range(3)
    ]
    rows = [
        [int(a), *map(float, b), *map(float, c), *map(float, d)]
        for a, b, c, d in zip(t, q, qd, tau, strict=True)
    ]
    return header, rows


def _dropped(ds: Dataset, name: str = "log.csv") -> dict:
    return _provenance(ds)["topics"][name].get("dropped", {})


def test_duplicated_and_out_of_order_stamps_are_dropped_and_counted(tmp_path, chain3):
    header, rows = _generic_csv(tmp_path)
    rows.insert(10, list(rows[9]))  # exact duplicate
    rows[30], rows[31] = rows[31], rows[30]  # one sample out of order
    _write_csv(tmp_path / "log.csv", header, rows)
    ds = _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    d = _dropped(ds)
    assert d == {"duplicate stamp": 1, "stamp earlier than the previous sample": 1}
    t = ds.episode().table("joint_states").column("t_ns").to_numpy()
    assert len(t) == 99 and np.all(np.diff(t) > 0)
    rec = _provenance(ds)["topics"]["log.csv"]
    assert rec["messages"] == 101 and rec["written"] == 99


def test_non_monotonic_file_is_an_error_naming_row_and_column(tmp_path, chain3):
    header, rows = _generic_csv(tmp_path)
    rows[40:60] = rows[40:60][::-1]
    _write_csv(tmp_path / "log.csv", header, rows)
    with pytest.raises(InputError, match="go back in time") as exc:
        _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    assert exc.value.where.startswith("line ") and "'t_ns'" in exc.value.where


def test_nan_rows_and_garbled_leading_rows(tmp_path, chain3):
    header, rows = _generic_csv(tmp_path)
    rows[5][4] = "nan"
    rows[7][2] = ""
    rows[9] = "1.0,garbage,row,%%,,,,,,"
    _write_csv(
        tmp_path / "log.csv", header, rows, prefix="# logger v2\x00\x01 started\nvoltage;12.1"
    )
    ds = _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    d = _dropped(ds)
    assert d["lines before the header"] == 2
    assert d["NaN or empty value in column 'velocity.joint1'"] == 1
    assert d["NaN or empty value in column 'position.joint2'"] == 1
    assert sum(v for k, v in d.items() if k.startswith("unparseable")) == 1
    assert ds.episode().table("joint_states").num_rows == 97
    assert any(
        "'velocity.joint1' (line 9)" in n for n in _provenance(ds)["notes"]
    )  # file line of the NaN


def test_degrees_given_as_radians_are_detected(tmp_path, chain3):
    header, rows = _generic_csv(tmp_path)
    for r in rows:
        r[2] = float(np.degrees(r[2])) + 40.0  # joint2 logged in degrees around 40 deg
    _write_csv(tmp_path / "log.csv", header, rows)
    with pytest.raises(InputError, match="degrees") as exc:
        _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    assert "'position.joint2'" in exc.value.where and "log.csv" in str(exc.value)


def test_rows_of_different_lengths(tmp_path, chain3):
    header, rows = _generic_csv(tmp_path)
    text_rows = [",".join(str(v) for v in r) for r in rows]
    text_rows[-1] = ",".join(text_rows[-1].split(",")[:4])  # truncated last row: dropped
    _write_csv(tmp_path / "log.csv", header, text_rows)
    ds = _convert(tmp_path / "log.csv", tmp_path / "out", chain3)
    assert _dropped(ds) == {"truncated rows at the end of the file": 1}
    text_rows[50] = ",".join(text_rows[50].split(",")[:6])  # short row inside the file: error
    _write_csv(tmp_path / "log2.csv", header, text_rows)
    with pytest.raises(InputError, match="different lengths") as exc:
        _convert(tmp_path / "log2.csv", tmp_path / "out2", chain3)
    assert exc.value.where == "line 52, column 'velocity.joint3'"  # the first missing field


def test_missing_log_and_wrong_suffix(tmp_path, chain3):
    with pytest.raises(InputError, match="does not exist"):
        _convert(tmp_path / "nope.csv", tmp_path / "out", chain3)
    (tmp_path / "x.txt").write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="not a CSV"):
        _convert(tmp_path / "x.txt", tmp_path / "out", chain3)


# --------------------------------------------------------------------------- real robot


@pytest.mark.realdata
def test_real_ur5_urdf_with_and_without_meshes(tmp_path, real_data: Path, monkeypatch):
    REAL, UR5_REAL = real_data, real_data / UR5_REL
    generate_armlog(tmp_path / "logs", UR5_REAL, ArmLogSpec(segments=1, duration_s=1.0))
    ds = _convert(
        tmp_path / "logs",
        tmp_path / "a",
        UR5_REAL,
        package_roots={"example-robot-data": REAL / "ur5"},
    )
    assert _provenance(ds)["robot"]["meshes"] > 0
    assert len(ds.urdf(load_meshes=True).robogs_mesh_refs) > 0
    assert ds.physics()["joints"]["elbow_joint"] == {"damping": 0.0, "friction": 0.0}
    # without --package: found as yourdfpy does (the ancestor that holds the mesh path)
    ds1 = _convert(tmp_path / "logs", tmp_path / "b1", UR5_REAL)
    pkg = _provenance(ds1)["robot"]["packages"]["example-robot-data"]
    assert Path(pkg["path"]) == (REAL / "ur5").resolve() and "yourdfpy" in pkg["how"]
    assert _provenance(ds1)["robot"]["meshes"] == _provenance(ds)["robot"]["meshes"]
    # a URDF copied away from its meshes: no package anywhere, the URDF is kept without them
    lone = tmp_path / "lone" / "ur5_robot.urdf"
    lone.parent.mkdir()
    lone.write_bytes(UR5_REAL.read_bytes())
    monkeypatch.setenv("ROS_PACKAGE_PATH", "")
    ds2 = _convert(tmp_path / "logs", tmp_path / "b", lone, meshes_optional=True)
    assert any("meshes not copied" in n for n in _provenance(ds2)["notes"])
    assert ds2.urdf(load_meshes=True).robogs_mesh_refs == []
    table = ds2.episode().table("joint_states")
    assert math.isclose(table.column("t_ns").to_numpy()[0] * 1e-9, 1234.5)
    json.dumps(_provenance(ds2))


def test_cli_convert_with_column_map(tmp_path, chain3, capsys):
    """``robogs convert LOG OUT --urdf U --map M`` routes --map to the tabular column mapping."""
    from robogs.cli.main import main

    t, q, _, _ = _generic_rows()
    _write_csv(
        tmp_path / "log.csv",
        ["t", "a", "b", "c"],
        [[float(a - t[0]) * 1e-9, *map(float, b)] for a, b in zip(t, q, strict=True)],
    )
    mp = tmp_path / "map.yaml"
    mp.write_text(
        "time: {column: t, unit: s}\njoints:\n  joint1: {position: a}\n  joint2: {position: b}\n"
        "  joint3: {position: c}\n"
    )
    rc = main(
        [
            "convert",
            str(tmp_path / "log.csv"),
            str(tmp_path / "out"),
            "--urdf",
            str(chain3),
            "--map",
            str(mp),
        ]
    )
    assert rc == 0, capsys.readouterr().err
    table = Dataset.open(tmp_path / "out").episode().table("joint_states")
    np.testing.assert_allclose(table.column("position.joint3").to_numpy(), q[:, 2], atol=1e-12)
    mp.write_text(
        "time: t\njoints:\n  joint1: {position: a}\n  joint2: {position: b}\n  joint3: {position: zz}\n"
    )
    rc = main(
        [
            "convert",
            str(tmp_path / "log.csv"),
            str(tmp_path / "out2"),
            "--urdf",
            str(chain3),
            "--map",
            str(mp),
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "'zz'" in err and "Traceback" not in err and not (tmp_path / "out2").exists()

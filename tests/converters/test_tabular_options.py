"""Tabular options: ``TabularOptions`` from the command line and through the one driver
``convert_path`` as ``ConvertOptions.source`` (``gap_s`` splits segments, ``meshes_optional`` keeps a URDF whose meshes are
missing); ``convert_tabular`` is a deprecated alias of the driver.

Oracles: the log is written here with a known gap; the expected segment sizes follow from it.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.convert.ingest.tabular import (
    TabularOptions,
    add_arguments,
    convert_tabular,
    options_from_args,
)
from robogs.convert.ingest.tabular.options import from_convert_options
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError

MESH = '<visual><geometry><mesh filename="meshes/missing.stl"/></geometry></visual>'


def _urdf(path: Path, *, mesh: bool = False) -> Path:
    parts = ['<robot name="c2"><link name="base"/>']
    for i in range(2):
        parent = "base" if i == 0 else f"l{i - 1}"
        parts.append(
            f'<joint name="joint{i + 1}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" effort="50" velocity="2"/></joint>'
            f'<link name="l{i}">{MESH if mesh else ""}<inertial><mass value="1"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>'
        )
    path.write_text("".join(parts) + "</robot>")
    return path


def _log(path: Path) -> Path:
    """200 rows at 250 Hz with a 0.3 s pause after row 100 (the default gap is 1 s)."""
    t = np.arange(200) * 4_000_000
    t[100:] += 300_000_000
    lines = ["t_ns,q1,q2"] + [f"{v},{0.1 * math.sin(k / 50)!r},0.2" for k, v in enumerate(t)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    p.add_argument("--map", type=Path)  # shared with the bag converters: the CLI owns it
    add_arguments(p)
    return p


def test_options_from_the_command_line() -> None:
    args = _parser().parse_args(["--map", "m.yaml", "--gap-s", "0.05", "--meshes-optional"])
    assert options_from_args(args) == TabularOptions(Path("m.yaml"), 0.05, True)
    assert options_from_args(_parser().parse_args([])) == TabularOptions()
    with pytest.raises(InputError, match="gap_s") as exc:
        options_from_args(_parser().parse_args(["--gap-s", "-1"]))
    assert exc.value.where == "--gap-s"
    with pytest.raises(InputError):
        TabularOptions(gap_s=float("nan"))


def test_gap_s_reaches_the_converter_through_convert_path(tmp_path: Path) -> None:
    urdf, log = _urdf(tmp_path / "c2.urdf"), _log(tmp_path / "log.csv")
    ds = convert_path(log, tmp_path / "a", options=ConvertOptions(urdf=urdf))
    assert [e.table("joint_states").num_rows for e in ds.episodes] == [200]

    ds = convert_path(log, tmp_path / "b", options=ConvertOptions(urdf=urdf, gap_s=0.1))
    assert [e.table("joint_states").num_rows for e in ds.episodes] == [100, 100]
    assert [e.segment for e in ds.episodes] == ["log.csv#0", "log.csv#1"]

    # the CLI passes the converter's own options as ``source``; they win over flat keywords
    opts = ConvertOptions(urdf=urdf, source=TabularOptions(gap_s=0.2))
    assert from_convert_options(opts) == TabularOptions(gap_s=0.2)
    assert from_convert_options(ConvertOptions(urdf=urdf, gap_s=0.1)).gap_s == 0.1
    ds = convert_path(log, tmp_path / "c", options=opts)
    assert [e.table("joint_states").num_rows for e in ds.episodes] == [100, 100]


def test_meshes_optional_keeps_a_urdf_whose_meshes_are_missing(tmp_path: Path) -> None:
    urdf, log = _urdf(tmp_path / "c2.urdf", mesh=True), _log(tmp_path / "log.csv")
    with pytest.raises(InputError, match="mesh"):
        convert_path(log, tmp_path / "a", options=ConvertOptions(urdf=urdf))
    assert not (tmp_path / "a").exists()

    lenient = ConvertOptions(urdf=urdf, source=TabularOptions(meshes_optional=True))
    ds = convert_path(log, tmp_path / "b", options=lenient)
    text = (ds.root / "robot" / "robot.urdf").read_text()
    assert "joint2" in text and "missing.stl" not in text
    prov = ds.manifest["provenance"]
    assert any("meshes not copied" in n and "2 mesh geometries" in n for n in prov["notes"])
    assert not any(n.startswith("no robot") for n in prov["notes"])
    assert ds.manifest["robot"]["urdf"] == "robot/robot.urdf"


def test_convert_tabular_is_a_deprecated_alias_of_the_driver(tmp_path: Path) -> None:
    urdf, log = _urdf(tmp_path / "c2.urdf", mesh=True), _log(tmp_path / "log.csv")
    with pytest.warns(DeprecationWarning, match="convert_path"):
        out = convert_tabular(log, tmp_path / "out", urdf=urdf, gap_s=0.1)
    ds = convert_path(
        log, tmp_path / "ref", options=ConvertOptions(urdf=_urdf(tmp_path / "u.urdf"), gap_s=0.1)
    )
    got = Dataset.open(out)
    assert [e.id for e in got.episodes] == [e.id for e in ds.episodes]
    for a, b in zip(got.episodes, ds.episodes, strict=True):
        assert a.table("joint_states").equals(b.table("joint_states"))
    assert got.manifest["provenance"]["converter"] == "tabular"
    with pytest.warns(DeprecationWarning), pytest.raises(InputError, match="URDF file not found"):
        convert_tabular(log, tmp_path / "x", urdf=tmp_path / "nope.urdf")


def test_cli_flags_reach_the_converter(tmp_path: Path, capsys) -> None:
    """``robogs convert LOG OUT --urdf U --gap-s S --meshes-optional``; a bad flag is one line."""
    from robogs.cli.main import main

    urdf, log = _urdf(tmp_path / "c2.urdf", mesh=True), _log(tmp_path / "log.csv")
    argv = ["convert", str(log), str(tmp_path / "out"), "--urdf", str(urdf)]
    assert main([*argv, "--gap-s", "0.1", "--meshes-optional"]) == 0, capsys.readouterr().err
    ds = Dataset.open(tmp_path / "out")
    assert [e.table("joint_states").num_rows for e in ds.episodes] == [100, 100]
    assert any("meshes not copied" in n for n in ds.manifest["provenance"]["notes"])
    capsys.readouterr()
    bad = ["convert", str(log), str(tmp_path / "bad"), "--urdf", str(urdf), "--gap-s", "-1"]
    assert main(bad) == 2
    err = capsys.readouterr().err
    assert "--gap-s" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()

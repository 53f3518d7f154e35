"""Converter registry, format detection, the CLI, and the robot copied into the dataset."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from plugin_dist import write_dist

from robogs.cli.main import main
from robogs.convert import registry
from robogs.convert.ingest import ConvertOptions, convert_path
from robogs.format.errors import InputError
from robogs.format.plugins import PluginError, PluginWarning
from robogs.format.validate import validate

CR3 = "dobot_cr3/dobot_description/urdf/cr3_robot.urdf"
CR3_JOINTS = ["joint1", "joint2", "joint3"]


def test_builtin_converters_and_detection(tmp_path: Path, synth) -> None:
    assert {"ros1", "ros2", "mcap", "video", "images", "nerfstudio", "colmap"} <= set(
        registry.available_converters()
    )
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.05)
    (tmp_path / "b.bin").write_bytes((tmp_path / "a.mcap").read_bytes())  # MCAP by its magic bytes
    assert registry.detect_format(tmp_path / "a.mcap").name == "mcap"
    assert registry.detect_format(tmp_path / "b.bin").name == "mcap"
    (tmp_path / "x.txt").write_text("hello")
    with pytest.raises(InputError, match="cannot tell the source format"):
        registry.detect_format(tmp_path / "x.txt")
    with pytest.raises(InputError, match="unknown source format 'nope'"):
        registry.get_converter("nope")


def test_register_and_detect(tmp_path: Path) -> None:
    seen = []

    def convert(src, ctx):
        seen.append(src)
        ctx.writer.set_asset("thing", kind="object")
        raise InputError("stop here")

    with registry.REGISTRY.sandbox():
        registry.register_converter("weird", lambda p: p.suffix == ".weird", convert, priority=1000)
        with pytest.raises(ValueError, match="already registered"):
            registry.register_converter("weird", lambda p: False, convert)
        (tmp_path / "a.weird").write_text("x")
        assert registry.detect_format(tmp_path / "a.weird").name == "weird"
        with pytest.raises(InputError, match="stop here"):
            convert_path(tmp_path / "a.weird", tmp_path / "out")
        assert seen == [tmp_path / "a.weird"] and not (tmp_path / "out").exists()
    assert "weird" not in registry.available_converters()


def test_entry_points_of_an_installed_distribution(tmp_path: Path, monkeypatch) -> None:
    write_dist(
        tmp_path,
        "robogs-labconv",
        "labconv",
        """
        from robogs.convert.registry import Converter, register_converter

        def _no(path):
            return False

        def _convert(src, ctx):
            raise NotImplementedError

        PLUG = Converter("plugfmt", _no, _convert, "from a plug-in")
        OTHER = Converter("plugfmt", _no, _convert, "another one, same name")

        def setup():
            register_converter("plugfmt2", _no, _convert, description="registered by a call")
        """,
        """
        [robogs.converters]
        plugfmt = labconv:PLUG
        plugfmt2 = labconv:setup
        again = labconv:PLUG
        clash = labconv:OTHER
        """,
    )
    with monkeypatch.context() as mp, registry.REGISTRY.sandbox():
        mp.syspath_prepend(str(tmp_path))
        with pytest.warns(PluginWarning, match="'clash'.*already registered") as caught:
            convs = registry.available_converters()
        assert len(caught) == 1  # the same Converter under a second name is no clash
        assert convs["plugfmt"].description == "from a plug-in" and "plugfmt2" in convs
        entries = {e.name: e for e in registry.converter_entries()}
        assert entries["plugfmt2"].source == entries["clash"].source == "robogs-labconv"
        assert entries["clash"].status == "unavailable"
        with pytest.raises(PluginError, match="'clash' from distribution 'robogs-labconv'"):
            registry.get_converter("clash")
    assert "plugfmt" not in registry.available_converters()


def test_cli_convert_json_and_errors(tmp_path: Path, synth, capsys) -> None:
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.1)
    out = tmp_path / "out"
    assert (
        main(
            [
                "convert",
                str(tmp_path / "a.mcap"),
                str(out),
                "--json",
                "--topic",
                "ignore=/wrench/ft_sensor",
            ]
        )
        == 0
    )
    summary = json.loads(capsys.readouterr().out)
    assert summary["episodes"][0]["streams"] == [
        "camera/cam0",
        "ee_poses",
        "joint_states",
        "object_poses",
        "streams/rosout_like",  # no role of its own: decoded into a generic table
    ]
    assert {d["topic"] for d in summary["dropped"]} == {"/wrench/ft_sensor"}
    roles = {r["topic"]: r["role"] for r in summary["roles"]}
    assert roles["/rosout_like"] == "generic" and roles["/wrench/ft_sensor"] == "ignore"
    assert main(["convert", str(tmp_path / "a.mcap"), str(out)]) == 2
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1
        and "already exists" in err
        and "--force" in err
        and "Traceback" not in err
    )
    assert main(["convert", str(tmp_path / "a.mcap"), str(out), "--force", "--from", "ros1"]) == 2
    assert "not a ROS 1 bag" in capsys.readouterr().err
    assert main(["convert", "--list-formats"]) == 0
    assert "nerfstudio" in capsys.readouterr().out


@pytest.mark.realdata
def test_urdf_copied_with_meshes(tmp_path: Path, synth, real: Path) -> None:
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.1, joints=CR3_JOINTS)
    opts = ConvertOptions(urdf=real / CR3, roles={"/ee/tool0/pose": "ee_pose:Link6"})
    ds = convert_path(tmp_path / "a.mcap", tmp_path / "out", options=opts)
    assert ds.manifest["robot"] == {"urdf": "robot/robot.urdf", "base_link": "dummy_link"}
    meshes = sorted(r for r in ds.files if r.startswith("robot/meshes/"))
    assert meshes == [
        f"robot/meshes/{n}.STL"
        for n in ("Link1", "Link2", "Link3", "Link4", "Link5", "Link6", "base_link")
    ]
    urdf = ds.urdf(load_meshes=True)
    assert len(urdf.robot.links) == 8
    errors = [
        f"{f.code} {f.message}"
        for f in validate(tmp_path / "out").findings
        if f.severity == "error"
    ]
    # the synthetic end-effector poses are random, so only forward kinematics may disagree
    assert all(e.startswith("G008") for e in errors), errors


def test_robot_description_topic(tmp_path: Path, synth) -> None:
    urdf = (
        '<robot name="r"><link name="base"/><link name="l1"/>'
        '<joint name="shoulder_pan" type="revolute"><parent link="base"/><child link="l1"/>'
        '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>'
    )
    synth.write_ros2_mcap(tmp_path / "a.mcap", duration_s=0.05, robot_description=urdf)
    ds = convert_path(tmp_path / "a.mcap", tmp_path / "out")
    assert ds.manifest["robot"]["base_link"] == "base"
    assert ds.manifest["provenance"]["robot"]["urdf"] == "robot_description topic"
    bad = urdf.replace(
        '<link name="l1"/>',
        '<link name="l1"><visual><geometry><mesh filename="package://nowhere/'
        'm.stl"/></geometry></visual></link>',
    )
    synth.write_ros2_mcap(tmp_path / "b.mcap", duration_s=0.05, robot_description=bad)
    ds = convert_path(tmp_path / "b.mcap", tmp_path / "out2")
    assert "robot" not in ds.manifest
    assert any(
        "robot_description from the source not used" in n
        for n in ds.manifest["provenance"]["notes"]
    )
    assert not any(r.startswith("robot/") for r in ds.files)

"""Exports of a real third-party robot (Dobot CR5: COLLADA meshes, package:// URIs)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import pytest
import yourdfpy

from robogs.convert.export import export
from robogs.convert.export.usd_physics import validate_usd
from robogs.format import Dataset


@pytest.fixture(scope="module")
def cr5(tmp_path_factory: pytest.TempPathFactory, real_data: Path) -> Dataset:
    src = real_data / "dobot_cr5" / "dobot_description"
    w = Dataset.create(tmp_path_factory.mktemp("real") / "cr5")
    for p in sorted(src.rglob("*")):
        if p.is_file():
            w.copy_file("robot/dobot_description/" + p.relative_to(src).as_posix(), p)
    w.set_robot("robot/dobot_description/urdf/cr5_robot.urdf")
    return w.commit()


@pytest.mark.realdata
def test_real_robot_urdf_and_usd(cr5: Dataset, tmp_path: Path) -> None:
    report = export("urdf", cr5, tmp_path / "urdf")
    got = yourdfpy.URDF.load(str(tmp_path / "urdf/cr5_robot.urdf"), mesh_dir=str(tmp_path / "urdf"))
    ref = cr5.urdf(load_meshes=False)
    assert set(got.joint_map) == set(ref.joint_map)
    # every COLLADA mesh found and written as STL with all its triangles
    assert report.facts["converted_meshes"] and not list((tmp_path / "urdf").rglob("*.dae"))
    faces = [sum(len(g.faces) for g in u.scene.geometry.values()) for u in (got, cr5.urdf())]
    assert faces[0] == faces[1] > 0
    model = mujoco.MjModel.from_xml_path(str(tmp_path / "urdf/cr5_robot.urdf"))
    assert model.nbody == 1 + sum(j.type != "fixed" for j in ref.robot.joints)
    assert model.nmesh == len(list((tmp_path / "urdf/meshes").iterdir()))
    for name, j in ref.joint_map.items():
        if j.limit is not None:
            assert (got.joint_map[name].limit.lower, got.joint_map[name].limit.upper) == (
                j.limit.lower,
                j.limit.upper,
            )
    report = export("usd", cr5, tmp_path / "cr5.usdc")
    assert report.facts["validator_errors"] == 0
    assert [i for i in validate_usd(tmp_path / "cr5.usdc") if i.kind == "error"] == []
    assert any("dummy_link has no inertial" in n for n in report.notes)

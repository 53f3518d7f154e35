"""Exports of a real third-party robot (Dobot CR5: COLLADA meshes, package:// URIs)."""

from __future__ import annotations

from pathlib import Path

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
    export("urdf", cr5, tmp_path / "urdf")
    got = yourdfpy.URDF.load(str(tmp_path / "urdf/cr5_robot.urdf"), mesh_dir=str(tmp_path / "urdf"))
    ref = cr5.urdf(load_meshes=False)
    assert set(got.joint_map) == set(ref.joint_map)
    assert len(got.scene.geometry) == len(cr5.urdf().scene.geometry)  # every COLLADA mesh found
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

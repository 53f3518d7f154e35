"""Every exporter on the synthetic push scene (robogs.synth.scene): a UR5-like arm, a box, a table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import plyfile
import pytest
import yourdfpy
from rerun.chunk import RrdReader

from robogs.convert.export import export
from robogs.convert.export.splat_ply import ply_property_names
from robogs.convert.export.usd_physics import validate_usd
from robogs.format import Dataset

try:
    from .test_export_data import check_round_trip, mcap_round_trip
except ImportError:
    from test_export_data import check_round_trip, mcap_round_trip


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("synth") / "scene"
    synthesize(root, seed=0, size="small")
    return Dataset.open(root)


def test_mcap_round_trip_through_ingest(scene: Dataset, tmp_path: Path) -> None:
    back = mcap_round_trip(scene, tmp_path)
    check_round_trip(scene, back)
    a, b = scene.urdf(load_meshes=True), back.urdf(load_meshes=True)  # the robot comes back
    assert [j.name for j in b.robot.joints] == [j.name for j in a.robot.joints]
    assert (len(b.robot.links), len(b.robogs_mesh_refs)) == (
        len(a.robot.links),
        len(a.robogs_mesh_refs),
    )


def test_urdf_and_usd(scene: Dataset, tmp_path: Path) -> None:
    export("urdf", scene, tmp_path / "urdf")
    got = yourdfpy.URDF.load(
        str(next((tmp_path / "urdf").glob("*.urdf"))), mesh_dir=str(tmp_path / "urdf")
    )
    ref = scene.urdf(load_meshes=False)
    phys = scene.physics()
    for j, dyn in phys["joints"].items():
        assert float(got.joint_map[j].dynamics.damping) == dyn["damping"]
        assert float(got.joint_map[j].dynamics.friction) == dyn["friction"]
    for link in ref.robot.links:
        if link.inertial is not None:
            assert got.link_map[link.name].inertial.mass == link.inertial.mass
    report = export("usd", scene, tmp_path / "s.usdc")
    assert report.facts["validator_errors"] == 0
    assert [i for i in validate_usd(tmp_path / "s.usdc") if i.kind == "error"] == []


def test_ply_and_rerun(scene: Dataset, tmp_path: Path) -> None:
    report = export("ply", scene, tmp_path / "s.ply")
    ply = plyfile.PlyData.read(str(tmp_path / "s.ply"))
    k = (report.facts["sh_degree"] + 1) ** 2
    assert [p.name for p in ply["vertex"].properties] == ply_property_names(k)
    assert len(ply["vertex"].data) == sum(len(scene.splats(o)) for o in report.facts["owners"])
    assert np.isfinite(np.stack([ply["vertex"].data[n] for n in ("x", "y", "z")])).all()
    export("rerun", scene, tmp_path / "s.rrd")
    entities = {c.entity_path for c in RrdReader(tmp_path / "s.rrd").stream().collect().stream()}
    for link in scene.urdf(load_meshes=False).link_map:
        assert f"/world/robot/{link}" in entities
    assert "/world/cameras/cam0/image/rgb" in entities and "/world/objects/box" in entities

"""URDF export: inertials, joint dynamics, limits and collisions equal the dataset's."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yourdfpy

from robogs.convert.export import export
from robogs.convert.export.urdf_physics import FRAME_MASS_KG
from robogs.format import Dataset

try:
    from .test_export_data import PHYSICS, build_tiny_dataset
except ImportError:
    from test_export_data import PHYSICS, build_tiny_dataset


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return build_tiny_dataset(tmp_path_factory.mktemp("urdf") / "tiny")


def _inertia_in_link(link: yourdfpy.Link) -> tuple[float, np.ndarray, np.ndarray]:
    T = np.asarray(link.inertial.origin)
    R = T[:3, :3]
    return float(link.inertial.mass), T[:3, 3], R @ np.asarray(link.inertial.inertia) @ R.T


def test_urdf_export_matches_dataset(tiny: Dataset, tmp_path: Path) -> None:
    report = export("urdf", tiny, tmp_path / "out")
    out = tmp_path / "out"
    assert report.out == out and (out / "tiny_arm.urdf").is_file()
    got = yourdfpy.URDF.load(
        str(out / "tiny_arm.urdf"),
        mesh_dir=str(out),
        build_collision_scene_graph=True,
        load_collision_meshes=True,
    )
    ref = tiny.urdf()
    for link in ref.robot.links:
        g = got.link_map[link.name]
        if link.inertial is None:  # a frame link: the declared tiny inertial (see the sidecar)
            assert (g.inertial.mass, link.name) == (FRAME_MASS_KG, "tool")
            np.testing.assert_allclose(g.inertial.inertia, np.eye(3) * 0.4e-6 * 1e-3**2, rtol=1e-15)
            continue
        m0, c0, I0 = _inertia_in_link(link)
        m1, c1, I1 = _inertia_in_link(g)
        assert m1 == m0
        np.testing.assert_allclose(c1, c0, atol=1e-15)
        np.testing.assert_allclose(I1, I0, rtol=1e-12, atol=1e-15)
        assert len(g.collisions) >= 1  # visual used as collision where none was given
    for j in ref.robot.joints:
        g = got.joint_map[j.name]
        assert g.type == j.type
        np.testing.assert_allclose(g.origin, j.origin, atol=1e-12)
        if j.type == "fixed":
            continue
        assert (g.limit.lower, g.limit.upper, g.limit.effort, g.limit.velocity) == (
            j.limit.lower,
            j.limit.upper,
            j.limit.effort,
            j.limit.velocity,
        )
        # yourdfpy keeps <dynamics> attributes as strings
        assert float(g.dynamics.damping) == PHYSICS["joints"][j.name]["damping"]
        assert float(g.dynamics.friction) == PHYSICS["joints"][j.name]["friction"]
    # link1 had no collision: its visual mesh is now its collision too, loaded from the copy
    assert len(got.link_map["link1"].collisions) == 1
    assert len(got.collision_scene.geometry) == 3
    # the PLY mesh is written as STL (MuJoCo and pybullet load no PLY), same triangles
    assert got.link_map["link1"].collisions[0].geometry.mesh.filename == "meshes/link1.stl"
    stl = trimesh.load(out / "meshes" / "link1.stl", process=False)
    ply = trimesh.load(tiny.root / "robot/meshes/link1.ply", process=False)
    np.testing.assert_allclose(stl.triangles, ply.triangles, atol=1e-6)  # float32 STL
    assert (out / "meshes" / "base.stl").read_bytes() == (
        tiny.root / "robot/meshes/base.stl"
    ).read_bytes()  # STL is copied as is
    assert sorted(p.suffix for p in out.rglob("*") if p.suffix in (".ply", ".stl")) == [".stl"] * 4

    contact = json.loads((out / "tiny_arm.contact.json").read_text())
    assert contact["links"]["link1"] == {
        "friction_static": 0.9,
        "friction_dynamic": 0.85,
        "restitution": 0.0,
    }
    assert contact["joints"]["j1"] == {"armature": 0.01}
    box = contact["objects"]["box"]
    assert (box["friction_static"], box["friction_dynamic"], box["restitution"]) == (
        0.6,
        0.45,
        0.15,
    )
    obj = yourdfpy.URDF.load(str(out / box["urdf"]), mesh_dir=str(out / "objects/box"))
    ob = obj.link_map["box"]
    assert ob.inertial.mass == PHYSICS["objects"]["box"]["mass_kg"]
    np.testing.assert_allclose(
        np.asarray(ob.inertial.origin)[:3, 3], PHYSICS["objects"]["box"]["com_m"]
    )
    np.testing.assert_allclose(
        ob.inertial.inertia, PHYSICS["objects"]["box"]["inertia_kgm2"], rtol=1e-12
    )
    assert len(obj.scene.geometry) == 1


def test_physics_json_overrides_urdf_inertial(tiny: Dataset, tmp_path: Path) -> None:
    shutil.copytree(tiny.root, tmp_path / "copy")
    src = Dataset.open(tmp_path / "copy")
    with src.edit() as w:
        phys = src.physics()
        phys["objects"]["link2"] = {
            "equation": "articulated",
            "mass_kg": 0.75,
            "com_m": [0.04, 0.001, 0.0],
            "inertia_kgm2": [[3e-4, 1e-5, 0], [1e-5, 5e-4, 0], [0, 0, 6e-4]],
        }
        w.set_physics(phys)
        ds = w.commit()
    export("urdf", ds, tmp_path / "o", objects=False)
    got = yourdfpy.URDF.load(str(tmp_path / "o/tiny_arm.urdf"), load_meshes=False)
    m, c, inertia = _inertia_in_link(got.link_map["link2"])
    assert m == 0.75
    np.testing.assert_allclose(c, [0.04, 0.001, 0.0])
    np.testing.assert_allclose(inertia, phys["objects"]["link2"]["inertia_kgm2"], rtol=1e-12)
    assert not (tmp_path / "o/objects").exists()

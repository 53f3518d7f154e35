"""COLLADA textures of a URDF's meshes are copied into the dataset, never from outside the package.

None of the real DAE files in ``../shared/fixtures/real`` has an image texture (their
``<library_images/>`` are empty), so the textured mesh is a minimal COLLADA file written here.
"""

from __future__ import annotations

import posixpath
from pathlib import Path
from urllib.parse import unquote

import pytest

from robogs.convert.ingest import convert_path
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.dae_textures import dae_texture_refs, texture_uri
from robogs.format.errors import PathEscapeError
from robogs.format.validate import validate

_DAE = """<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="meter" meter="1"/><up_axis>Z_UP</up_axis></asset>
  <library_images>
    <image id="wood"><init_from>../../materials/textures/wood%20grain.png</init_from></image>
    <image id="b"><init_from><ref>tex/b.png</ref></init_from></image>
    <image id="abs"><init_from>file:///etc/hostname</init_from></image>
    <image id="out"><init_from>../../../outside.png</init_from></image>
    <image id="gone"><init_from>missing.png</init_from></image>
  </library_images>
  <library_geometries>
    <geometry id="tri"><mesh>
      <source id="p"><float_array id="pa" count="9">0 0 0 0.1 0 0 0 0.1 0</float_array>
        <technique_common><accessor source="#pa" count="3" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
        </accessor></technique_common></source>
      <vertices id="v"><input semantic="POSITION" source="#p"/></vertices>
      <triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes><visual_scene id="s"><node id="n">
    <instance_geometry url="#tri"/></node></visual_scene></library_visual_scenes>
  <scene><instance_visual_scene url="#s"/></scene>
</COLLADA>
"""

_URDF = """<robot name="r">
  <link name="base"><visual><geometry>
    <mesh filename="package://texpkg/meshes/visual/part.dae"/></geometry></visual></link>
  <link name="tip"><visual><geometry>
    <mesh filename="package://texpkg/meshes/visual/part.dae"/></geometry></visual></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="tip"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="end"/>
  <joint name="j2" type="continuous"><parent link="tip"/><child link="end"/>
    <axis xyz="0 0 1"/></joint>
</robot>
"""


def _package(root: Path) -> Path:
    pkg = root / "src" / "texpkg"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes/visual/tex").mkdir(parents=True)
    (pkg / "materials/textures").mkdir(parents=True)
    (pkg / "package.xml").write_text("<package><name>texpkg</name></package>", encoding="utf-8")
    (pkg / "urdf/r.urdf").write_text(_URDF, encoding="utf-8")
    (pkg / "meshes/visual/part.dae").write_text(_DAE, encoding="utf-8")
    (pkg / "materials/textures/wood grain.png").write_bytes(b"\x89PNG wood")
    (pkg / "meshes/visual/tex/b.png").write_bytes(b"\x89PNG b")
    (root / "src/outside.png").write_bytes(b"\x89PNG secret")
    return pkg


def test_textures_are_copied_next_to_their_mesh(tmp_path: Path, synth) -> None:
    pkg = _package(tmp_path)
    synth.write_ros1_bag(tmp_path / "a.bag")
    opts = ConvertOptions(urdf=pkg / "urdf/r.urdf", video=False)
    ds = convert_path(tmp_path / "a.bag", tmp_path / "out", options=opts)
    files = set(ds.manifest["files"])
    dae = next(f for f in files if f.endswith("part.dae"))
    copied = {}
    for ref in dae_texture_refs(ds.resolve(dae)):
        rel = posixpath.normpath(posixpath.join(posixpath.dirname(dae), unquote(ref)))
        copied[ref] = (ds.root / rel).read_bytes() if rel in files else None
    assert copied == {
        "../../materials/textures/wood%20grain.png": b"\x89PNG wood",
        "tex/b.png": b"\x89PNG b",
        "file:///etc/hostname": None,
        "../../../outside.png": None,
        "missing.png": None,
    }
    assert not any(f.endswith(("outside.png", "hostname")) for f in files)
    assert (ds.root / dae).read_text(encoding="utf-8") == _DAE  # the mesh is unchanged
    prov = ds.manifest["provenance"]
    assert prov["robot"]["textures"] == 2
    notes = [n for n in prov["notes"] if n.startswith("texture ")]
    assert len(notes) == 3
    assert any("'file:///etc/hostname'" in n and "absolute or has a URI scheme" in n for n in notes)
    assert any("'../../../outside.png'" in n and "leaves the mesh's package" in n for n in notes)
    assert any("'missing.png'" in n and "file not found" in n for n in notes)
    report = validate(tmp_path / "out", select=["schema", "integrity"])  # textures are listed
    assert [f for f in report.findings if f.severity == "error"] == []


def test_texture_uri_rules() -> None:
    assert texture_uri("package://p/m/a.dae", "t/x.png") == "package://p/m/t/x.png"
    assert texture_uri("package://p/m/a.dae", "..\\t\\x.png") == "package://p/t/x.png"
    assert texture_uri("../meshes/a.dae", "./x%20y.png") == "../meshes/x y.png"
    for bad in ("file:///x.png", "/abs/x.png", "http://h/x.png", "C:/x.png"):
        with pytest.raises(PathEscapeError):
            texture_uri("package://p/m/a.dae", bad)
    with pytest.raises(PathEscapeError, match="leaves the mesh's package"):
        texture_uri("package://p/m/a.dae", "../../x.png")


@pytest.mark.realdata
@pytest.mark.parametrize(
    "urdf",
    [
        "ur5/robots/ur_description/urdf/ur5_robot.urdf",
        "franka_panda/robots/panda_description/urdf/panda.urdf",
        "dobot_cr5/dobot_description/urdf/cr5_robot.urdf",
    ],
)
def test_real_dae_meshes_have_no_textures(real: Path, urdf: str) -> None:
    """Every real COLLADA mesh is scanned; none names an image (empty <library_images/>)."""
    pkg = (real / urdf).parents[1]
    daes = sorted(pkg.rglob("*.dae"))
    assert daes
    assert [dae_texture_refs(p) for p in daes] == [[] for _ in daes]

"""``package://`` URIs resolved like ROS and yourdfpy: URDF ancestors, ROS_PACKAGE_PATH, fallback.

Each test builds its folder layout in ``tmp_path`` and checks that the copied mesh is the file it
placed (its bytes) and that the provenance says where and how the package was found.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.errors import RobogsError
from robogs.format.packages import find_packages, package_uris


def _stl(path: Path, scale: float) -> bytes:
    """A binary STL tetrahedron of edge ``scale`` m (its bytes identify the file)."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * scale
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = bytearray(b"\0" * 80 + struct.pack("<I", len(faces)))
    for f in faces:
        data += struct.pack("<3f", 0, 0, 0)
        for i in f:
            data += struct.pack("<3f", *v[i])
        data += b"\0\0"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(bytes(data))
    return bytes(data)


def _urdf(pkg: str) -> str:
    return f"""<robot name="r"><link name="base"><visual><geometry>
<mesh filename="package://{pkg}/meshes/base.stl"/></geometry></visual></link>
<link name="l1"/><joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"""


def _package(folder: Path, name: str, scale: float) -> bytes:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "package.xml").write_text(f"<package format='3'><name>{name}</name></package>")
    return _stl(folder / "meshes" / "base.stl", scale)


def _log(path: Path) -> Path:
    t = np.arange(20) * 0.01
    rows = ["t_s,q0"] + [f"{a:.2f},{0.1 * a:.6f}" for a in t]
    path.write_text("\n".join(rows) + "\n")
    return path


def _convert(tmp: Path, urdf: Path, **kw) -> dict:
    ds = convert_path(_log(tmp / "log.csv"), tmp / "out", options=ConvertOptions(urdf=urdf, **kw))
    copied = (ds.root / "robot" / "meshes" / "base.stl").read_bytes()
    return {"prov": ds.manifest["provenance"]["robot"], "mesh": copied}


def test_package_found_only_on_ros_package_path(tmp_path: Path, monkeypatch) -> None:
    want = _package(tmp_path / "ws" / "src" / "vendor" / "my_arm_description", "my_arm", 0.2)
    _package(tmp_path / "ws" / "src" / "other_pkg", "other", 0.5)  # a decoy on the path
    urdf = tmp_path / "elsewhere" / "robot.urdf"
    urdf.parent.mkdir()
    urdf.write_text(_urdf("my_arm"))
    monkeypatch.setenv("ROS_PACKAGE_PATH", f"{tmp_path / 'nowhere'}:{tmp_path / 'ws' / 'src'}")
    got = _convert(tmp_path, urdf)
    assert got["mesh"] == want
    pkg = got["prov"]["packages"]["my_arm"]
    assert pkg == {
        "path": str((tmp_path / "ws/src/vendor/my_arm_description").resolve()),
        "how": "ROS_PACKAGE_PATH",
    }
    assert got["prov"]["mesh_files"] == {
        "package://my_arm/meshes/base.stl": str(
            (tmp_path / "ws/src/vendor/my_arm_description/meshes/base.stl").resolve()
        )
    }
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "nowhere"))
    with pytest.raises(RobogsError, match="ROS_PACKAGE_PATH") as ei:
        convert_path(tmp_path / "log.csv", tmp_path / "out2", options=ConvertOptions(urdf=urdf))
    assert "--package my_arm=FOLDER" in str(ei.value)


def test_ancestor_package_xml_wins_over_ros_package_path(tmp_path: Path, monkeypatch) -> None:
    want = _package(tmp_path / "src" / "arm_desc", "my_arm", 0.1)  # folder name != package name
    urdf = tmp_path / "src" / "arm_desc" / "urdf" / "robot.urdf"
    urdf.parent.mkdir()
    urdf.write_text(_urdf("my_arm"))
    _package(tmp_path / "env" / "my_arm", "my_arm", 0.7)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "env"))
    got = _convert(tmp_path, urdf)
    assert got["mesh"] == want
    assert got["prov"]["packages"]["my_arm"]["how"] == "package.xml in a URDF ancestor"
    # --package still wins
    other = _package(tmp_path / "mine", "my_arm", 0.3)
    ds = convert_path(
        tmp_path / "log.csv",
        tmp_path / "out3",
        options=ConvertOptions(urdf=urdf, package_roots={"my_arm": tmp_path / "mine"}),
    )
    assert (ds.root / "robot/meshes/base.stl").read_bytes() == other
    assert ds.manifest["provenance"]["robot"]["packages"]["my_arm"]["how"] == "--package"


def test_search_order_without_package_xml(tmp_path: Path) -> None:
    _stl(tmp_path / "a" / "my_arm" / "meshes" / "base.stl", 1.0)
    urdf = tmp_path / "a" / "b" / "robot.urdf"
    urdf.parent.mkdir(parents=True)
    uris = package_uris(_urdf("my_arm"))
    assert uris == {"my_arm": ["meshes/base.stl"]}
    found = find_packages(uris, urdf.parent, env="")
    assert found["my_arm"].path == (tmp_path / "a" / "my_arm").resolve()
    assert found["my_arm"].how == "folder name among the URDF's ancestors"
    # yourdfpy's fallback: the package name appears nowhere, an ancestor holds the rest
    _stl(tmp_path / "c" / "meshes" / "base.stl", 1.0)
    deep = tmp_path / "c" / "x" / "y"
    deep.mkdir(parents=True)
    found = find_packages(package_uris(_urdf("pip-installed")), deep, env="")
    assert found["pip-installed"].path == (tmp_path / "c").resolve()
    assert "yourdfpy" in found["pip-installed"].how
    assert find_packages(package_uris(_urdf("absent")), urdf.parent, env="") == {}

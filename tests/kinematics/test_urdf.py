"""Safe URDF loading: real robots with their meshes, and hostile or broken inputs."""

from __future__ import annotations

import collections
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from robogs.format.errors import FormatError, InputError, PathEscapeError
from robogs.format.urdf import default_allowed_root, load_urdf, mesh_refs, resolve_mesh_uri

from .conftest import REAL_URDFS

# --------------------------------------------------------------------------- helpers


def urdf_text(mesh_uri: str | None = None, extra: str = "", name: str = "r") -> str:
    visual = (
        f'<visual><geometry><mesh filename="{mesh_uri}"/></geometry></visual>' if mesh_uri else ""
    )
    return f"""<?xml version="1.0"?>
<robot name="{name}">
  <link name="base">{visual}</link>
  <link name="arm"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  {extra}
</robot>
"""


def write_robot(folder: Path, mesh_uri: str | None, extra: str = "") -> Path:
    (folder / "urdf").mkdir(parents=True, exist_ok=True)
    p = folder / "urdf" / "r.urdf"
    p.write_text(urdf_text(mesh_uri, extra))
    return p


def link_extents(urdf) -> dict[str, np.ndarray]:
    """Bounding-box extents of the visual geometry attached to each link, in the link frame."""
    g = urdf.scene.graph
    parents = g.transforms.parents
    per: dict[str, list] = collections.defaultdict(list)
    for node in g.nodes_geometry:
        link = parents[node]
        T = g.get(node, link)[0]
        per[link].append(urdf.scene.geometry[g[node][1]].copy().apply_transform(T))
    return {k: trimesh.util.concatenate(v).extents for k, v in per.items()}


# --------------------------------------------------------------------------- real robots


@pytest.mark.realdata
@pytest.mark.parametrize("name", sorted(REAL_URDFS))
def test_real_urdf_loads_with_meshes(name: str, real_urdf_args) -> None:
    path, root, pkgs = real_urdf_args(name)
    urdf = load_urdf(path, root=root, package_roots=pkgs)
    text = path.read_text()
    # independent count of <mesh> elements, per kind, straight from the XML text
    n_mesh = len(re.findall(r"<mesh\s", text))
    refs = urdf.robogs_mesh_refs
    assert len(refs) == n_mesh and n_mesh >= 14
    root_r = root.resolve()
    for ref in refs:
        assert ref.path is not None and ref.path.is_file()
        assert ref.path.is_relative_to(root_r)
        assert ref.path.name == ref.uri.rsplit("/", 1)[-1]
    visual_links = {r.link for r in refs if r.kind == "visual"}
    collision_links = {r.link for r in refs if r.kind == "collision"}
    ext = link_extents(urdf)
    # every link with a visual mesh got geometry, and each is a plausible size in metres
    assert visual_links <= set(ext)
    for link in visual_links:
        assert 0.05 < ext[link].max() < 1.0, (link, ext[link])
    assert collision_links <= set(urdf.collision_scene.graph.transforms.parents.values())
    span = urdf.scene.extents.max()
    assert 0.5 < span < 2.0


@pytest.mark.realdata
def test_real_dobot_resolves_package_by_search_with_default_root(real_urdf_args) -> None:
    path, _, _ = real_urdf_args("dobot_cr5")
    # default root = .../dobot_description (the URDF sits in urdf/), found via package.xml
    assert default_allowed_root(path) == path.resolve().parents[1]
    urdf = load_urdf(path)
    assert len(urdf.robogs_mesh_refs) == 14
    assert urdf.robogs_mesh_refs[0].path.is_file()


@pytest.mark.realdata
def test_real_ur5_unknown_package_has_hint(real_urdf_args) -> None:
    path, root, _ = real_urdf_args("ur5")
    with pytest.raises(FormatError) as ei:
        load_urdf(path, root=root)
    msg = str(ei.value)
    assert "example-robot-data" in msg and "package_roots" in msg and "base_link" in msg
    # without meshes the same file loads and keeps its kinematics
    urdf = load_urdf(path, root=root, load_meshes=False)
    assert urdf.num_actuated_joints == 6


# --------------------------------------------------------------------------- inline meshes


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".dae"])
def test_inline_mesh_formats_relative_and_package(tmp_path: Path, suffix: str) -> None:
    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    mesh_dir = tmp_path / "meshes"
    mesh_dir.mkdir()
    mesh_file = mesh_dir / f"box{suffix}"
    box.export(mesh_file)
    (tmp_path / "package.xml").write_text("<package><name>mypkg</name></package>")
    for uri in (f"../meshes/box{suffix}", f"package://mypkg/meshes/box{suffix}"):
        p = write_robot(tmp_path, uri)
        urdf = load_urdf(p)
        ext = link_extents(urdf)["base"]
        assert np.abs(np.sort(ext) - [0.1, 0.2, 0.3]).max() < 1e-6
        assert urdf.robogs_mesh_refs[0].path == mesh_file.resolve()


def test_package_found_by_folder_name_and_explicit_map(tmp_path: Path) -> None:
    pkg = tmp_path / "robot" / "pkgA"
    (pkg / "m").mkdir(parents=True)
    urdf_path = tmp_path / "robot" / "r.urdf"
    assert (
        resolve_mesh_uri("package://pkgA/m/x.stl", urdf_path, tmp_path)
        == (pkg / "m/x.stl").resolve()
    )
    other = tmp_path / "elsewhere"
    other.mkdir()
    got = resolve_mesh_uri("package://pkgA/x.stl", urdf_path, tmp_path, {"pkgA": other})
    assert got == (other / "x.stl").resolve()


def test_ambiguous_package(tmp_path: Path) -> None:
    (tmp_path / "a" / "pkg").mkdir(parents=True)
    (tmp_path / "b" / "pkg").mkdir(parents=True)
    with pytest.raises(FormatError, match="ambiguous"):
        resolve_mesh_uri("package://pkg/x.stl", tmp_path / "r.urdf", tmp_path)


def test_missing_mesh_names_link_and_uri(tmp_path: Path) -> None:
    p = write_robot(tmp_path, "../meshes/nothere.stl")
    with pytest.raises(FormatError) as ei:
        load_urdf(p)
    err = ei.value
    assert err.path == str(p)
    assert "base" in err.where and "../meshes/nothere.stl" in err.where
    assert err.hint and "load_meshes=False" in err.hint
    urdf = load_urdf(p, load_meshes=False)
    assert urdf.actuated_joint_names == ["j1"]


# --------------------------------------------------------------------------- hostile inputs


@pytest.mark.parametrize(
    "uri",
    [
        "../../etc/passwd",
        "../../../../../../../../etc/passwd",
        "file:///etc/passwd",
        "/etc/passwd",
        "http://example.com/mesh.stl",
        "C:\\Windows\\mesh.stl",
        "package://pkg/../../../etc/passwd",
        "package://pkg//etc/passwd",
    ],
)
def test_uri_escapes_are_refused(tmp_path: Path, uri: str) -> None:
    (tmp_path / "pkg").mkdir()
    p = write_robot(tmp_path, uri)
    with pytest.raises(PathEscapeError) as ei:
        load_urdf(p, root=tmp_path)
    assert ei.value.path == str(p) and uri in ei.value.where


def test_symlinks_out_of_root_are_refused(tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    trimesh.creation.box().export(outside / "box.stl")
    robot = tmp_path / "robot"
    (robot / "meshes").mkdir(parents=True)
    (robot / "meshes" / "box.stl").symlink_to(outside / "box.stl")
    p = write_robot(robot, "../meshes/box.stl")
    with pytest.raises(PathEscapeError):
        load_urdf(p, root=robot)
    (robot / "evilpkg").symlink_to(outside, target_is_directory=True)
    p = write_robot(robot, "package://evilpkg/box.stl")
    with pytest.raises(PathEscapeError):
        load_urdf(p, root=robot)


BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
 <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
 <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
 <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
 <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<robot name="&lol9;"><link name="base"/></robot>
"""

XXE = """<?xml version="1.0"?>
<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>
<robot name="r"><link name="&x;"/></robot>
"""


@pytest.mark.parametrize("text", [BILLION_LAUGHS, XXE], ids=["billion_laughs", "xxe"])
def test_entity_declarations_are_refused(tmp_path: Path, text: str) -> None:
    p = tmp_path / "evil.urdf"
    p.write_text(text)
    with pytest.raises(FormatError, match="entities"):
        load_urdf(p)


@pytest.mark.parametrize("padding", [0, 100_000])
def test_entity_in_collada_is_refused(tmp_path: Path, padding: int) -> None:
    evil = BILLION_LAUGHS.replace("robot", "COLLADA")
    head, _, rest = evil.partition("\n")
    # a long comment before the DOCTYPE must not hide it
    (tmp_path / "m.dae").write_text(head + "\n<!--" + "x" * padding + "-->\n" + rest)
    p = tmp_path / "r.urdf"
    p.write_text(urdf_text("m.dae"))
    with pytest.raises(FormatError, match="entities"):
        load_urdf(p)


def test_truncated_and_wrong_xml(tmp_path: Path) -> None:
    full = urdf_text()
    p = tmp_path / "t.urdf"
    p.write_text(full[: len(full) // 2])
    with pytest.raises(FormatError) as ei:
        load_urdf(p)
    assert "well-formed" in ei.value.message and ei.value.where.startswith("line")
    p.write_text("<sdf version='1.6'><model name='m'/></sdf>")
    with pytest.raises(FormatError, match="expected <robot>"):
        load_urdf(p)
    p.write_bytes(b"\x00\x01binary")
    with pytest.raises(FormatError):
        load_urdf(p)
    with pytest.raises(InputError, match="not found"):
        load_urdf(tmp_path / "absent.urdf")


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (
            '<joint name="j2" type="fixed"><parent link="arm"/><child link="ghost"/></joint>',
            "unknown link",
        ),
        ('<link name="floating_island"/>', "exactly one root"),
        (
            '<joint name="j2" type="fixed"><parent link="base"/><child link="arm"/></joint>',
            "child of two",
        ),
        (
            '<joint name="j2" type="hinge"><parent link="arm"/><child link="x"/></joint><link name="x"/>',
            "unknown joint type",
        ),
        ('<joint name="j2" type="fixed"><parent link="arm"/></joint>', "child link"),
        ('<link name="arm"/>', "duplicate link"),
    ],
)
def test_broken_trees(tmp_path: Path, extra: str, match: str) -> None:
    p = tmp_path / "b.urdf"
    p.write_text(urdf_text(extra=extra))
    with pytest.raises(FormatError, match=match):
        load_urdf(p, load_meshes=False)


def test_bad_numbers_are_format_errors(tmp_path: Path) -> None:
    p = tmp_path / "n.urdf"
    p.write_text(urdf_text().replace('xyz="0 0 0.1"', 'xyz="0 zero 0.1"'))
    with pytest.raises(FormatError, match="could not be parsed"):
        load_urdf(p, load_meshes=False)


def test_corrupt_mesh_is_a_format_error(tmp_path: Path) -> None:
    (tmp_path / "bad.stl").write_bytes(b"solid x\n facet normal 0 0 1\n garbage")
    p = tmp_path / "r.urdf"
    p.write_text(urdf_text("bad.stl"))
    with pytest.raises(FormatError) as ei:
        load_urdf(p)
    assert ei.value.path == str(p) and "bad.stl" in ei.value.where


def test_mesh_refs_lists_visual_then_collision(tmp_path: Path) -> None:
    extra = (
        '<link name="c"><collision><geometry><mesh filename="c.stl"/></geometry></collision></link>'
    )
    extra += '<joint name="jc" type="fixed"><parent link="arm"/><child link="c"/></joint>'
    p = tmp_path / "r.urdf"
    p.write_text(urdf_text("v.stl", extra=extra))
    urdf = load_urdf(p, load_meshes=False)
    refs = mesh_refs(urdf)
    assert [(r.link, r.kind, r.uri) for r in refs] == [
        ("base", "visual", "v.stl"),
        ("c", "collision", "c.stl"),
    ]

"""Units of ``robogs physics init``: URDF collision shapes, plane fits, provenance records."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robogs.format.errors import InputError
from robogs.physics.init.priors import box_mass_properties, mesh_mass_properties
from robogs.physics.init.provenance import Entry, parse_assignment, record, rows, set_value
from robogs.physics.init.pusher import collision_shapes, shape_distance
from robogs.physics.init.support import fit_plane, plane_from_mesh

_URDF = """<robot name="shapes">
<link name="root"/>
<link name="a"><collision><origin xyz="0.1 0 0"/><geometry><sphere radius="0.01"/></geometry>
</collision></link>
<link name="b"><collision><origin rpy="1.5707963267948966 0 0"/>
<geometry><cylinder radius="0.02" length="0.1"/></geometry></collision></link>
<link name="c"/>
<link name="d"><collision><geometry><box size="0.01 0.2 0.05"/></geometry></collision></link>
<link name="e"><collision><geometry><mesh filename="rod.stl"/></geometry></collision></link>
<joint name="ja" type="fixed"><parent link="root"/><child link="a"/></joint>
<joint name="jb" type="fixed"><parent link="root"/><child link="b"/></joint>
<joint name="jc" type="fixed"><parent link="root"/><child link="c"/></joint>
<joint name="jd" type="fixed"><parent link="root"/><child link="d"/></joint>
<joint name="je" type="fixed"><parent link="root"/><child link="e"/></joint>
</robot>
"""


def test_collision_shapes_as_swept_spheres(tmp_path: Path) -> None:
    import trimesh

    from robogs.format.urdf import load_urdf

    path = tmp_path / "shapes.urdf"
    path.write_text(_URDF)
    rod = trimesh.creation.cylinder(radius=0.01, height=0.1, sections=64)
    shapes = {
        s.link: s
        for s in collision_shapes(
            load_urdf(path, load_meshes=False), path, mesh_loader=lambda f: rod
        )
    }
    a, b, d, e = (shapes[k] for k in "abde")
    assert a.radius == 0.01 and a.length == 0.0 and np.allclose(a.a, [0.1, 0, 0])
    assert b.radius == 0.02 and b.length == pytest.approx(0.1)
    assert np.allclose(np.abs(b.b - b.a), [0, 0.1, 0], atol=1e-12)  # rpy x 90 deg: axis on y
    assert "c" not in shapes  # no collision geometry
    assert d.radius == 0.005 and d.length == pytest.approx(0.19)  # long axis minus thickness
    assert e.radius == pytest.approx(0.01, abs=1e-9) and e.length == pytest.approx(0.08)
    # distance to a swept sphere: along the axis past an end, and beside it
    assert shape_distance(np.array([0.0, 0.2, 0.0]), b.a, b.b, b.radius) == pytest.approx(0.13)
    assert shape_distance(np.array([0.05, 0.01, 0.0]), b.a, b.b, b.radius) == pytest.approx(0.03)


def test_capsule_collisions_are_read_from_the_xml(tmp_path: Path) -> None:
    """yourdfpy refuses ``<capsule>``: robogs' URDF loader keeps it (axis along origin z)."""
    from robogs.format.urdf import capsules, load_urdf

    path = tmp_path / "cap.urdf"
    path.write_text(
        '<robot name="r"><link name="c"><collision>'
        '<origin xyz="0 0 -0.03" rpy="1.5707963267948966 0 0"/>'
        '<geometry><capsule radius="0.015" length="0.06"/></geometry></collision></link></robot>'
    )
    urdf = load_urdf(path, load_meshes=False)
    ((cap,),) = [capsules(urdf)]
    T, r, length = cap.origin, cap.radius, cap.length
    assert cap.link == "c" and r == 0.015 and length == 0.06
    (shape,) = collision_shapes(urdf, path)
    assert shape.kind == "capsule" and shape.radius == 0.015 and shape.length == pytest.approx(0.06)
    assert np.allclose(T[:3, 3], [0, 0, -0.03]) and np.allclose(T[:3, 2], [0, -1, 0], atol=1e-12)


def test_robust_plane_fit_ignores_lifted_samples() -> None:
    rng = np.random.default_rng(0)
    n = np.array([0.03, -0.02, 1.0])
    n /= np.linalg.norm(n)
    d = 0.42
    xy = rng.uniform(-0.3, 0.3, (300, 2))
    z = (d - xy @ n[:2]) / n[2] + rng.normal(0, 5e-4, 300)
    pts = np.column_stack([xy, z])
    pts[:30, 2] += 0.05  # held above the table
    plane = fit_plane(pts)
    assert np.degrees(np.arccos(plane.normal @ n)) < 0.1
    assert abs(plane.offset - d) < 2e-4 and plane.n_points == 270
    # a single resting spot: the normal must come from the hint
    spot = np.tile([0.1, 0.2, 0.3], (50, 1)) + rng.normal(0, 5e-4, (50, 3))
    with pytest.raises(InputError, match="too little to fit a plane"):
        fit_plane(spot)
    assert np.allclose(fit_plane(spot, normal_hint=[0, 0, -2]).normal, [0, 0, 1])


def test_table_top_under_the_object() -> None:
    import trimesh

    table = trimesh.creation.box(extents=(1.0, 0.8, 0.04))
    v = np.asarray(table.vertices) + [0.5, 0.0, 0.7]
    plane = plane_from_mesh(v, np.asarray(table.faces), np.array([0.6, 0.1, 0.75]))
    assert plane is not None and np.allclose(plane.normal, [0, 0, 1])
    assert plane.offset == pytest.approx(0.72)
    assert plane_from_mesh(v, np.asarray(table.faces), np.array([2.0, 0.0, 0.75])) is None


def test_mass_properties_of_a_box_mesh_match_the_formula() -> None:
    import trimesh

    size = (0.1, 0.07, 0.05)
    m_box, i_box = box_mass_properties(size, 1000.0)
    m_mesh, com, i_mesh, note = mesh_mass_properties(trimesh.creation.box(extents=size), 1000.0)
    assert m_box == pytest.approx(0.35) and m_mesh == pytest.approx(m_box, rel=1e-9)
    assert np.allclose(i_mesh, i_box, rtol=1e-9, atol=1e-15) and np.allclose(com, 0) and not note


def test_provenance_rows_say_when_a_fit_changed_a_value() -> None:
    doc = {"objects": {"box": {"mass_kg": 0.2, "size_m": [0.1, 0.07, 0.05]}}, "revision": 1}
    doc = record(
        doc,
        [
            Entry("objects.box.mass_kg", 0.2, "prior(wood)", None, "", (0.1, 0.3)),
            Entry("objects.box.size_m", [0.1, 0.07, 0.05], "estimated", [1e-3, 2e-3, 5e-4]),
        ],
    )
    r = {k: s for k, _, s in rows(doc)}
    assert r["objects.box.mass_kg"].startswith("prior(wood) in [0.1, 0.3]")
    assert r["objects.box.size_m"].startswith("estimated ± [1.0, 2.0, 0.5] mm")
    fitted = set_value(doc, "objects.box.mass_kg", 0.25)
    fitted["revision"] = 2
    r = {k: s for k, _, s in rows(fitted)}
    assert r["objects.box.mass_kg"].startswith("revision 2 (replaced 0.2 from prior(wood)")
    assert set_value(doc, "objects.box.size_m.1", 0.08)["objects"]["box"]["size_m"][1] == 0.08
    assert doc["objects"]["box"]["size_m"][1] == 0.07  # set_value copies
    assert parse_assignment("a.b=[1, 2]") == ("a.b", [1, 2])
    assert parse_assignment("a.b=wood") == ("a.b", "wood")
    with pytest.raises(InputError, match="not an index"):
        set_value(doc, "objects.box.size_m.7", 1.0)
    with pytest.raises(InputError, match="KEY=VALUE"):
        parse_assignment("objects..mass_kg=1")

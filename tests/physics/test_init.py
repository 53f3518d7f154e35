"""``robogs physics init``: geometry, support plane, pusher and priors against a known scene.

Oracles: :mod:`init_scene` writes a box of known size on a tilted (2.5 deg), raised plane,
pushed along its x and then its y axis by a gantry whose ``tool`` link carries a known collision
sphere or vertical cylinder 4 cm below the link origin; poses carry 0.5 mm noise. The table's
priors are checked against volume x the table's density, computed here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from init_scene import write_scene

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.physics.init import MATERIALS, init_physics, set_physics_values

XY = np.array([[0.40, -0.10], [0.70, 0.20], [0.55, 0.05], [0.45, 0.15]])  # workspace points


def _plane_err_mm(physics: dict, truth) -> np.ndarray:
    t = physics["objects"]["table"]
    n = np.asarray(t["normal"])
    d = n @ np.asarray(t["point_m"])
    z = (d - XY[:, 0] * n[0] - XY[:, 1] * n[1]) / n[2]
    return np.abs(z - truth.plane_z(XY)) * 1000.0


@pytest.fixture(scope="module")
def estimated(tmp_path_factory) -> tuple[Path, object, dict]:
    """No box size anywhere: size from the data, plane from the table mesh."""
    root = tmp_path_factory.mktemp("init") / "est"
    truth = write_scene(root, seed=3)
    res = init_physics(root, objects=["box=material:wood"])
    return root, truth, res


def test_size_estimated_from_rest_height_and_pushes(estimated) -> None:
    _, truth, res = estimated
    box = res.physics["objects"]["box"]
    err_mm = np.abs(np.asarray(box["size_m"]) - truth.size) * 1000.0
    assert err_mm.max() < 5.0, err_mm
    src = res.physics["sources"]["objects.box.size_m"]
    assert src["source"] == "estimated"
    sigma = np.asarray(src["sigma"]) * 1000.0
    assert np.all(sigma > 0) and np.all(sigma < 2.0)
    assert np.all(err_mm < 5 * sigma + 0.5)  # the stated uncertainty is honest


def test_initialised_dataset_validates(estimated, capsys) -> None:
    root, _, _ = estimated
    rc, out, _ = _cli(["validate", str(root)], capsys)
    assert rc == 0 and "0 errors" in out


def test_plane_from_the_table_mesh(estimated) -> None:
    _, truth, res = estimated
    assert _plane_err_mm(res.physics, truth).max() < 2.0
    assert res.physics["sources"]["objects.table.plane_z_m"]["source"] == "mesh"
    assert any("tilted 2.5 deg" in n for n in res.notes)


def test_pusher_is_the_tool_sphere_from_the_urdf(estimated) -> None:
    _, truth, res = estimated
    p = res.physics["objects"]["pusher"]
    assert p["link"] == "tool" and p["shape"] == "sphere"
    assert p["radius_m"] == truth.radius  # exactly the URDF value
    assert p["length_m"] == 0.0
    assert np.allclose(p["offset_m"], [0.0, 0.0, -0.04], atol=1e-12)
    assert res.physics["sources"]["objects.pusher.radius_m"]["source"] == "urdf"


def test_mass_is_volume_times_the_material_density(estimated) -> None:
    _, _, res = estimated
    box = res.physics["objects"]["box"]
    wood = MATERIALS["wood"]
    sx, sy, sz = box["size_m"]
    m = sx * sy * sz * wood.density_kgm3
    assert box["mass_kg"] == pytest.approx(m, rel=1e-12)
    assert np.allclose(
        np.diag(box["inertia_kgm2"]),
        [m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12],
        rtol=1e-12,
    )
    src = res.physics["sources"]["objects.box.mass_kg"]
    assert src["source"] == "prior(wood)"
    assert src["bounds"] == pytest.approx([sx * sy * sz * b for b in wood.density_bounds])
    assert box["friction_dynamic"] == wood.friction_dynamic


def test_plane_fitted_from_resting_bottom_faces(tmp_path: Path) -> None:
    truth = write_scene(tmp_path / "ann", seed=4, table_mesh=False, box_annotation=True)
    res = init_physics(tmp_path / "ann", objects=["box=material:steel"])
    box = res.physics["objects"]["box"]
    assert box["size_m"] == pytest.approx(truth.size.tolist(), abs=1e-12)
    assert res.physics["sources"]["objects.box.size_m"]["source"] == "annotation"
    assert _plane_err_mm(res.physics, truth).max() < 2.0
    normal = np.asarray(res.physics["objects"]["table"]["normal"])
    assert np.degrees(np.arccos(normal @ truth.normal)) < 0.3
    assert res.physics["sources"]["objects.table.plane_z_m"]["source"] == "estimated"


def test_object_mesh_gives_size_and_mass(tmp_path: Path) -> None:
    truth = write_scene(tmp_path / "mesh", seed=5, table_mesh=False, box_mesh=True)
    res = init_physics(tmp_path / "mesh", objects=["box=material:aluminium"])
    box = res.physics["objects"]["box"]
    assert box["size_m"] == pytest.approx(truth.size.tolist(), abs=1e-6)  # float32 PLY
    vol = float(np.prod(truth.size))
    assert box["mass_kg"] == pytest.approx(vol * MATERIALS["aluminium"].density_kgm3, rel=1e-5)
    assert res.physics["sources"]["objects.box.size_m"]["source"] == "mesh"


def test_vertical_cylinder_pusher(tmp_path: Path) -> None:
    truth = write_scene(tmp_path / "cyl", seed=6, pusher="cylinder", radius=0.015)
    res = init_physics(tmp_path / "cyl")
    p = res.physics["objects"]["pusher"]
    assert p["radius_m"] == 0.015 and p["length_m"] == 0.0 and p["link"] == "tool"
    # the model's point lies on the cylinder axis (tool z in [-0.08, 0]) near the box centre
    assert p["offset_m"][:2] == [0.0, 0.0] and -0.045 < p["offset_m"][2] < -0.035
    err_mm = np.abs(np.asarray(res.physics["objects"]["box"]["size_m"]) - truth.size) * 1000.0
    assert err_mm.max() < 5.0
    assert res.physics["sources"]["objects.box.mass_kg"]["source"] == "prior(plastic, default)"


def test_no_robot_but_ee_poses_and_a_user_pusher(tmp_path: Path) -> None:
    truth = write_scene(tmp_path / "ee", seed=11, robot=False, ee_tip=True)
    res = init_physics(tmp_path / "ee", objects=["pusher=sphere:0.012"])
    p = res.physics["objects"]["pusher"]
    assert p["link"] == "tip" and p["radius_m"] == 0.012 and "offset_m" not in p
    assert res.physics["sources"]["objects.pusher.radius_m"]["source"] == "user"
    err_mm = np.abs(np.asarray(res.physics["objects"]["box"]["size_m"]) - truth.size) * 1000.0
    assert err_mm.max() < 5.0


def test_unknown_material_lists_the_known_ones() -> None:
    from robogs.physics.init import MaterialTable, PriorProvider

    assert isinstance(MaterialTable(), PriorProvider)
    with pytest.raises(InputError, match="known materials: aluminium, cardboard, foam"):
        MaterialTable().material("unobtainium")
    assert MaterialTable().material("Aluminum") is MATERIALS["aluminium"]


def test_compare_runs_on_the_initialised_dataset(estimated, tmp_path: Path) -> None:
    """The model, from the initialised physics alone, follows the pushes to a few mm; the same
    dataset with the pusher offset removed (the pusher 4 cm too high) does not move the box."""
    import shutil

    from robogs.physics.api import compare

    root, _, _ = estimated
    good = compare(root, dt=5e-3, mask_frames=0)
    assert np.isfinite(good.rms_mm) and good.rms_mm < 8.0, good.rms_mm
    bad_root = tmp_path / "bad"
    shutil.copytree(root, bad_root)
    set_physics_values(bad_root, ["objects.pusher.offset_m=[0, 0, 0]"])
    bad = compare(bad_root, dt=5e-3, mask_frames=0)
    assert bad.rms_mm > 5 * good.rms_mm, (good.rms_mm, bad.rms_mm)


# ---------------------------------------------------------------------------- CLI


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    from robogs.cli.main import main

    rc = main(argv)
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_cli_init_show_set(tmp_path: Path, capsys) -> None:
    root = tmp_path / "cli"
    write_scene(root, seed=7, table_mesh=False, box_annotation=True)
    rc, out, _ = _cli(["physics", "init", str(root), "--object", "box=material:wood"], capsys)
    assert rc == 0
    assert "objects.box.size_m" in out and "annotation" in out and "prior(wood)" in out
    assert "wrote physics.json revision 1" in out
    rc, _, err = _cli(["physics", "init", str(root)], capsys)
    assert rc == 2 and "already has a physics.json" in err and "--force" in err
    rc, out, _ = _cli(
        ["physics", "set", str(root), "objects.box.mass_kg=0.35", "objects.box.note=hollow"], capsys
    )
    assert rc == 0
    doc = Dataset.open(root).physics()
    assert doc["revision"] == 2 and doc["parent_revision"] == 1
    assert doc["objects"]["box"]["mass_kg"] == 0.35 and doc["objects"]["box"]["note"] == "hollow"
    assert doc["sources"]["objects.box.mass_kg"]["source"] == "user"
    rc, out, _ = _cli(["physics", "set", str(root), "objects.box.size_m.2=0.06"], capsys)
    doc = Dataset.open(root).physics()
    assert rc == 0 and doc["revision"] == 3 and doc["objects"]["box"]["size_m"][2] == 0.06
    assert doc["sources"]["objects.box.size_m"]["source"] == "user"
    rc, out, _ = _cli(["physics", "show", str(root)], capsys)
    line = next(ln for ln in out.splitlines() if ln.startswith("objects.box.mass_kg"))
    assert "0.35" in line and "user" in line
    rc, out, _ = _cli(["physics", "show", str(root), "--json"], capsys)
    assert json.loads(out)["revision"] == 3
    rc, _, err = _cli(["physics", "set", str(root), "objects.box.mass_kg=-1"], capsys)
    assert rc == 2 and "mass_kg" in err and len(err.strip().splitlines()) == 1
    rc, _, err = _cli(["physics", "set", str(root), "objects.box.mass_kg.x=1"], capsys)
    assert rc == 2 and "is a value, not a group" in err
    rc, out, _ = _cli(["physics", "init", str(root), "--force"], capsys)
    assert rc == 0 and Dataset.open(root).physics()["revision"] == 4
    assert Dataset.open(root).physics_history() == [1, 2, 3]


@pytest.mark.parametrize(
    ("kw", "args", "words"),
    [
        (dict(objects=False), [], ("no tracked object", "robogs convert", "--topic object_pose")),
        (dict(robot=False), [], ("no robot", "robogs convert", "--urdf")),
        ({}, ["--object", "box=material:unobtainium"], ("unknown material", "wood")),
        ({}, ["--object", "box=box:0.1x0.2"], ("cannot read box size",)),
        ({}, ["--object", "cup=material:wood"], ("cup", "tracked objects: box")),
    ],
)
def test_cli_bad_input_is_one_line(tmp_path: Path, capsys, kw, args, words) -> None:
    root = tmp_path / "bad"
    write_scene(root, seed=8, **kw)
    rc, out, err = _cli(["physics", "init", str(root), *args], capsys)
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    for w in words:
        assert w in err, err


def test_cli_missing_urdf_file(tmp_path: Path, capsys) -> None:
    root = tmp_path / "nourdf"
    write_scene(root, seed=9)
    m = json.loads((root / "manifest.json").read_text())
    (root / "robot" / "robot.urdf").unlink()
    m["files"].pop("robot/robot.urdf")
    (root / "manifest.json").write_text(json.dumps(m))
    rc, _, err = _cli(["physics", "init", str(root)], capsys)
    assert rc == 2 and "URDF robot/robot.urdf is missing" in err and "--urdf" in err


def test_cli_no_size_and_no_plane_names_the_options(tmp_path: Path, capsys) -> None:
    root = tmp_path / "noplane"
    write_scene(root, seed=10, table_mesh=False)
    rc, _, err = _cli(["physics", "init", str(root)], capsys)
    assert rc == 2 and "table=plane:Z" in err and "box=box:LxWxH" in err
    rc, out, _ = _cli(["physics", "init", str(root), "--object", "table=plane:0.12"], capsys)
    assert rc == 0 and "user" in out


def test_synth_scene_pusher_and_box_recovered(tmp_path: Path) -> None:
    """The synthetic scene (an independent generator) states its pusher link and radius and its
    box in ``physics.json``; init from its data alone (``--force``) must find the same."""
    from robogs.synth.scene import synthesize

    root = tmp_path / "scene"
    synthesize(root, seed=0, size="small", progress=False)
    truth = Dataset.open(root).physics()
    res = init_physics(root, force=True)
    p, tool = res.physics["objects"]["pusher"], truth["contacts"]["tool"]
    assert p["link"] == tool["link"] and p["radius_m"] == pytest.approx(tool["radius_m"], abs=1e-6)
    assert res.physics["objects"]["box"]["size_m"] == pytest.approx(
        truth["objects"]["box"]["size_m"], abs=1e-6
    )
    top = truth["objects"]["table"]["top_z_m"]
    assert abs(res.physics["objects"]["table"]["plane_z_m"] - top) < 1e-4
    assert Dataset.open(root).physics()["joints"] == truth["joints"]  # kept on --force

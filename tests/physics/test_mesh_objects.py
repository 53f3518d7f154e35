"""Object meshes of a dataset reach the physics fit (issue 16, Deliver 1 and "Bad input").

Oracles:
* the synthetic scene writes its box as ``assets/box/mesh.ply``: the mesh IS the box (Hausdorff
  distance ~0), so the planar engine and its numbers stay: compare's RMS is the same, to the
  last digit, as on the same dataset with the mesh asset removed (the path before meshes were
  read) - a box misjudged as a mesh would switch to MuJoCo and change it;
* :func:`box_distance_m` against closed forms (a box grown by d: d; a cylinder inscribed in
  the box's footprint: the footprint corner's distance to the circle);
* the same dataset with the box's mesh replaced by a cylinder: ``auto`` picks MuJoCo, and the
  compiled model's object geom is a mesh whose volume is the hull's within 1e-6 relative;
* a non-convex tube with more hull vertices than ``MAX_HULL_VERTICES``: the substitution is
  printed by ``robogs fit`` and written into the revision note;
* a mesh path escaping the dataset root: a PathEscapeError naming the asset (``Dataset.mesh``).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError, PathEscapeError
from robogs.format.mjcf import MAX_HULL_VERTICES
from robogs.format.shapes import box_distance_m, object_shapes
from robogs.physics.engine import Engine, recording_backend
from robogs.physics.recording import load_recording

SIZE = (0.1, 0.08, 0.06)  # the synthetic scene's box (checked against physics.json below)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("mesh_objects") / "scene"
    synthesize(root, seed=0, size="small", progress=False)
    assert Dataset.open(root).physics()["objects"]["box"]["size_m"] == list(SIZE)
    return root


def _with_mesh(src: Path, dst: Path, mesh: trimesh.Trimesh) -> Path:
    """A copy of ``src`` whose box mesh asset is ``mesh`` (written through the dataset writer)."""
    shutil.copytree(src, dst)
    ds = Dataset.open(dst)
    with ds.edit() as w:
        w.write_bytes(ds.assets["box"]["mesh"], mesh.export(file_type="ply"))
        w.commit()
    return dst


def _without_mesh(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    m = json.loads((dst / "manifest.json").read_text())
    m["assets"]["box"].pop("mesh")
    (dst / "manifest.json").write_text(json.dumps(m))
    return dst


def test_box_distance_closed_forms() -> None:
    box = trimesh.creation.box(extents=SIZE)
    assert box_distance_m(box, SIZE) < 1e-12
    for d in (0.5e-3, 3e-3):  # every face pushed out by d: the farthest hull point is d away
        grown = trimesh.creation.box(extents=np.asarray(SIZE) + 2 * d)
        assert box_distance_m(grown, SIZE) == pytest.approx(d * np.sqrt(3), rel=1e-9)
        assert box_distance_m(trimesh.creation.box(extents=np.asarray(SIZE) - 2 * d), SIZE) == (
            pytest.approx(d * np.sqrt(3), rel=1e-9)
        )
    # a cylinder of radius 0.04 (the footprint's half-width) and the box's height: the box's
    # corner (0.05, 0.04) lies outside; its distance to the 256-gon's nearest edge, in closed
    # form for the polygon (the hull the distance is computed on)
    n, r = 256, 0.04
    cyl = trimesh.creation.cylinder(radius=r, height=SIZE[2], sections=n)
    corner = np.array([0.05, 0.04])
    ang = np.arctan2(corner[1], corner[0])
    k = np.floor(ang / (2 * np.pi / n))
    a, b = (
        r * np.array([np.cos(t), np.sin(t)]) for t in (k * 2 * np.pi / n, (k + 1) * 2 * np.pi / n)
    )
    t = np.clip(np.dot(corner - a, b - a) / np.dot(b - a, b - a), 0, 1)
    expect = np.linalg.norm(corner - (a + t * (b - a)))
    assert box_distance_m(cyl, SIZE) == pytest.approx(expect, rel=1e-9)
    # the verdict follows the budget: 3 mm out is a mesh at 2 mm, a box at 6 mm
    phys = {"objects": {"box": {"equation": "rigid", "size_m": list(SIZE), "mass_kg": 0.5}}}
    grown = trimesh.creation.box(extents=np.asarray(SIZE) + 2 * 3e-3)
    assert list(object_shapes(phys, {"box": grown}, 2.0).meshes) == ["box"]
    assert list(object_shapes(phys, {"box": grown}, 6.0).boxes) == ["box"]


def test_box_mesh_keeps_planar_and_its_numbers(
    scene: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from robogs.physics import baseline
    from robogs.physics.api import compare

    rec = load_recording(scene)
    assert set(rec.meshes) == {"box"}  # the asset is read ...
    assert rec.shapes().meshes == {} and rec.shapes().boxes["box"] < 1e-6  # ... and is the box
    assert recording_backend(rec, "auto")[0] == "planar"
    bare = _without_mesh(scene, tmp_path / "bare")
    assert load_recording(bare).meshes == {}
    runs = []
    for i, root in enumerate((scene, bare)):  # bare: the path before meshes were read
        baseline._CACHE.clear()  # each refitted from scratch, no cached baseline shared
        monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / f"cache{i}"))
        runs.append(compare(root, mask_frames=0, engine="auto"))
    with_mesh, before = runs
    assert with_mesh.rms_mm == before.rms_mm


def test_cylinder_mesh_goes_to_mujoco_as_its_hull(scene: Path, tmp_path: Path) -> None:
    import mujoco

    cyl = trimesh.creation.cylinder(radius=0.045, height=SIZE[2], sections=32)
    root = _with_mesh(scene, tmp_path / "cyl", cyl)
    rec = load_recording(root)
    name, why = recording_backend(rec, "auto")
    assert name == "mujoco"
    assert "object 'box' has a mesh shape" in why
    with pytest.raises(InputError, match="planar engine cannot represent .* object 'box'"):
        Engine(rec, backend="planar")
    eng = Engine(rec, backend="auto")
    assert eng.backend == "mujoco" and "mesh shape" in eng.shapes.notes[0]
    m = eng._mujoco.eng.model
    gid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "box")
    assert m.geom_type[gid] == mujoco.mjtGeom.mjGEOM_MESH
    k = int(m.geom_dataid[gid])
    v0, nv = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
    f0, nf = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
    compiled = trimesh.Trimesh(m.mesh_vert[v0 : v0 + nv], m.mesh_face[f0 : f0 + nf], process=False)
    hull = trimesh.convex.convex_hull(np.asarray(cyl.vertices))
    assert abs(compiled.volume) == pytest.approx(hull.volume, rel=1e-6)
    # a start measured on the support rests on the hull's lowest vertices: half the height
    fit = eng._mujoco
    assert fit.rest_z == pytest.approx(0.5 * SIZE[2], abs=1e-8)  # float32 PLY vertices
    assert 0.0 <= fit.rest_z - fit.settled_z < 1e-4  # the soft contact's rest penetration


def test_non_convex_detailed_mesh_is_hulled_said_and_noted(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from robogs.cli.main import main

    tube = trimesh.creation.annulus(r_min=0.03, r_max=0.045, height=SIZE[2], sections=160)
    assert not tube.is_convex and len(tube.convex_hull.vertices) > MAX_HULL_VERTICES
    root = _with_mesh(scene, tmp_path / "tube", tube)
    assert main(["fit", str(root), "--engine", "auto", "--mask-frames", "0"]) == 0
    out = capsys.readouterr().out
    assert "engine: mujoco (auto: planar cannot represent it: object 'box' has a mesh" in out
    assert "non-convex" in out and f"decimated to {MAX_HULL_VERTICES}" in out
    note = Dataset.open(root).physics()["note"]
    assert "object 'box' has a mesh shape" in note
    assert "non-convex" in note and f"decimated to {MAX_HULL_VERTICES}" in note


def test_mesh_path_escaping_the_dataset_is_refused(scene: Path, tmp_path: Path) -> None:
    root = tmp_path / "hostile"
    shutil.copytree(scene, root)
    m = json.loads((root / "manifest.json").read_text())
    m["assets"]["box"]["mesh"] = "../../outside.ply"
    (root / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(PathEscapeError, match="assets/box/mesh: path '../../outside.ply' escapes"):
        load_recording(root)


def test_the_baseline_cache_key_sees_the_mesh():
    """Two recordings with the same samples but different object meshes must not share a
    memoised baseline (the MuJoCo fit simulates the hull)."""
    import dataclasses

    import trimesh

    from robogs.physics.baseline import _fingerprint
    from robogs.physics.recording import as_recording
    from robogs.synth.scenarios.generate import make_scenario

    rec = as_recording(make_scenario("none", seed=0, kinds=("release_slide",)))
    cyl = dataclasses.replace(rec, meshes={"box": trimesh.creation.cylinder(0.045, 0.06)})
    wider = dataclasses.replace(rec, meshes={"box": trimesh.creation.cylinder(0.046, 0.06)})
    keys = {_fingerprint(r) for r in (rec, cyl, wider)}
    assert len(keys) == 3
    assert _fingerprint(dataclasses.replace(cyl)) == _fingerprint(cyl)

"""``robogs synth OUT --capture static [--no-poses]``: the multi-view scan of the scene at rest.

The dataset validates; with poses it stores exactly the poses of its ground truth and clears the
reconstructor's coverage; without them the camera declares ``extrinsics: unknown`` (spec §8),
stores no pose anywhere, and ``reconstruct`` refuses it naming structure from motion.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.format.dataset import Dataset, read_parquet
from robogs.format.frames import quat_to_matrix
from robogs.format.validate import validate
from robogs.synth.multiview import read_truth_poses, truth_path

EXT = "episodes/static/cameras/orbit/extrinsics.parquet"


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("capture")
    out = {"poses": root / "with", "no_poses": root / "without"}
    assert main(["synth", str(out["poses"]), "--capture", "static", "--seed", "3"]) == 0
    argv = ["synth", str(out["no_poses"]), "--capture", "static", "--no-poses", "--seed", "3"]
    assert main(argv) == 0
    return out


def _errors(path: Path) -> list[str]:
    rep = validate(path)
    return [f"{f.code} {f.message}" for f in rep.findings if f.severity == "error"]


@pytest.mark.slow
def test_with_poses_validates_and_stores_the_true_poses(captures):
    path = captures["poses"]
    assert _errors(path) == []
    ds = Dataset.open(path)
    cam = ds.camera("orbit")
    assert (cam.width, cam.height, cam.extrinsics) == (320, 240, "time_varying")
    tab = read_parquet(ds.resolve(EXT))
    assert tab.num_rows == 60
    T = read_truth_poses(truth_path(path))
    p = np.stack([tab.column(c).to_numpy() for c in "xyz"], -1)
    q = np.stack([tab.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
    assert np.allclose(p, T[:, :3, 3], atol=1e-12)
    assert np.allclose(quat_to_matrix(q), T[:, :3, :3], atol=1e-9)
    doc = json.loads(truth_path(path).read_text())
    assert (truth_path(path).parent / doc["scene_mesh"]).is_file()
    assert 1.0 < doc["scene_size_m"] < 3.0  # table diagonal and arm


@pytest.mark.slow
def test_with_poses_clears_the_coverage(captures):
    from robogs.format.kinematics import Chain
    from robogs.reconstruct.coverage import assess_coverage
    from robogs.reconstruct.pipeline import _target_centres
    from robogs.reconstruct.robot_geometry import link_meshes
    from robogs.reconstruct.segment import target_map
    from robogs.reconstruct.views import load_capture, split_heldout

    ds = Dataset.open(captures["poses"])
    cap = load_capture(ds)
    train, _ = split_heldout(cap.views, 8)
    tmap = target_map(cap.segments, set(Chain.from_urdf(ds.urdf(load_meshes=False)).link_names))
    rep = assess_coverage(
        train, tmap, _target_centres(ds, cap, link_meshes(ds, cap.joint_positions))
    )
    assert rep.problems() == [], rep.to_json()
    assert {t.name for t in rep.targets} >= {"wrist_3_link", "box", "table"}


@pytest.mark.slow
def test_without_poses_validates_and_declares_them_unknown(captures, capsys):
    path = captures["no_poses"]
    assert _errors(path) == []
    ds = Dataset.open(path)
    cam = ds.camera("orbit")
    assert cam.extrinsics == "unknown" and cam.T_world_cam is None
    stream = ds.episode("static").streams["camera/orbit"]
    assert "extrinsics" not in stream and not (path / EXT).exists()
    assert not any(r.endswith("extrinsics.parquet") for r in ds.files)
    # the same images as the posed capture (same seed): only the poses are withheld
    T = read_truth_poses(truth_path(path))
    assert np.array_equal(T, read_truth_poses(truth_path(captures["poses"])))
    code = main(["reconstruct", str(path), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "extrinsics unknown" in err and "--sfm" in err


def test_no_poses_needs_capture(tmp_path: Path, capsys):
    assert main(["synth", str(tmp_path / "x"), "--no-poses"]) == 2
    assert "--no-poses needs --capture static" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_schema_refuses_an_unknown_extrinsics_word(tmp_path: Path):
    """Mutation: only static, time_varying and unknown are extrinsics values (S002)."""
    from robogs.synth.multiview import synthesize_multiview

    synthesize_multiview(tmp_path / "d", n_views=4, width=16, height=12, poses=False)
    assert _errors(tmp_path / "d") == []
    cam = tmp_path / "d" / "cameras" / "orbit.json"
    doc = json.loads(cam.read_text())
    assert doc["extrinsics"] == "unknown"
    doc["extrinsics"] = "guessed"
    cam.write_text(json.dumps(doc))
    errs = [e for e in _errors(tmp_path / "d") if e.startswith("S002")]
    assert errs and "'guessed' is not one of ['static', 'time_varying', 'unknown']" in errs[0]

"""Reconstruct the procedural two-link scene and measure it against its ground truth.

Scene: ``robogs.synth.multiview`` (two-link arm on a base and a box; 40 views of 128x96 px on a
sphere around it, every 8th held out; rasterised by the fixture's own triangle rasteriser).
Targets (the reconstructor's acceptance thresholds): held-out PSNR >= 28 dB, F-score at 1 % of
the bounding-box diagonal >= 0.9 against the visible true surface, link/object label mIoU >= 0.9
after re-rendering through the binding, and a dataset that passes ``robogs-validate`` including
the binding re-render checks.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.format.validate import validate
from robogs.reconstruct.evaluate import evaluate
from robogs.reconstruct.mesh_metrics import point_metrics, sample_mesh
from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
from robogs.reconstruct.train import TrainConfig
from robogs.synth.multiview import synthesize_multiview


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory):
    import torch

    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("e2e") / "scene"
    truth = synthesize_multiview(root, n_views=40, width=128, height=96)
    # 150 iterations (was 200, 20 % less CPU): the same scene, stages and thresholds; measured
    # PSNR 29.5 dB (>= 28), mIoU 0.94 (>= 0.9), F@1 % 0.99 (>= 0.9), link1 part median 2.33 mm
    # (< 3; 2.84 at 200). Fewer views or smaller images save nothing (training cost is per
    # iteration) or leave PSNR at 28.4 dB (96x72)
    opts = ReconstructOptions(
        train=TrainConfig(iterations=150, checkpoint_every=0),
        lr_scale=3.0,
        work_dir=root.parent / "work",
    )
    report = reconstruct(root, opts)
    gt = root.parent / "truth.ply"
    truth.scene_mesh.export(gt)
    return root, truth, report, gt


def test_heldout_images_and_labels(scene):
    root, truth, report, _ = scene
    assert report.views_heldout == [f"orbit/{i}" for i in truth.heldout]
    ev = evaluate(root)
    assert [v.key for v in ev.views] == report.views_heldout
    assert ev.psnr_db >= 28.0, [v.psnr_db for v in ev.views]
    assert ev.ssim >= 0.9
    assert set(ev.iou) == set(truth.label_of.values())  # every link and the box
    assert ev.miou >= 0.9, ev.iou


def test_mesh_fscore_at_one_percent_of_the_diagonal(scene):
    root, truth, report, gt = scene
    diag = float(np.linalg.norm(np.ptp(truth.scene_mesh.vertices, axis=0)))
    tau_mm = 0.01 * diag * 1e3
    ev = evaluate(
        root, reference=gt, visible_only=True, images=False, samples=60_000, taus_mm=(tau_mm, 5.0)
    )
    assert ev.mesh.fscore[tau_mm] >= 0.9, ev.mesh.to_json()
    assert ev.mesh.chamfer_l1_mm <= 0.005 * diag * 1e3  # CD-L1 <= 0.5 % of the diagonal
    # the same against the fixture's own visibility of the true surface
    ref, ref_n = truth.visible_surface_points(60_000)
    mesh = Dataset.open(root).resolve("reconstruction/mesh.ply")
    import trimesh

    p, pn = sample_mesh(trimesh.load(mesh, force="mesh"), 60_000)
    m = point_metrics(p, ref, pred_normals=pn, ref_normals=ref_n, taus_mm=(tau_mm,))
    assert m.fscore[tau_mm] >= 0.9 and m.normal_consistency >= 0.85


def test_metric_alignment_to_the_urdf(scene):
    _, _, report, _ = scene
    a = report.alignment
    assert a is not None and a["mode"] == "report"
    assert abs(a["scale"] - 1.0) < 0.02 and a["rotation_deg"] < 1.0
    assert np.linalg.norm(a["translation_mm"]) < 3.0
    assert a["rms_mm"] < 5.0 and set(a["per_link_median_mm"]) == {"base_link", "link1", "link2"}


def test_binding_and_written_dataset(scene):
    root, truth, report, _ = scene
    ds = Dataset.open(root)
    robot = ds.manifest["robot"]["splats"]
    assert robot["kind"] == "2dgs" and robot["targets"] == ["base_link", "link1", "link2"]
    assert robot["rest"]["joint_positions"] == pytest.approx(truth.joint_positions)
    assert "mesh" in ds.assets["box"] and ds.assets["box"]["splats"]["targets"] == ["box"]
    assert report.binding_max_mm < 0.01 and report.gaussians_unassigned < 0.05 * sum(
        report.gaussians.values()
    )
    prov = ds.manifest["provenance"]["reconstruction"]
    assert prov["heldout"] == report.views_heldout and prov["report"]["iterations"] == 150
    # the box mesh is stored in its own frame: posed at its rest pose it lies on the true box
    from robogs.format.frames import quat_to_matrix

    pose = np.asarray(robot["rest"]["object_poses"]["box"])
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(pose[3:])
    T[:3, 3] = pose[:3]
    box = ds.mesh("box").copy().apply_transform(T)
    d = np.abs(truth.meshes["box"].nearest.signed_distance(box.vertices[::5]))
    assert np.median(d) < 3e-3


def test_robogs_validate_passes(scene):
    root, _, _, _ = scene
    rep = validate(root)
    errors = [f for f in rep.findings if f.severity == "error"]
    assert not errors, [f.message for f in errors]
    ran = {r.code for r in rep.runs if r.status != "skipped"}
    assert {"B001", "B002", "B003"} <= ran
    assert "B002" not in rep.codes(min_severity="warning")  # re-rendered label IoU >= 0.9


def test_cli_evaluate_json(scene, capsys: pytest.CaptureFixture[str]):
    root, _, _, _ = scene
    assert main(["evaluate", str(root), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["psnr_db"] >= 28.0 and len(doc["views"]) == 5


def test_link_parts_are_segmented_and_stored_in_their_link_frames(scene):
    # oracle: the fixture's own link meshes, in their link frames (the two-link URDF has
    # identity visual origins)
    import trimesh

    from robogs.synth.multiview.two_link import two_link_robot

    root, _, report, _ = scene
    meshes = two_link_robot().meshes
    ds = Dataset.open(root)
    for link in meshes:
        rel = f"reconstruction/links/{link}.ply"
        assert rel in report.written
        part = trimesh.load(ds.resolve(rel), force="mesh")
        d = {n: np.abs(m.nearest.signed_distance(part.vertices[::7])) for n, m in meshes.items()}
        assert np.median(d[link]) < 3e-3, link  # in its own link frame, on its own link
        assert (d[link] < 6e-3).mean() > 0.9, link

"""Floors after training: an empty mesh, a link with too few Gaussians or a low held-out PSNR
stop the run (exit 1) with the figures, write nothing, and keep the checkpoint for ``--force``."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from robogs.cli.main import main
from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
from robogs.reconstruct.quality import QualityFloors, ReconstructionRejected, assess_quality
from robogs.reconstruct.train import TrainConfig


def test_floors_closed_form():
    rep = assess_quality(
        mesh_faces=0,
        heldout_psnr_db=12.0,
        link_gaussians={"upper_arm_link": 13, "wrist_3_link": 40, "no_mesh": 7},
        link_areas_m2={"upper_arm_link": 0.3, "wrist_3_link": 0.02},
        spacing_m=0.018,
    )
    # required: max(8, ceil(0.25 A / s^2)): 0.3 m^2 -> 232, 0.02 m^2 -> 16, no area -> 8
    assert rep.gaussians == {
        "upper_arm_link": (13, 232),
        "wrist_3_link": (40, 16),
        "no_mesh": (7, 8),
    }
    assert rep.failures == [
        "the mesh is empty (0 faces)",
        "held-out PSNR 12.0 dB < 20 dB",
        "link upper_arm_link has 13 Gaussians < 232",
        "link no_mesh has 7 Gaussians < 8",
    ]
    with pytest.raises(ReconstructionRejected, match="mesh 0 faces, held-out PSNR 12.0 dB") as e:
        rep.raise_if_failed()
    assert e.value.figures["gaussians"]["upper_arm_link"] == {"count": 13, "required": 232}
    ok = assess_quality(
        mesh_faces=10,
        heldout_psnr_db=math.nan,  # no held-out views: not checked
        link_gaussians={"a": 232},
        link_areas_m2={"a": 0.3},
        spacing_m=0.018,
    )
    assert ok.passed
    ok.raise_if_failed()


NO_COVERAGE = ["--min-views", "1", "--min-span-deg", "0", "--min-pixels", "1"]


def test_a_result_below_the_floors_is_rejected_then_forced(
    capture_copy: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
):
    work = tmp_path / "w"
    before = (capture_copy / "manifest.json").read_bytes()
    argv = [
        "reconstruct", str(capture_copy), "--iterations", "4", "--heldout-every", "4",
        "--tsdf-resolution", "32", "--no-progress", "--work-dir", str(work),
        "--min-psnr", "99", *NO_COVERAGE,
    ]  # fmt: skip
    code = main([*argv, "--json"])
    cap = capsys.readouterr()
    assert code == 1, cap.err
    fig = json.loads(cap.out)
    assert fig["rejected"].startswith("the reconstruction is below its floors: held-out PSNR")
    psnr = fig["heldout_psnr_db"]
    assert 0.0 < psnr < 99.0 and f"held-out PSNR {psnr:.1f} dB < 99 dB" in cap.err
    assert cap.err.count("\n") == 1 and "Traceback" not in cap.err
    assert (capture_copy / "manifest.json").read_bytes() == before  # nothing written
    assert (work / "checkpoint.pt").exists()  # kept for --force
    # --force writes the same result without training again, and reports the failure
    steps: list[int] = []
    rep = reconstruct(
        capture_copy,
        ReconstructOptions(
            train=TrainConfig(iterations=4),
            heldout_every=4,
            tsdf_resolution=32,
            work_dir=work,
            floors=QualityFloors(min_psnr_db=99.0),
            force=True,
        ),
        on_step=lambda k, _: steps.append(k),
    )
    assert steps == [] and rep.resumed_from == 4
    assert rep.quality["heldout_psnr_db"] == pytest.approx(psnr, abs=1e-9)
    assert rep.quality["failures"] == [f"held-out PSNR {psnr:.1f} dB < 99 dB"]
    assert rep.coverage["problems"]  # the tiny capture is below the default coverage too
    assert (capture_copy / "manifest.json").read_bytes() != before


def test_links_with_too_few_gaussians_are_named(capture_copy: Path, tmp_path: Path):
    with pytest.raises(ReconstructionRejected) as e:
        reconstruct(
            capture_copy,
            ReconstructOptions(
                train=TrainConfig(iterations=2, checkpoint_every=0),
                heldout_every=4,
                tsdf_resolution=32,
                work_dir=tmp_path / "w",
                floors=QualityFloors(min_psnr_db=0.0, min_gaussians=10**6),
                force=False,
                coverage=_no_coverage(),
            ),
        )
    g = e.value.figures["gaussians"]
    assert set(g) == {"base_link", "link1", "link2"}
    for name, f in g.items():
        assert f["required"] == 10**6 and 0 <= f["count"] < 10**6
        assert f"link {name} has {f['count']} Gaussians < 1000000" in e.value.message


def _no_coverage():
    from robogs.reconstruct.coverage import CoverageThresholds

    return CoverageThresholds(min_views=1, min_span_deg=0.0, min_pixels=1)

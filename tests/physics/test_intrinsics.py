"""``camera_intrinsics`` from mask boundaries: recovery, null data, fit writes, revert.

The perturbed scene is made by the fixture generator and a mutation, never by the code under
test: frames and labels are rasterised with the true intrinsics (``robogs.synth.scene``) and the
dataset then declares ``fx * 1.03`` and ``cx + 4 px`` (``robogs.synth.mutations.perturb_intrinsics``).
Tolerances: at 160x120 px over seeds 0-7 (bench/mask_intrinsics.py, 30 frames) dfx came out
0.0286-0.0317 for 0.03, dcx 3.96-4.05 px for 4 px, and null scenes kept |dfx| <= 0.0013,
|dcx| <= 0.04 px, |dfy| <= 0.0044 (splat growth that varies along the table's far edge).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from robogs.format.dataset import Dataset
from robogs.physics.api import fit, revert
from robogs.physics.diagnose import DBIC_MAX
from robogs.physics.intrinsics import (
    EFFECT_SIZE_MIN,
    HELDOUT_MIN_GAIN,
    corrected_camera,
    diagnose_intrinsics,
    fit_intrinsics,
)
from robogs.physics.masks import mask_boundary
from robogs.synth.mutations import perturb_intrinsics

FRAMES = 10
DFX, DCX = 0.03, 4.0


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("intr") / "clean"
    synthesize(root, seed=1, size="small", progress=False)
    return root


@pytest.fixture(scope="module")
def perturbed(scene: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("intr") / "perturbed"
    shutil.copytree(scene, root)
    perturb_intrinsics(root, fx_rel=DFX, cx_px=DCX)
    return root


@pytest.fixture(scope="module")
def perturbed_fit(perturbed: Path):
    (f,) = fit_intrinsics(Dataset.open(perturbed), max_frames=FRAMES)
    return f


def test_fit_recovers_the_declared_focal_and_principal_point_errors(perturbed_fit) -> None:
    f = perturbed_fit
    dfx, dfy, dcx, dcy = f.values
    assert dfx == pytest.approx(DFX, abs=0.003)
    assert dcx == pytest.approx(DCX, abs=0.15)
    assert dfy == pytest.approx(0.0, abs=0.008)
    assert dcy == pytest.approx(0.0, abs=0.3)
    assert f.identifiable.all()
    row = f.row.to_dict()
    assert row["name"] == "camera_intrinsics" and row["family"] == "sensor"
    assert row["reported"] and row["verdict"] == "add" and row["unit"] == "px"
    assert row["delta_bic"] <= DBIC_MAX
    assert row["heldout_gain"] > HELDOUT_MIN_GAIN
    assert row["heldout_rms_after"] < 0.6 * row["heldout_rms_before"]
    assert row["effect_size"] >= EFFECT_SIZE_MIN
    p = {q["name"]: q for q in row["params"]}
    assert set(p) == {"cam0.dfx", "cam0.dfy", "cam0.dcx", "cam0.dcy"}
    for q in p.values():
        assert q["low"] < q["value"] < q["high"]
    # the intervals hold the truth (the generator's errors)
    for name, truth in (("dfx", DFX), ("dfy", 0.0), ("dcx", DCX), ("dcy", 0.0)):
        assert p[f"cam0.{name}"]["low"] <= truth <= p[f"cam0.{name}"]["high"], name
    # the warp model explains the boundary error: it falls to the clean level
    assert f.boundary_px_after < 0.5 * f.boundary_px_before


def test_null_scene_reports_nothing(scene: Path) -> None:
    fits, why = diagnose_intrinsics(Dataset.open(scene), max_frames=FRAMES)
    assert why is None
    (f,) = fits
    assert not f.row.reported and f.row.verdict != "add"
    assert f.row.effect_size < EFFECT_SIZE_MIN
    assert f.row.heldout_gain < HELDOUT_MIN_GAIN
    # ΔBIC counts effectively independent boundary pixels: no false evidence on null data
    # (with the raw pixel count it was about -2000 here)
    assert f.row.delta_bic > DBIC_MAX
    assert f.extra["n_effective"] < 0.1 * f.extra["n_points"]
    assert abs(f.values[0]) < 0.003 and abs(f.values[2]) < 0.15
    for q in f.row.params:  # the 95 % intervals hold the truth (no error)
        assert q.low <= 0.0 <= q.high, q


def test_fit_writes_the_intrinsics_and_the_boundary_residual_falls(
    perturbed: Path, tmp_path: Path
) -> None:
    root = tmp_path / "ds"
    shutil.copytree(perturbed, root)
    declared = json.loads((root / "cameras/cam0.json").read_text())
    # the mask-boundary stream compare reports with mask_poses="recorded" (the same call, bit for
    # bit), without compare's refit of the physics baseline (30 s CPU each, unused here)
    before = mask_boundary(Dataset.open(root), max_frames=6).boundary_px
    rev0 = Dataset.open(root).physics()["revision"]
    res = fit(root, ["camera_intrinsics"], mask_frames=FRAMES)
    assert res.revision == rev0 + 1
    cam = json.loads((root / "cameras/cam0.json").read_text())
    # the written camera is the generator's (declared / 1.03, declared - 4 px)
    assert cam["fx"] == pytest.approx(declared["fx"] / (1 + DFX), rel=0.01)
    assert cam["cx"] == pytest.approx(declared["cx"] - DCX, abs=0.3)
    rec = Dataset.open(root).physics()["sensors"]["cam0"]["intrinsics"]
    assert rec["previous"]["fx"] == pytest.approx(declared["fx"])
    after = mask_boundary(Dataset.open(root), max_frames=6).boundary_px
    assert before > 1.8 and after < 1.1 and after < 0.55 * before, (before, after)
    # the physics history keeps the old camera: reverting restores it
    revert(root, rev0)
    back = json.loads((root / "cameras/cam0.json").read_text())
    assert back["fx"] == pytest.approx(declared["fx"]) and back["cx"] == pytest.approx(
        declared["cx"]
    )
    assert np.isfinite(res.to_dict()["cameras"][0]["boundary_px_after"])


def _stripe_frames(shift_px: int, n: int = 6):
    """Frames of a full-width horizontal band (rows 40-79 rendered, moved by ``shift_px`` in the
    recorded labels): its edges are all horizontal, so nothing constrains dfx or dcx."""
    from robogs.format.cameras import CameraModel
    from robogs.physics.masks import RenderedFrame

    cam = CameraModel("cam", 160, 120, 130.0, 130.0, 80.0, 60.0, T_world_cam=np.eye(4))
    ren = np.zeros((120, 160), np.int64)
    ren[40:80] = 1
    rec = np.roll(ren, shift_px, axis=0)
    z = np.zeros(1)
    return [
        RenderedFrame(
            "ep",
            "cam",
            cam,
            ["band"],
            ["object"],
            i,
            i,
            rec,
            ren,
            np.ones((120, 160)),
            z,
            z,
            z,
            z,
            z,
        )
        for i in range(n)
    ]


def test_parameters_the_edges_cannot_see_are_unidentifiable() -> None:
    from robogs.physics.intrinsics import analyse_contours, contours_of

    f = analyse_contours(contours_of(_stripe_frames(2)))
    assert f.identifiable.tolist() == [False, True, False, True]  # dfx dfy dcx dcy
    # the true image shows the band 2 px lower: cy_true = cy + 2, so dcy = -2
    assert f.values[3] == pytest.approx(-2.0, abs=0.05)
    assert f.values[1] == pytest.approx(0.0, abs=0.005)  # 0.1 px at the band edges
    row = f.row.to_dict()
    p = {q["name"]: q for q in row["params"]}
    assert p["cam.dfx"]["low"] is None and p["cam.dcx"]["high"] is None  # infinite interval
    assert "unidentifiable: dfx, dcx" in row["note"]
    assert corrected_camera(f).cx == 80.0 and corrected_camera(f).cy == pytest.approx(
        62.0, abs=0.05
    )

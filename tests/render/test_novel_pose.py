"""Novel poses: the binding rendered at joint configurations never recorded matches the
synthetic scene's independent triangle rasteriser (label IoU >= 0.9 per link, boundary error
<= 1.5 px, the validator's budgets), and a 0.03 rad joint error in the binding's render fails
those bounds. PSNR is reported (bench/render.py writes the figures to bench/RESULTS.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from novel_pose import novel_configurations, novel_pose_metrics

from robogs.format import Dataset
from robogs.synth.scene import synthesize

IOU_MIN, BOUNDARY_MAX_PX = 0.9, 1.5
LINKS = (
    "base_link",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
    "pusher_tip",
)


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("novel") / "s"
    synthesize(out, seed=2, size="small", progress=False)
    return out


@pytest.fixture(scope="module")
def configs(scene: Path) -> np.ndarray:
    return novel_configurations(Dataset.open(scene), 3, seed=5)


def test_novel_poses_match_the_rasteriser(scene: Path, configs: np.ndarray) -> None:
    res = novel_pose_metrics(scene, configs, scale=2.0)
    compared = set()
    for r in res:
        assert r.min_distance_rad >= 0.25  # never recorded
        for name, iou, b in zip(r.names, r.iou, r.boundary_px, strict=True):
            if name in LINKS:
                compared.add(name)
                assert np.isnan(iou) or iou >= IOU_MIN, (name, iou)
                assert b <= BOUNDARY_MAX_PX, (name, b)
        assert 15.0 < r.psnr_db < 60.0  # reported; flat-shaded meshes vs baked splat colour
    assert len(compared) >= 5, compared


def test_a_joint_error_is_caught(scene: Path, configs: np.ndarray) -> None:
    off = np.zeros(configs.shape[1])
    off[1] = 0.03  # shoulder lift: moves every link after it
    res = novel_pose_metrics(scene, configs[:1], scale=2.0, binding_offset=off)
    worst = [
        (n, i, b)
        for r in res
        for n, i, b in zip(r.names, r.iou, r.boundary_px, strict=True)
        if n in LINKS and (i < IOU_MIN or b > BOUNDARY_MAX_PX)  # NaN IoU compares False
    ]
    assert worst, res

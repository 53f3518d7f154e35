"""Mesh metrics against closed forms: parallel planes, subsets, the Robo-GS-compatible threshold."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from robogs.reconstruct.mesh_metrics import (
    COMPAT_TAU_M,
    mesh_metrics,
    point_metrics,
    robogs_compat,
)


def _grid(n: int = 60, z: float = 0.0) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(0, 0.3, n), np.linspace(0, 0.3, n))
    return np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], 1)


@pytest.mark.parametrize("d_mm", [0.5, 1.5, 3.0, 7.0])
def test_parallel_planes_offset_by_d(d_mm: float):
    d = d_mm * 1e-3
    pred, ref = _grid(z=d), _grid(z=0.0)
    nz = np.tile([0.0, 0.0, 1.0], (len(ref), 1))
    m = point_metrics(pred, ref, pred_normals=nz, ref_normals=-nz, taus_mm=(1.0, 2.0, 5.0))
    assert m.accuracy_mm == pytest.approx(d_mm, rel=1e-9)
    assert m.completeness_mm == pytest.approx(d_mm, rel=1e-9)
    assert m.chamfer_l1_mm == pytest.approx(d_mm, rel=1e-9)
    assert m.chamfer_l2_mm2 == pytest.approx(d_mm**2, rel=1e-9)
    for tau in (1.0, 2.0, 5.0):
        assert m.fscore[tau] == (1.0 if d_mm < tau else 0.0)
    assert m.normal_consistency == pytest.approx(1.0)  # |n . n| ignores orientation


def test_parallel_plane_meshes_sampled():
    a = trimesh.creation.box(extents=(0.2, 0.2, 1e-4))
    b = a.copy().apply_translation((0, 0, 0.002))
    m = mesh_metrics(b, a, n=40_000, taus_mm=(1.0, 3.0))
    # the 0.1 mm slab has both faces: distances are 2 mm to the far face's twin, ~1.9-2.1 mm overall
    assert m.chamfer_l1_mm == pytest.approx(2.0, abs=0.15)
    assert m.fscore[1.0] < 0.05 and m.fscore[3.0] > 0.95


def test_precision_recall_of_a_subset():
    ref = _grid(40)
    pred = ref[: len(ref) // 2]
    m = point_metrics(pred, ref, taus_mm=(0.1,))
    assert m.precision[0.1] == 1.0
    assert m.recall[0.1] == pytest.approx(0.5, abs=0.02)
    p, r = m.precision[0.1], m.recall[0.1]
    assert m.fscore[0.1] == pytest.approx(2 * p * r / (p + r))
    assert m.accuracy_mm == 0.0 and m.completeness_mm > 0.0


def test_robogs_compat_threshold_is_on_squared_distance():
    assert COMPAT_TAU_M == pytest.approx(np.sqrt(1e-5))
    ref = _grid(30)
    inside = robogs_compat(_grid(30, z=3.0e-3), ref)  # 9e-6 m^2 < 1e-5
    outside = robogs_compat(_grid(30, z=3.3e-3), ref)  # 1.089e-5 m^2 > 1e-5
    assert inside["fscore"] == 1.0 and outside["fscore"] == 0.0
    assert inside["mse_m2"] == pytest.approx(9e-6, rel=1e-9)


def test_empty_input_gives_nan_not_crash():
    m = point_metrics(np.zeros((0, 3)), _grid(5))
    assert np.isnan(m.chamfer_l1_mm) and m.fscore[1.0] == 0.0

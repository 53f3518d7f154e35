"""Oracle tests of the numerical helpers behind the checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.format.checks._common import (
    com_outside_mm,
    hull_distance_outside,
    inertia_problem,
    quat_to_matrix_np,
)
from robogs.format.checks.label_boxes import boxes_of_label_image, scan_label_boxes
from robogs.format.frames import quat_to_matrix
from robogs.format.images import encode_label_png


def _brute_boxes(img: np.ndarray) -> dict[int, tuple[int, ...]]:
    out = {}
    for label in np.unique(img):
        if label == 0:
            continue
        ys, xs = np.nonzero(img == label)
        out[int(label)] = (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1, xs.size)
    return out


@pytest.mark.parametrize("seed", range(5))
def test_label_boxes_match_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 40, 2)
    img = np.zeros((h, w), np.uint16)
    for _ in range(6):  # overlapping rectangles plus scattered pixels
        x0, y0 = rng.integers(0, w), rng.integers(0, h)
        img[y0 : y0 + rng.integers(1, 15), x0 : x0 + rng.integers(1, 15)] = rng.integers(1, 65535)
    img[rng.integers(0, h, 5), rng.integers(0, w, 5)] = 7
    ids, x0, y0, x1, y1, n = boxes_of_label_image(img)
    got = {int(i): (a, b, c, d, e) for i, a, b, c, d, e in zip(ids, x0, y0, x1, y1, n, strict=True)}
    assert got == _brute_boxes(img)


def test_empty_label_image_has_no_boxes() -> None:
    assert all(a.size == 0 for a in boxes_of_label_image(np.zeros((5, 4), np.uint16)))


def test_scan_streams_batches_and_keeps_frame_order(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    imgs = [rng.integers(0, 4, (9, 11)).astype(np.uint16) for _ in range(23)]
    idx = np.arange(23) * 2 + 5
    pq.write_table(
        pa.table(
            {"frame_index": pa.array(idx, pa.int64()), "png": [encode_label_png(i) for i in imgs]}
        ),
        tmp_path / "labels.parquet",
    )
    calls: list[int] = []
    lb = scan_label_boxes(
        tmp_path / "labels.parquet", batch_rows=5, threads=2, on_batch=calls.append
    )
    assert calls == [5, 5, 5, 5, 3] and np.array_equal(lb.frames, idx)
    assert (lb.width, lb.height, lb.sizes_consistent) == (11, 9, True)
    for k, img in enumerate(imgs):
        sel = lb.frame_index == idx[k]
        got = {
            int(i): (a, b, c, d, e)
            for i, a, b, c, d, e in zip(
                lb.label_id[sel],
                lb.x_min[sel],
                lb.y_min[sel],
                lb.x_max[sel],
                lb.y_max[sel],
                lb.pixels[sel],
                strict=True,
            )
        }
        assert got == _brute_boxes(img)


def test_inertia_problem_closed_form_cases() -> None:
    box = np.diag([1.0, 2.0, 2.5])  # 1 + 2 >= 2.5: physical
    assert inertia_problem(box, 1e-6) is None
    R = quat_to_matrix_np(np.array([[0.9, 0.1, -0.3, 0.2]]))[0]
    assert inertia_problem(R @ box @ R.T, 1e-6) is None  # rotated: still physical
    assert "positive definite" in inertia_problem(np.diag([-1.0, 2.0, 2.0]), 1e-6)
    assert "triangle" in inertia_problem(np.diag([1.0, 1.0, 2.5]), 1e-6)
    assert inertia_problem(np.diag([1.0, 1.0, 2.0]), 1e-6) is None  # a flat plate is the limit case
    assert "symmetric" in inertia_problem(np.array([[1, 0.5, 0], [0, 1, 0], [0, 0, 1.5]]), 1e-6)


def test_hull_distance_against_a_unit_cube() -> None:
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    pts = np.array([[0.5, 0.5, 0.5], [1.25, 0.5, 0.5], [0.5, -0.1, 0.5], [0.5, 0.5, 3.0]])
    np.testing.assert_allclose(hull_distance_outside(cube, pts), [0.0, 0.25, 0.1, 2.0], atol=1e-12)


def test_com_outside_in_mm_and_degenerate_input() -> None:
    cube = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    assert com_outside_mm(cube, [0.5, 0.5, 0.5]) == 0.0
    assert com_outside_mm(cube, [1.25, 0.5, 0.5]) == pytest.approx(250.0, abs=1e-9)
    assert com_outside_mm(cube[:2], [0.5, 0.5, 1.0]) is None  # a segment spans no hull
    assert com_outside_mm(cube, [0.5, 0.5]) is None  # malformed CoM: no verdict either


def test_quaternion_matrix_matches_frames_module() -> None:
    q = np.random.default_rng(2).normal(size=(50, 4))
    np.testing.assert_allclose(quat_to_matrix_np(q), quat_to_matrix(q), atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_png_fast_path_matches_full_decode(seed: int) -> None:
    import cv2

    from robogs.format.checks.label_boxes import _png_sub_runs

    rng = np.random.default_rng(seed)
    img = np.zeros((37, 53), np.uint16)
    for _ in range(8):
        x0, y0 = rng.integers(0, 53), rng.integers(0, 37)
        img[y0 : y0 + rng.integers(1, 20), x0 : x0 + rng.integers(1, 20)] = rng.integers(1, 65535)
    fast = _png_sub_runs(encode_label_png(img))  # the writer's PNGs use the Sub filter
    assert fast is not None and fast[0] == img.shape
    expect = _brute_boxes(img)
    got = {int(i): (a, b, c, d, e) for i, a, b, c, d, e in zip(*fast[1], strict=True)}
    assert got == expect
    ok, paeth = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_PAETH])
    assert ok and _png_sub_runs(paeth.tobytes()) is None  # other filters: full decode

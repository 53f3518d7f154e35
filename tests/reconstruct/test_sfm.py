"""Structure from motion: keyframes from a video and the failure on images without parallax.

The SfM accuracy acceptance (camera centres within 1 % of the scene size on
``robogs synth --capture static --no-poses``) is not tested yet: see docs/reconstruct.md.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from robogs.convert.ingest.sfm import select_keyframes, sharpness


def _texture(seed: int, shape=(120, 160)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (shape[0] // 4, shape[1] // 4), dtype=np.uint8)
    return cv2.resize(small, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)


def test_sharpness_is_the_variance_of_the_laplacian():
    g = _texture(0)
    lap = cv2.Laplacian(g.astype(np.float64), cv2.CV_64F)
    assert sharpness(g) == pytest.approx(float(lap.var()))
    assert sharpness(cv2.GaussianBlur(g, (0, 0), 3.0)) < 0.1 * sharpness(g)
    assert sharpness(np.full((8, 8), 7, np.uint8)) == 0.0


def test_keyframes_drop_blurred_and_duplicate_frames():
    a, b, c = _texture(1), _texture(2), _texture(3)
    blurred = cv2.GaussianBlur(b, (0, 0), 4.0)
    frames = [a, a.copy(), blurred, b, b.copy(), c]
    assert select_keyframes(frames) == [0, 3, 5]
    assert select_keyframes([]) == []


def test_sfm_on_identical_images_names_how_many_registered(tmp_path: Path):
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.convert.ingest.sfm import SfmError, run_sfm

    img = tmp_path / "img"
    img.mkdir()
    g = cv2.cvtColor(_texture(4), cv2.COLOR_GRAY2BGR)
    for i in range(6):
        cv2.imwrite(str(img / f"{i:03d}.png"), g)
    with pytest.raises(SfmError, match=r"registered [0-2] of 6 images") as e:
        run_sfm(img, tmp_path / "work", intrinsics=(150.0, 150.0, 80.0, 60.0))
    assert "parallax" in e.value.hint

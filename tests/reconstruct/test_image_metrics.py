"""PSNR, SSIM and IoU against closed forms and skimage."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from skimage.metrics import structural_similarity

from robogs.reconstruct.image_metrics import gaussian_window, label_iou, psnr, ssim


def test_ssim_matches_skimage_gaussian_window():
    rng = np.random.default_rng(0)
    a = rng.random((37, 53, 3))
    b = np.clip(a + rng.normal(0.0, 0.08, a.shape), 0.0, 1.0)
    ref = structural_similarity(
        a,
        b,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=2,
    )
    assert float(ssim(torch.tensor(a), torch.tensor(b))) == pytest.approx(ref, abs=1e-12)


def test_ssim_of_constant_images_is_the_luminance_term():
    # zero variance: SSIM = (2 a b + C1) / (a^2 + b^2 + C1) exactly (the contrast term is C2 / C2)
    a, b = 0.3, 0.7
    c1 = (0.01) ** 2
    expected = (2 * a * b + c1) / (a * a + b * b + c1)
    got = ssim(
        torch.full((20, 20), a, dtype=torch.float64), torch.full((20, 20), b, dtype=torch.float64)
    )
    assert float(got) == pytest.approx(expected, rel=1e-12)
    same = torch.rand(16, 16, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    assert float(ssim(same, same)) == pytest.approx(1.0, abs=1e-12)


def test_window_is_the_11_tap_gaussian():
    w = gaussian_window(dtype=torch.float64)
    assert w.numel() == 11
    assert float(w.sum()) == pytest.approx(1.0)
    assert float(w[6] / w[5]) == pytest.approx(math.exp(-0.5 / 1.5**2))


def test_ssim_gradient_flows():
    a = torch.rand(12, 12, 3, dtype=torch.float64, requires_grad=True)
    b = torch.rand(12, 12, 3, dtype=torch.float64)
    (1 - ssim(a, b, crop=False)).backward()
    assert a.grad is not None and torch.isfinite(a.grad).all() and a.grad.abs().sum() > 0


def test_psnr_closed_form():
    a = np.zeros((4, 5, 3))
    assert psnr(a, a + 0.1) == pytest.approx(20.0)
    assert psnr(a, a) == math.inf
    mask = np.zeros((4, 5), bool)
    mask[0, 0] = True
    b = a.copy()
    b[1:] = 1.0
    b[0, 0] = 0.01
    assert psnr(a, b, mask=mask) == pytest.approx(40.0)


def test_label_iou():
    p = np.array([[1, 1, 0], [2, 2, 2]])
    t = np.array([[1, 0, 0], [2, 2, 0]])
    iou = label_iou(p, t, [1, 2, 7])
    assert iou == {1: 0.5, 2: pytest.approx(2 / 3), 7: 1.0}

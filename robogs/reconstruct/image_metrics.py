"""Image metrics in torch: PSNR and SSIM (also the D-SSIM training loss), and label mIoU.

SSIM follows Wang et al. 2004 with the constants of the 3DGS/2DGS code and torchmetrics:
an 11 x 11 Gaussian window with sigma 1.5, K1 = 0.01, K2 = 0.03, data range 1, population
(not sample) covariances. Borders follow ``skimage.metrics.structural_similarity`` with
``gaussian_weights=True, sigma=1.5, use_sample_covariance=False``: the image is extended by
half-sample symmetric reflection (scipy's ``reflect``), and the mean SSIM leaves out the
5-pixel border. Channels are averaged.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch
import torch.nn.functional as F

__all__ = ["psnr", "ssim", "ssim_map", "gaussian_window", "label_iou"]

_SIGMA = 1.5
_RADIUS = 5  # int(3.5 * sigma + 0.5): scipy's truncate=3.5 at sigma 1.5
_K1, _K2 = 0.01, 0.03


def gaussian_window(
    sigma: float = _SIGMA,
    radius: int = _RADIUS,
    *,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str = "cpu",
) -> torch.Tensor:
    """[2 radius + 1] normalised 1-D Gaussian taps."""
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    w = torch.exp(-0.5 * (x / sigma) ** 2)
    return (w / w.sum()).to(dtype=dtype, device=device)


@functools.lru_cache(maxsize=16)
def _window_on(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """:func:`gaussian_window` kept per dtype and device: built on the host and copied once, not
    in every training step (a host-to-device copy waits for the device)."""
    return gaussian_window(dtype=dtype, device=device)


def _symmetric_pad(x: torch.Tensor, p: int) -> torch.Tensor:
    """Pad the last two dims of [B, C, H, W] by half-sample symmetric reflection (d c b a | a b c d)."""
    x = torch.cat([x[..., :p, :].flip(-2), x, x[..., -p:, :].flip(-2)], dim=-2)
    return torch.cat([x[..., :p].flip(-1), x, x[..., -p:].flip(-1)], dim=-1)


def _blur(x: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Separable Gaussian filter of [B, C, H, W] with symmetric borders; same size out."""
    c = x.shape[1]
    r = (w.numel() - 1) // 2
    x = _symmetric_pad(x, r)
    x = F.conv2d(x, w.view(1, 1, -1, 1).expand(c, 1, -1, 1), groups=c)
    return F.conv2d(x, w.view(1, 1, 1, -1).expand(c, 1, 1, -1), groups=c)


def _as_bchw(img: torch.Tensor) -> torch.Tensor:
    if img.ndim == 2:
        return img[None, None]
    if img.ndim == 3:  # [H, W, C]
        return img.permute(2, 0, 1)[None]
    return img


def ssim_map(a: torch.Tensor, b: torch.Tensor, *, data_range: float = 1.0) -> torch.Tensor:
    """Per-pixel SSIM [B, C, H, W] of two images ([H, W], [H, W, C] or [B, C, H, W]); differentiable."""
    x, y = _as_bchw(a), _as_bchw(b)
    w = _window_on(x.dtype, x.device)
    c1, c2 = (_K1 * data_range) ** 2, (_K2 * data_range) ** 2
    # the five moments blurred in one grouped convolution (one launch instead of five on a GPU)
    c = x.shape[1]
    blurred = _blur(torch.cat([x, y, x * x, y * y, x * y], dim=1), w)
    mx, my, sxx, syy, sxy = blurred.split(c, dim=1)
    vx = sxx - mx * mx
    vy = syy - my * my
    cxy = sxy - mx * my
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def ssim(
    a: torch.Tensor, b: torch.Tensor, *, data_range: float = 1.0, crop: bool = True
) -> torch.Tensor:
    """Mean SSIM (scalar tensor), channels averaged; ``crop`` leaves out the 5-px border (skimage)."""
    s = ssim_map(a, b, data_range=data_range)
    if crop and s.shape[-1] > 2 * _RADIUS and s.shape[-2] > 2 * _RADIUS:
        s = s[..., _RADIUS:-_RADIUS, _RADIUS:-_RADIUS]
    return s.mean()


def psnr(
    a: torch.Tensor | np.ndarray,
    b: torch.Tensor | np.ndarray,
    *,
    data_range: float = 1.0,
    mask: np.ndarray | torch.Tensor | None = None,
) -> float:
    """PSNR in dB: ``10 log10(range^2 / MSE)``, over ``mask`` pixels if given; inf for equal images."""
    x = torch.as_tensor(a, dtype=torch.float64)
    y = torch.as_tensor(b, dtype=torch.float64)
    d = (x - y) ** 2
    if mask is not None:
        m = torch.as_tensor(mask, dtype=torch.bool)
        d = d[m]
    mse = float(d.mean()) if d.numel() else float("nan")
    if mse == 0.0:
        return math.inf
    return 10.0 * math.log10(data_range**2 / mse)


def label_iou(pred: np.ndarray, truth: np.ndarray, labels: list[int]) -> dict[int, float]:
    """IoU per label id of two label images [H, W]; a label absent from both gets 1.0."""
    out = {}
    for lab in labels:
        p, t = pred == lab, truth == lab
        union = int((p | t).sum())
        out[int(lab)] = 1.0 if union == 0 else float((p & t).sum()) / union
    return out

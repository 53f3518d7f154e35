"""The numba backend's Gaussian-major tile kernel gives the images of the pixel-major kernel it
replaced (kept here as the reference: every pixel walks its tile's whole list), within 1e-5
(in practice to the bit: per pixel the arithmetic and its order are the same)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from robogs.format.render import RenderConfig, available_backends, render
from robogs.format.render.constants import (
    MAX_ALPHA,
    MEDIAN_TRANSMITTANCE,
    TRANSMITTANCE_THRESHOLD,
)

pytestmark = pytest.mark.skipif(
    "numba" not in available_backends(), reason="numba backend not installed"
)
FIELDS = ("rgb", "alpha", "depth_expected", "depth_median", "normals", "extra")


# Repeats fused._composite's per-pair arithmetic by design: it is the old path checked against.
def _pixel_major(tiles, offsets, gids, prm, feats, tiles_x, ts, width, height, surfels, near,
                 inv_sq, out) -> None:  # fmt: skip
    """The kernel before the change, pixel by pixel (compiled below, serial)."""
    D = feats.shape[1]
    for ti in range(tiles.shape[0]):
        t = tiles[ti]
        ox = (t % tiles_x) * ts
        oy = (t // tiles_x) * ts
        for py in range(oy, min(oy + ts, height)):
            y = py + 0.5
            for px in range(ox, min(ox + ts, width)):
                x = px + 0.5
                T = 1.0
                for k in range(offsets[t], offsets[t + 1]):
                    g = gids[k]
                    dx = x - prm[g, 0]
                    dy = y - prm[g, 1]
                    if surfels:
                        h0 = x * prm[g, 5] + y * prm[g, 8] + prm[g, 11]
                        h1 = x * prm[g, 6] + y * prm[g, 9] + prm[g, 12]
                        h2 = x * prm[g, 7] + y * prm[g, 10] + prm[g, 13]
                        rho = inv_sq * (dx * dx + dy * dy)
                        z = prm[g, 4]
                        if h2 != 0.0:
                            u = h0 / h2
                            v = h1 / h2
                            zh = (prm[g, 14] * h0 + prm[g, 15] * h1 + prm[g, 16] * h2) / h2
                            if zh > near and u * u + v * v <= rho:
                                rho = u * u + v * v
                                z = zh
                        e = prm[g, 2] - 0.5 * rho
                        e_min = prm[g, 3]
                    else:
                        e = prm[g, 5] - (
                            0.5 * (prm[g, 2] * dx * dx + prm[g, 4] * dy * dy) + prm[g, 3] * dx * dy
                        )
                        e_min = prm[g, 6]
                        z = prm[g, 7]
                    if e < e_min:
                        continue
                    alpha = min(MAX_ALPHA, math.exp(e))
                    T_next = T * (1.0 - alpha)
                    if T_next < TRANSMITTANCE_THRESHOLD:
                        break
                    w = alpha * T
                    for d in range(D):
                        out[py, px, d] += w * feats[g, d]
                    out[py, px, D] += w * z
                    if T > MEDIAN_TRANSMITTANCE and T_next <= MEDIAN_TRANSMITTANCE:
                        out[py, px, D + 1] = z
                    T = T_next


@pytest.fixture(scope="module")
def reference():
    import numba

    return numba.njit(cache=False)(_pixel_major)


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("size", [(37, 29), (97, 75)])
def test_gaussian_major_kernel_equals_pixel_major(
    make_gaussians, make_camera, reference, monkeypatch, kind, dtype, size
) -> None:
    import robogs.format.render.fused as fused

    g = make_gaussians(1500, kind, seed=7, scale=(0.01, 0.08), opacity_shift=2.0, extra=4,
                       dtype=dtype)  # fmt: skip
    cam = make_camera(*size, dtype=dtype)
    f = 1.1 * size[0]
    cam = replace(cam, fx=f, fy=f, cx=size[0] / 2, cy=size[1] / 2)
    cfg = RenderConfig(kind=kind, background=(0.2, 0.3, 0.4))
    new = render(g, cam, config=cfg, backend="numba")
    monkeypatch.setattr(fused, "_composite", reference)
    old = render(g, cam, config=cfg, backend="numba")
    # the scene exercises the stop rule, the median and partial tiles at the border
    assert float((old.alpha > 1 - 1e-3).float().mean()) > 0.1
    assert float((old.alpha > 0).float().mean()) > 0.5
    assert float((old.depth_median > 0).float().mean()) > 0.3
    d = {f: float((getattr(new, f) - getattr(old, f)).abs().max()) for f in FIELDS}
    assert max(d.values()) <= 1e-5, d
    assert np.isfinite(list(d.values())).all()

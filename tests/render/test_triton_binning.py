"""Tile binning in Triton (``triton_binning.py``) against ``binning.bin_tiles``: equal lists.

Runs where the ``triton`` backend runs (CUDA, or the CPU under ``TRITON_INTERPRET=1``); skipped
with the registry's reason elsewhere. The boxes include ones off screen, larger than the image,
of zero size, and with edges exactly on a tile boundary give or take the margin; depths tie;
some Gaussians are culled.
"""

from __future__ import annotations

import pytest
import torch

from robogs.format.render import available_backends
from robogs.format.render.backends import backend_entries
from robogs.format.render.binning import _BBOX_MARGIN_PX, bin_tiles

HAVE = "triton" in available_backends()
REASON = next((str(e.reason) for e in backend_entries() if e.name == "triton"), "not registered")
DEVICE = "cuda" if torch.cuda.is_available() else "cpu"
pytestmark = pytest.mark.skipif(not HAVE, reason=f"triton backend unavailable: {REASON}")


def _boxes(n: int, width: int, height: int, ts: int, dtype, seed: int):
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)  # noqa: E731
    cx, cy = r(n) * width * 1.4 - 0.2 * width, r(n) * height * 1.4 - 0.2 * height
    hw, hh = r(n) ** 3 * width * 0.6, r(n) ** 3 * height * 0.6
    box = torch.stack([cx - hw, cx + hw, cy - hh, cy + hh], dim=1)
    k = n // 8
    box[:k] = torch.tensor([-1e4, 1e4, -1e4, 1e4], dtype=torch.float64)  # covers every tile
    box[k : 2 * k, 1] = box[k : 2 * k, 0]  # zero width
    # edges on a tile boundary (pixel centre i + 0.5 with i = ts * j), just in and just out
    j = torch.randint(1, max(width // ts, 2), (2 * k,), generator=g).to(torch.float64)
    edge = ts * j + 0.5
    sign = torch.tensor([-1.0, 1.0], dtype=torch.float64).repeat(k)
    box[2 * k : 4 * k, 0] = edge + sign * 0.5 * _BBOX_MARGIN_PX
    box[2 * k : 4 * k, 1] = edge + 3 * ts + sign * 2 * _BBOX_MARGIN_PX
    box[4 * k : 5 * k] = box[4 * k : 5 * k] + 5 * max(width, height)  # off screen
    depth = torch.round(r(n) * 20) / 10 + 0.1  # ties
    visible = r(n) > 0.2
    return box.to(dtype), depth.to(dtype), visible


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("width,height,ts", [(70, 45, 16), (64, 48, 8), (33, 17, 16)])
@pytest.mark.parametrize("seed", [0, 1])
def test_triton_bins_equal_bin_tiles(dtype, width, height, ts, seed):
    from robogs.format.render.triton_binning import bin_tiles_triton

    box, depth, visible = _boxes(400, width, height, ts, dtype, seed)
    box, depth, visible = box.to(DEVICE), depth.to(DEVICE), visible.to(DEVICE)
    want = bin_tiles(box, depth, visible, width, height, ts)
    got = bin_tiles_triton(box, depth, visible, width, height, ts)
    assert (got.tiles_x, got.tiles_y, got.tile_size) == (want.tiles_x, want.tiles_y, ts)
    assert got.offsets.dtype == want.offsets.dtype == torch.int64
    assert torch.equal(got.offsets, want.offsets)
    assert torch.equal(got.gaussian_ids, want.gaussian_ids)
    assert want.gaussian_ids.numel() > 400  # the scene has many multi-tile boxes


@pytest.mark.parametrize("n_visible", [0, 1])
def test_empty_and_single(n_visible):
    from robogs.format.render.triton_binning import bin_tiles_triton

    for n in (0, 3):
        box = torch.tensor([[10.0, 40.0, 5.0, 20.0]] * n, device=DEVICE).reshape(n, 4)
        depth = torch.ones(n, device=DEVICE)
        visible = torch.zeros(n, dtype=torch.bool, device=DEVICE)
        visible[:n_visible] = True
        want = bin_tiles(box, depth, visible, 48, 32, 16)
        got = bin_tiles_triton(box, depth, visible, 48, 32, 16)
        assert torch.equal(got.offsets, want.offsets)
        assert torch.equal(got.gaussian_ids, want.gaussian_ids)


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
def test_render_with_triton_binning_equals_render_without(
    make_gaussians, make_camera, monkeypatch, kind
):
    from robogs.format.render import RenderConfig, render
    from robogs.format.render import triton_raster as tr

    g = make_gaussians(150, kind, seed=2, spread=0.5, dtype=torch.float32, device=DEVICE)
    cam = make_camera(40, 28, device=DEVICE)
    cfg = RenderConfig(kind=kind, validate=False, tile_size=8)
    outs = []
    for on in (False, True):
        monkeypatch.setattr(tr, "_TRITON_BINNING", on)
        outs.append(render(g, cam, config=cfg, backend="triton"))
    for name in ("rgb", "alpha", "depth_expected", "depth_median", "normals"):
        assert torch.equal(getattr(outs[0], name), getattr(outs[1], name)), name

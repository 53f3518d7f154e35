"""Tile binning in two Triton kernels: the same lists as :func:`binning.bin_tiles`, fewer launches.

``bin_tiles`` builds the per-tile lists from about seventy small torch ops (a few microseconds
of GPU work each, but 10-20 us each to launch from Python). Here:

1. the Gaussians are sorted by depth once (culled ones last);
2. one program per block of sorted Gaussians computes each one's rectangle of tiles and its
   tile count (0 when culled), as ``bin_tiles`` does (same margin, same float operations);
3. an inclusive cumsum gives each one's first slot; the total is read back (the one host sync);
4. one program per sorted Gaussian writes its (tile id, Gaussian id) pairs, row by row of its
   rectangle, into its slots;
5. a stable sort by tile id keeps the depth order inside each tile (the 3DGS reference's
   (tile << 32 | depth) radix sort, Kerbl et al. 2023, without building the 64-bit key), and
   ``searchsorted`` gives the tile offsets.

The result equals ``bin_tiles`` exactly (``tests/render/test_triton_binning.py``).
"""

from __future__ import annotations

import math

import torch
import triton
import triton.language as tl

from .binning import _BBOX_MARGIN_PX, TileBins

__all__ = ["bin_tiles_triton"]

#: sorted Gaussians per program of the rectangle kernel
_BLOCK = 256
#: slots written per iteration of the emit kernel
_EMIT = 64
_MARGIN = tl.constexpr(_BBOX_MARGIN_PX)


@triton.jit
def _rect_kernel(
    order_ptr, bbox_ptr, vis_ptr, n_ptr, rect_ptr, N, tiles_x, tiles_y,
    TS: tl.constexpr, BLOCK: tl.constexpr,
):  # fmt: skip
    j = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    m = j < N
    g = tl.load(order_ptr + j, mask=m, other=0)
    vis = tl.load(vis_ptr + g, mask=m, other=0) != 0
    xmin = tl.load(bbox_ptr + g * 4 + 0, mask=m, other=0.0)
    xmax = tl.load(bbox_ptr + g * 4 + 1, mask=m, other=0.0)
    ymin = tl.load(bbox_ptr + g * 4 + 2, mask=m, other=0.0)
    ymax = tl.load(bbox_ptr + g * 4 + 3, mask=m, other=0.0)
    # as bin_tiles: floor((b -/+ 0.5 - margin) / ts) clamped to the grid, in the bbox dtype; ts
    # is a power of two, so the product with 1 / ts is exact, like torch's division (Triton's own
    # float32 division is div.full.f32, an approximation)
    inv = 1.0 / TS
    x0 = tl.minimum(tl.maximum(tl.floor((xmin - 0.5 - _MARGIN) * inv), 0.0), tiles_x - 1.0)
    x1 = tl.minimum(tl.maximum(tl.floor((xmax - 0.5 + _MARGIN) * inv), 0.0), tiles_x - 1.0)
    y0 = tl.minimum(tl.maximum(tl.floor((ymin - 0.5 - _MARGIN) * inv), 0.0), tiles_y - 1.0)
    y1 = tl.minimum(tl.maximum(tl.floor((ymax - 0.5 + _MARGIN) * inv), 0.0), tiles_y - 1.0)
    x0i = x0.to(tl.int32)
    y0i = y0.to(tl.int32)
    w = tl.maximum(x1.to(tl.int32) - x0i + 1, 0)
    h = tl.maximum(y1.to(tl.int32) - y0i + 1, 0)
    n = tl.where(vis & m, w.to(tl.int64) * h.to(tl.int64), 0)
    tl.store(n_ptr + j, n, mask=m)
    tl.store(rect_ptr + j * 3 + 0, x0i, mask=m)
    tl.store(rect_ptr + j * 3 + 1, y0i, mask=m)
    tl.store(rect_ptr + j * 3 + 2, w, mask=m)


@triton.jit
def _emit_kernel(
    order_ptr, n_ptr, csum_ptr, rect_ptr, key_ptr, id_ptr, tiles_x, EMIT: tl.constexpr,
):  # fmt: skip
    j = tl.program_id(0)
    n = tl.load(n_ptr + j)
    start = tl.load(csum_ptr + j) - n
    g = tl.load(order_ptr + j)
    x0 = tl.load(rect_ptr + j * 3 + 0)
    y0 = tl.load(rect_ptr + j * 3 + 1)
    w = tl.maximum(tl.load(rect_ptr + j * 3 + 2), 1)  # n == 0 when w == 0: never divides by it
    kk = tl.arange(0, EMIT)
    k0 = n * 0
    while k0 < n:
        k = k0 + kk
        m = k < n
        tile = (y0 + k // w) * tiles_x + (x0 + k % w)
        tl.store(key_ptr + start + k, tile.to(tl.int32), mask=m)
        tl.store(id_ptr + start + k, g + k * 0, mask=m)
        k0 += EMIT


def bin_tiles_triton(
    bbox: torch.Tensor,
    depth: torch.Tensor,
    visible: torch.Tensor,
    width: int,
    height: int,
    tile_size: int,
) -> TileBins:
    """:func:`binning.bin_tiles` in Triton kernels (same arguments, same result).

    Args:
        bbox: [N, 4] (xmin, xmax, ymin, ymax) support box, px (float32 or float64).
        depth: [N] sort key (camera-frame z of the mean), m.
        visible: [N] bool; invisible Gaussians are left out.
        width, height: image size, px.
        tile_size: tile edge, px (a power of two).
    """
    device = depth.device
    tiles_x = math.ceil(width / tile_size)
    tiles_y = math.ceil(height / tile_size)
    num_tiles = tiles_x * tiles_y
    if num_tiles >= 2**31:
        raise ValueError(f"{num_tiles} tiles do not fit the int32 tile key")
    if tile_size < 1 or tile_size & (tile_size - 1):
        raise ValueError(f"tile_size must be a power of two, got {tile_size}")
    N = depth.shape[0]
    order = torch.argsort(
        torch.where(visible, depth.detach(), torch.inf), stable=True
    )  # culled Gaussians last; ties keep index order, as bin_tiles
    n = torch.empty(N, dtype=torch.int64, device=device)
    rect = torch.empty((N, 3), dtype=torch.int32, device=device)
    if N:
        _rect_kernel[(triton.cdiv(N, _BLOCK),)](
            order, bbox.detach().contiguous(), visible.contiguous(), n, rect, N, tiles_x, tiles_y,
            TS=tile_size, BLOCK=_BLOCK,
        )  # fmt: skip
    csum = torch.cumsum(n, 0)
    total = int(csum[-1]) if N else 0  # the one host sync: sizes the lists
    key = torch.empty(total, dtype=torch.int32, device=device)
    ids = torch.empty(total, dtype=torch.int64, device=device)
    if total:
        _emit_kernel[(N,)](order, n, csum, rect, key, ids, tiles_x, EMIT=_EMIT)
    key, perm = torch.sort(key, stable=True)
    gaussian_ids = ids[perm]
    bounds = torch.arange(num_tiles + 1, dtype=torch.int32, device=device)
    offsets = torch.searchsorted(key, bounds)
    return TileBins(tile_size, tiles_x, tiles_y, gaussian_ids, offsets)

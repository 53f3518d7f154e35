"""Assign depth-sorted Gaussians to screen tiles without Python loops.

Each visible Gaussian covers a rectangle of tiles given by its support bounding box. The
depth-ordered ids are repeated once per covered tile (``repeat_interleave``), the tile of each
copy is decoded from its rank inside the rectangle, and a stable sort by tile id keeps depth order
inside every tile (the same result as the 64-bit (tile << 32 | depth) radix sort of the 3DGS
reference, without building the key).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

__all__ = ["TileBins", "bin_tiles"]

#: Extra margin of the bounding box before it is turned into tiles, px (absorbs rounding).
_BBOX_MARGIN_PX = 1e-3


@dataclass(frozen=True, eq=False)
class TileBins:
    """Per-tile, front-to-back lists of Gaussian ids.

    Attributes:
        tile_size: tile edge, px.
        tiles_x: number of tile columns.
        tiles_y: number of tile rows.
        gaussian_ids: [M] int64 Gaussian ids, grouped by tile, front to back in each tile.
        offsets: [tiles_x * tiles_y + 1] int64 start of each tile's list in ``gaussian_ids``.
    """

    tile_size: int
    tiles_x: int
    tiles_y: int
    gaussian_ids: torch.Tensor
    offsets: torch.Tensor

    @property
    def counts(self) -> torch.Tensor:
        """[tiles] number of Gaussians in each tile."""
        return self.offsets[1:] - self.offsets[:-1]


def bin_tiles(
    bbox: torch.Tensor,
    depth: torch.Tensor,
    visible: torch.Tensor,
    width: int,
    height: int,
    tile_size: int,
) -> TileBins:
    """Bin Gaussians into tiles, sorted front to back by ``depth``.

    Args:
        bbox: [N, 4] (xmin, xmax, ymin, ymax) support box, px.
        depth: [N] sort key (camera-frame z of the mean), m.
        visible: [N] bool; invisible Gaussians are left out.
        width: image width, px.
        height: image height, px.
        tile_size: tile edge, px.

    Returns:
        The tile lists.
    """
    device = depth.device
    tiles_x = math.ceil(width / tile_size)
    tiles_y = math.ceil(height / tile_size)
    vis_ids = torch.nonzero(visible).flatten()
    order = vis_ids[torch.argsort(depth.detach()[vis_ids], stable=True)]
    box = bbox[order]
    # pixel i (centre i + 0.5) can be inside the box only if xmin - 0.5 <= i <= xmax - 0.5
    x0 = torch.floor((box[:, 0] - 0.5 - _BBOX_MARGIN_PX) / tile_size).clamp(0, tiles_x - 1).long()
    x1 = torch.floor((box[:, 1] - 0.5 + _BBOX_MARGIN_PX) / tile_size).clamp(0, tiles_x - 1).long()
    y0 = torch.floor((box[:, 2] - 0.5 - _BBOX_MARGIN_PX) / tile_size).clamp(0, tiles_y - 1).long()
    y1 = torch.floor((box[:, 3] - 0.5 + _BBOX_MARGIN_PX) / tile_size).clamp(0, tiles_y - 1).long()
    w = (x1 - x0 + 1).clamp_min(0)
    h = (y1 - y0 + 1).clamp_min(0)
    n = w * h
    total = int(n.sum())
    start = torch.cumsum(n, 0) - n
    rep = torch.repeat_interleave(torch.arange(order.numel(), device=device), n, output_size=total)
    k = torch.arange(total, device=device) - start[rep]
    wr = w[rep]
    tile = (y0[rep] + k // wr) * tiles_x + (x0[rep] + k % wr)
    num_tiles = tiles_x * tiles_y
    key = tile.to(torch.int32) if num_tiles < 2**31 else tile
    _, perm = torch.sort(key, stable=True)
    gaussian_ids = order[rep[perm]]
    counts = torch.bincount(tile, minlength=num_tiles)
    offsets = torch.zeros(num_tiles + 1, dtype=torch.int64, device=device)
    offsets[1:] = torch.cumsum(counts, 0)
    return TileBins(tile_size, tiles_x, tiles_y, gaussian_ids, offsets)

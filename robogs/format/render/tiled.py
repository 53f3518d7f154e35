"""The default ``torch`` backend: project, cull, sort, bin into tiles, composite per tile."""

from __future__ import annotations

from dataclasses import replace

import torch

from .binning import bin_tiles
from .camera import Camera
from .composite import composite_tiles
from .config import RenderConfig
from .gaussians import Gaussians
from .output import RenderOutput
from .projection import project

__all__ = ["render_tiled"]

#: default tiles per batch on CPU (keeps a step's [tiles, pixels, chunk] tensors in cache)
_CPU_TILE_BATCH = 256
#: default tile edges, px
_CPU_TILE_SIZE = 8
_GPU_TILE_SIZE = 16


def render_tiled(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> RenderOutput:
    """Render a pinhole camera with the tile-chunk rasterizer (CPU or CUDA, differentiable).

    Args:
        gaussians: N Gaussians, world frame; all outputs are on their device and dtype.
        camera: the camera; distortion is ignored here (see ``render``).
        config: render options.

    Returns:
        The render.
    """
    H, W = camera.height, camera.width
    proj = project(gaussians, camera, config)
    # composite from the very tensor that is returned as ``means2d``, so that its gradient
    # (after ``retain_grad``) is the screen-space gradient used for densification
    proj = replace(proj, means2d=visible_means2d(proj.means2d, proj.visible))
    on_cpu = proj.depth.device.type == "cpu"
    tile_size = config.tile_size or (_CPU_TILE_SIZE if on_cpu else _GPU_TILE_SIZE)
    bins = bin_tiles(proj.bbox, proj.depth, proj.visible, W, H, tile_size)
    ones = torch.ones_like(proj.depth)[:, None]
    feats = torch.cat([proj.rgb, ones, proj.normals, proj.extra], dim=1)
    batch = config.tile_batch
    if batch is None and on_cpu:
        batch = _CPU_TILE_BATCH
    img = composite_tiles(
        proj, bins, feats, W, H, chunk=config.chunk, near=camera.near, tile_batch=batch
    )
    return finish_output(
        img.features, img.depth, img.median, proj.means2d, proj.bbox, proj.visible, config
    )


def visible_means2d(means2d: torch.Tensor, visible: torch.Tensor) -> torch.Tensor:
    """[N, 2] projected means, px, with the rows of culled Gaussians set to 0.

    Culled Gaussians are never composited, so compositing from this tensor gives the same
    images as from ``means2d`` and puts the returned ``RenderOutput.means2d`` on the graph.
    """
    return torch.where(visible[:, None], means2d, 0.0)


def finish_output(
    features: torch.Tensor,
    depth_sum: torch.Tensor,
    median: torch.Tensor,
    means2d: torch.Tensor,
    bbox: torch.Tensor,
    visible: torch.Tensor,
    config: RenderConfig,
) -> RenderOutput:
    """Normalise accumulated images into a :class:`RenderOutput`.

    Args:
        features: [H, W, 7 + C] accumulated (rgb, alpha, normals, extra).
        depth_sum: [H, W] accumulated w z.
        median: [H, W] median depth.
        means2d: [N, 2] projected means, px, 0 where culled (see :func:`visible_means2d`);
            returned as is, so it stays the tensor the compositing read.
        bbox: [N, 4] support boxes, px.
        visible: [N] bool.
        config: render options (background).
    """
    rgb = features[..., 0:3]
    alpha = features[..., 3]
    normals = features[..., 4:7]
    extra = features[..., 7:]
    has = alpha > 0
    inv = 1.0 / torch.where(has, alpha, torch.ones_like(alpha))
    bg = torch.tensor(config.background, dtype=features.dtype, device=features.device)
    return RenderOutput(
        rgb=rgb + (1.0 - alpha)[..., None] * bg,
        alpha=alpha,
        depth_expected=torch.where(has, depth_sum * inv, 0.0),
        depth_median=median,
        normals=torch.where(has[..., None], normals * inv[..., None], 0.0),
        extra=extra,
        means2d=means2d,
        radii=support_radii(bbox, visible),
    )


def support_radii(bbox: torch.Tensor, visible: torch.Tensor) -> torch.Tensor:
    """[N, 2] half extents (px) of the support boxes [N, 4]; 0 for culled Gaussians."""
    radii = torch.stack([bbox[:, 1] - bbox[:, 0], bbox[:, 3] - bbox[:, 2]], dim=-1) * 0.5
    return torch.where(visible[:, None], radii, 0.0)

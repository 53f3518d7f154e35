"""Options of a render call."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["RenderConfig"]


@dataclass(frozen=True)
class RenderConfig:
    """How to render.

    Attributes:
        kind: "3dgs" (3D Gaussians, EWA splatting) or "2dgs" (surfels, ray-splat intersection).
        tile_size: tile edge, px (None: 8 on CPU, 16 on CUDA). 16 is the GPU standard; on a
            CPU 8 wastes fewer pixel-Gaussian pairs and is 1.3-2x faster (bench/render.py).
        background: colour added with weight (1 - alpha), 3 floats.
        sh_degree: use SH bands up to this degree (None: all coefficients given).
        chunk: Gaussians composited per tile and step by the torch backend.
        tile_batch: tiles composited together by the torch backend; smaller batches keep the
            working set in cache on CPUs (None: 256 tiles on CPU, all on CUDA).
        antialiased: 3DGS only; scale opacity by sqrt(det S / det(S + 0.3 I)) (Mip-Splatting,
            Yu et al. 2024) instead of the classic 3DGS low-pass that brightens tiny Gaussians.
        undistort_scale: for distorted cameras, the pinhole render grid has this many pixels per
            output pixel along each axis before it is remapped (see ``distortion.py``).
        lowpass_scale: output pixels are this many render-grid pixels wide; the 3DGS low-pass
            (0.3 px^2) and the 2DGS screen filter are widened to match. ``render`` sets it to
            ``undistort_scale`` on the supersampled grid of distorted cameras; leave it at 1.
        validate: check inputs for NaN, shapes and degenerate values before rendering.
    """

    kind: Literal["3dgs", "2dgs"] = "3dgs"
    tile_size: int | None = None
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int | None = None
    chunk: int = 32
    tile_batch: int | None = None
    antialiased: bool = False
    undistort_scale: float = 1.0
    lowpass_scale: float = 1.0
    validate: bool = True

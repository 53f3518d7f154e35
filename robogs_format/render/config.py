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
        tile_size: tile edge, px. 16 is the GPU standard; 8 is about twice as fast on a CPU.
        background: colour added with weight (1 - alpha), 3 floats.
        sh_degree: use SH bands up to this degree (None: all coefficients given).
        chunk: Gaussians composited per tile and step by the torch backend.
        antialiased: 3DGS only; scale opacity by sqrt(det S / det(S + 0.3 I)) (Mip-Splatting,
            Yu et al. 2024) instead of the classic 3DGS low-pass that brightens tiny Gaussians.
        undistort_scale: for distorted cameras, the pinhole render grid has this many pixels per
            output pixel along each axis before it is remapped (see ``distortion.py``).
        validate: check inputs for NaN, shapes and degenerate values before rendering.
    """

    kind: Literal["3dgs", "2dgs"] = "3dgs"
    tile_size: int = 16
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sh_degree: int | None = None
    chunk: int = 32
    antialiased: bool = False
    undistort_scale: float = 1.0
    validate: bool = True

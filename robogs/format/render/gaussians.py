"""The Gaussians to render: 3D Gaussians (3DGS) or 2D surfels (2DGS)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["Gaussians"]


@dataclass(eq=False)
class Gaussians:
    """A set of N Gaussians in the world frame, in pre-activation form (3DGS PLY layout).

    Attributes:
        means: [N, 3] centres, m, world frame.
        quats: [N, 4] rotations (w, x, y, z) to the world frame; normalised inside.
        log_scales: [N, 3] log standard deviations, log m (3DGS), or [N, 2] (2DGS surfels:
            the two tangent axes are the first two columns of the rotation).
        opacity_logits: [N] opacity before the sigmoid.
        sh: [N, K, 3] spherical-harmonic colour coefficients, K in {1, 4, 9, 16}, DC first.
        extra: optional [N, C] per-Gaussian channels blended like colour (label one-hots, ids).
    """

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor
    extra: torch.Tensor | None = None

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def kind(self) -> str:
        """ "3dgs" for three scales, "2dgs" for two."""
        return "2dgs" if self.log_scales.shape[-1] == 2 else "3dgs"

    @property
    def num_extra(self) -> int:
        """Number of extra channels C (0 without extras)."""
        return 0 if self.extra is None else int(self.extra.shape[-1])

"""The result of a render call."""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["RenderOutput"]


@dataclass(frozen=True, eq=False)
class RenderOutput:
    """Everything one compositing pass produces. Images are [H, W, ...], row-major.

    With w_i = alpha_i * T_i the compositing weight of Gaussian i at a pixel (front to back):

    Attributes:
        rgb: [H, W, 3] sum_i w_i c_i + (1 - alpha) * background.
        alpha: [H, W] sum_i w_i = 1 - final transmittance.
        depth_expected: [H, W] sum_i w_i z_i / alpha, m, camera-frame z; 0 where alpha = 0.
            z_i is the mean's depth (3DGS) or the ray-surfel intersection depth (2DGS).
        depth_median: [H, W] z of the Gaussian at which the transmittance first drops to
            <= 0.5, m; 0 where it never does (alpha < 0.5).
        normals: [H, W, 3] sum_i w_i n_i / alpha, camera frame, 0 where alpha = 0. n_i is the
            surfel normal (2DGS) or the shortest axis (3DGS), flipped to face the camera, so a
            surface seen head-on gives (0, 0, -1). Not renormalised: |n| < 1 where normals mix.
        extra: [H, W, C] sum_i w_i e_i (no background); C = 0 without extra channels.
        means2d: [N, 2] projected means, px, on the render grid (the pinhole grid for distorted
            cameras); rows of culled Gaussians are 0. On the autograd graph: it is the tensor
            the compositing read, so after ``out.means2d.retain_grad()`` and ``loss.backward()``
            ``out.means2d.grad`` holds dL/d(means2d) with the 2D kernel shape held fixed, the
            view-space positional gradient of 3DGS densification (0 for culled rows). Detached
            for forward-only backends (``numba``).
        radii: [N, 2] half extents of the screen-space support box, px; 0 where culled (and
            everywhere for the dense oracle, which needs no boxes).
    """

    rgb: torch.Tensor
    alpha: torch.Tensor
    depth_expected: torch.Tensor
    depth_median: torch.Tensor
    normals: torch.Tensor
    extra: torch.Tensor
    means2d: torch.Tensor
    radii: torch.Tensor

    @property
    def height(self) -> int:
        return int(self.alpha.shape[0])

    @property
    def width(self) -> int:
        return int(self.alpha.shape[1])

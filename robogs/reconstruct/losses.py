"""Training losses of 2DGS (Huang et al. 2024, §4.2): photometric, normal consistency, depth distortion.

* Photometric: ``(1 - l) L1 + l (1 - SSIM)`` with ``l = 0.2`` (Kerbl et al. 2023).
* Normal consistency: ``mean(alpha (1 - n . N))`` where ``n`` is the rendered surfel normal and
  ``N`` the normal of the surface through the rendered depth (central differences of the
  back-projected median depth), both in the camera frame and facing the camera.
* Depth distortion: ``sum_{i<j} w_i w_j (z_i - z_j)^2`` per pixel, the squared-distance form of
  the 2DGS paper's Eq. 13 (its CUDA code also uses squared differences). With the running sums
  ``A = sum w``, ``S1 = sum w z``, ``S2 = sum w z^2`` it equals ``A S2 - S1^2`` exactly, so two
  extra render channels (z and z^2 per Gaussian) give it in one pass. z is the camera-frame depth
  of each Gaussian's centre, m (the paper uses the ray-splat intersection depth; for surfels
  smaller than a few pixels the two agree to a fraction of the surfel size).
"""

from __future__ import annotations

import torch

from robogs.format.render import Camera

from .image_metrics import ssim

__all__ = [
    "photometric_loss",
    "depth_normals",
    "pixel_rays",
    "normal_consistency",
    "depth_distortion",
    "depth_channels",
]


def photometric_loss(
    pred: torch.Tensor, target: torch.Tensor, lambda_dssim: float = 0.2
) -> torch.Tensor:
    """``(1 - l) L1 + l (1 - SSIM)`` of two [H, W, 3] images in [0, 1]."""
    l1 = (pred - target).abs().mean()
    if lambda_dssim == 0.0:
        return l1
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * (1.0 - ssim(pred, target, crop=False))


def pixel_rays(camera: Camera, dtype: torch.dtype, device: torch.device | str) -> torch.Tensor:
    """[H, W, 2] (u, v) of each pixel centre on the z = 1 plane of the camera frame (pinhole).

    A tensor rather than the camera's numbers, so that a loss built on it can be captured once
    (CUDA graph) and replayed for every view. Built on ``device`` (no host-to-device copy, which
    would wait for the device).
    """
    H, W = camera.height, camera.width
    u = (torch.arange(W, dtype=torch.float64, device=device) + 0.5 - camera.cx) / camera.fx
    v = (torch.arange(H, dtype=torch.float64, device=device) + 0.5 - camera.cy) / camera.fy
    uv = torch.stack([u[None, :].expand(H, W), v[:, None].expand(H, W)], dim=-1)
    return uv.to(dtype=dtype, device=device)


def _interior_normals(depth: torch.Tensor, rays: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Normals [H-2, W-2, 3] and valid mask of the pixels that have all four neighbours."""
    P = torch.cat([rays * depth[..., None], depth[..., None]], dim=-1)
    dx = P[1:-1, 2:] - P[1:-1, :-2]
    dy = P[2:, 1:-1] - P[:-2, 1:-1]
    n = torch.cross(dx, dy, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    # face the camera: n . P < 0
    n = torch.where(((n * P[1:-1, 1:-1]).sum(-1, keepdim=True) > 0), -n, n)
    pos = depth > 0
    ok = pos[1:-1, 2:] & pos[1:-1, :-2] & pos[2:, 1:-1] & pos[:-2, 1:-1]
    return n, ok


def depth_normals(depth: torch.Tensor, camera: Camera) -> tuple[torch.Tensor, torch.Tensor]:
    """Normals [H, W, 3] of the surface through a depth map (camera frame, facing the camera).

    Args:
        depth: [H, W] camera-frame z, m (0 = no surface).
        camera: the pinhole camera of the render.

    Returns:
        normals (zero on the border and where a neighbour has no depth) and the valid mask [H, W].
    """
    H, W = depth.shape
    n, ok = _interior_normals(depth, pixel_rays(camera, depth.dtype, depth.device))
    full = torch.zeros(H, W, 3, dtype=depth.dtype, device=depth.device)
    mask = torch.zeros(H, W, dtype=torch.bool, device=depth.device)
    full[1:-1, 1:-1] = torch.where(ok[..., None], n, 0.0)
    mask[1:-1, 1:-1] = ok
    return full, mask


def normal_consistency(
    rendered_normals: torch.Tensor, alpha: torch.Tensor, depth: torch.Tensor, rays: torch.Tensor
) -> torch.Tensor:
    """``mean(alpha (1 - n . N))`` over pixels with a depth normal; the depth normal is detached
    from neither side (both the surfels' orientation and their depths are pulled together).

    Args:
        rendered_normals: [H, W, 3] blended surfel normals, camera frame.
        alpha: [H, W] accumulated opacity.
        depth: [H, W] rendered depth, m.
        rays: [H, W, 2] :func:`pixel_rays` of the render's camera.
    """
    N, ok = _interior_normals(depth, rays)
    n = rendered_normals[1:-1, 1:-1]
    err = alpha[1:-1, 1:-1] * (1.0 - (n * N).sum(-1))
    okf = ok.to(err.dtype)
    return (err * okf).sum() / okf.sum().clamp(min=1.0)


def depth_distortion(alpha: torch.Tensor, extra: torch.Tensor) -> torch.Tensor:
    """Mean over pixels of ``sum_{i<j} w_i w_j (z_i - z_j)^2 = A S2 - S1^2`` (m^2).

    Args:
        alpha: [H, W] ``A``.
        extra: [H, W, 2] the blended :func:`depth_channels` (``S1``, ``S2``).
    """
    return (alpha * extra[..., 1] - extra[..., 0] ** 2).clamp(min=0.0).mean()


def depth_channels(means: torch.Tensor, camera: Camera) -> torch.Tensor:
    """[N, 2] per-Gaussian extra channels (z, z^2) of the centres in ``camera``, m and m^2."""
    T = camera.T_world_cam.to(dtype=means.dtype, device=means.device)
    z = (means - T[:3, 3]) @ T[:3, 2]
    return torch.stack([z, z * z], dim=1)

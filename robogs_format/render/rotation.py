"""Quaternion (w, x, y, z) to rotation matrix, batched and differentiable."""

from __future__ import annotations

import torch

__all__ = ["quat_to_rotmat"]


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """Rotation matrices from quaternions, scalar first.

    Args:
        quats: [N, 4] (w, x, y, z); normalised here (zero quaternions are rejected upstream).

    Returns:
        [N, 3, 3] rotation matrices R with columns the rotated x, y, z axes.
    """
    q = quats / quats.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = [
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    ]  # fmt: skip
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))

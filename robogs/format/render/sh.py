"""Real spherical harmonics up to degree 3, in the 3DGS convention.

The basis and its constants are the standard real SH (Sloan, "Stupid Spherical Harmonics
Tricks", 2008) with the signs used by the 3DGS reference code (Kerbl et al. 2023,
``forward.cu: computeColorFromSH``): coefficient 0 is the DC term, then degree 1 in the order
(y, z, x), and so on. Colour is ``max(SH . dir + 0.5, 0)``.
"""

from __future__ import annotations

import torch

__all__ = ["SH_C0", "sh_basis", "eval_sh", "sh_degree_of", "rgb_to_sh_dc"]

SH_C0 = 0.28209479177387814
_C1 = 0.4886025119029199
_C2 = (
    1.0925484305920792,
    -1.0925484305920792,
    0.31539156525252005,
    -1.0925484305920792,
    0.5462742152960396,
)
_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)

_K_TO_DEGREE = {1: 0, 4: 1, 9: 2, 16: 3}


def sh_degree_of(num_coeffs: int) -> int | None:
    """The SH degree that has ``num_coeffs`` coefficients (1, 4, 9, 16), or None."""
    return _K_TO_DEGREE.get(int(num_coeffs))


def sh_basis(dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Real SH basis functions evaluated at unit directions.

    Args:
        dirs: [N, 3] unit vectors.
        degree: 0..3.

    Returns:
        [N, (degree + 1) ** 2] basis values, DC first.
    """
    x, y, z = dirs.unbind(-1)
    cols = [torch.full_like(x, SH_C0)]
    if degree >= 1:
        cols += [-_C1 * y, _C1 * z, -_C1 * x]
    if degree >= 2:
        xx, yy, zz = x * x, y * y, z * z
        cols += [
            _C2[0] * x * y,
            _C2[1] * y * z,
            _C2[2] * (2.0 * zz - xx - yy),
            _C2[3] * x * z,
            _C2[4] * (xx - yy),
        ]
    if degree >= 3:
        cols += [
            _C3[0] * y * (3.0 * xx - yy),
            _C3[1] * x * y * z,
            _C3[2] * y * (4.0 * zz - xx - yy),
            _C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            _C3[4] * x * (4.0 * zz - xx - yy),
            _C3[5] * z * (xx - yy),
            _C3[6] * x * (xx - 3.0 * yy),
        ]
    return torch.stack(cols, dim=-1)


def eval_sh(sh: torch.Tensor, dirs: torch.Tensor, degree: int | None = None) -> torch.Tensor:
    """View-dependent colour from SH coefficients (3DGS convention).

    Args:
        sh: [N, K, 3] coefficients, K in {1, 4, 9, 16}, DC first.
        dirs: [N, 3] unit directions from the camera centre to each Gaussian mean, world frame.
        degree: use only bands up to this degree (default: all K coefficients).

    Returns:
        [N, 3] colour ``max(sum_k Y_k(dir) sh[:, k] + 0.5, 0)``.
    """
    full = _K_TO_DEGREE[sh.shape[1]]
    deg = full if degree is None else min(int(degree), full)
    basis = sh_basis(dirs, deg)  # [N, K']
    rgb = torch.einsum("nk,nkc->nc", basis, sh[:, : basis.shape[1], :])
    return torch.clamp_min(rgb + 0.5, 0.0)


def rgb_to_sh_dc(rgb: torch.Tensor) -> torch.Tensor:
    """DC coefficient that renders as ``rgb`` (inverse of the degree-0 colour)."""
    return (rgb - 0.5) / SH_C0

"""Named constants of the splat rasterizer, each with the reason for its value.

The values follow the reference 3DGS CUDA rasterizer (Kerbl et al. 2023,
graphdeco-inria/diff-gaussian-rasterization) and gsplat (``cuda/include/Common.h``),
so that our renders can be compared with theirs.
"""

from __future__ import annotations

import math

__all__ = [
    "ALPHA_THRESHOLD",
    "MAX_ALPHA",
    "TRANSMITTANCE_THRESHOLD",
    "EXTENT_SIGMA",
    "MAX_EXPONENT",
    "LOWPASS_3DGS_PX2",
    "LOWPASS_2DGS_INV_SQ",
    "MEDIAN_TRANSMITTANCE",
    "FOV_CLAMP_MARGIN",
    "LOG_ALPHA_THRESHOLD",
]

#: A pair contributes only if its alpha is at least this (below one 8-bit level).
ALPHA_THRESHOLD: float = 1.0 / 255.0

#: Alpha is clamped to this so that transmittance never becomes exactly zero.
MAX_ALPHA: float = 0.99

#: A pair is composited only while the transmittance after it stays >= this value;
#: the first pair that would push it below ends the pixel (``(1 - MAX_ALPHA) ** 2``).
TRANSMITTANCE_THRESHOLD: float = 1e-4

#: Support of a Gaussian in Mahalanobis units: pairs beyond 3 sigma are dropped.
EXTENT_SIGMA: float = 3.0

#: Largest exponent ``sigma = 0.5 * d^T Sigma^-1 d`` inside the support (4.5).
MAX_EXPONENT: float = 0.5 * EXTENT_SIGMA**2

#: EWA low-pass of 3DGS: added to the diagonal of the 2D covariance, px^2 (Kerbl et al. 2023).
LOWPASS_3DGS_PX2: float = 0.3

#: 2DGS screen-space filter: rho_2d = LOWPASS_2DGS_INV_SQ * |x - c|^2 (Huang et al. 2024, sigma = 1/sqrt(2) px).
LOWPASS_2DGS_INV_SQ: float = 2.0

#: The median depth is taken where the transmittance first drops to or below this.
MEDIAN_TRANSMITTANCE: float = 0.5

#: The EWA Jacobian is evaluated with tx/tz, ty/tz clamped to the field of view widened by this
#: fraction of the half-FOV tangent (3DGS uses 1.3 x tan(fov/2); gsplat the asymmetric form).
FOV_CLAMP_MARGIN: float = 0.3

#: ``log(ALPHA_THRESHOLD)``: the kernels compare exponents instead of alphas.
LOG_ALPHA_THRESHOLD: float = math.log(ALPHA_THRESHOLD)

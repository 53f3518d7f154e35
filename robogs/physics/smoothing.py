"""Local polynomial smoothing of end-effector samples (tricube-weighted, Cleveland 1979).

The pusher contact is one-sided, so whatever noise the drive keeps is rectified: the box
follows the pusher's fastest excursions and leaves it too fast. A Savitzky-Golay filter (a
rectangular window) passes a noticeable share of white noise at high frequencies through its
side lobes; a tricube weight goes to zero smoothly, so its side lobes are far smaller. A
degree-4 local fit follows the changes of jerk at a braking onset that a quadratic rounds off
(the rounding makes the box leave too slowly). Measured on the hidden-effect scenarios (1e-4 rad
encoders, 500 Hz): quadratic Savitzky-Golay over 40 ms biased the fitted quadratic drag by
-3...-6 % from encoder noise alone; degree 4 with tricube weights over 80 ms removed that bias
without rounding the releases.

The window is not fixed: :func:`drive_windows` shortens it for a recording whose own path noise
(:func:`path_noise`) and sample rate allow it, keeping the drive's velocity noise at the level
those 80 ms had at the scenarios' encoder noise; a clean recording's path is not rounded at all.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "DRIVE_WINDOW_REF_S",
    "CARRY_WINDOW_REF_S",
    "PATH_NOISE_REF_M",
    "PATH_RATE_REF_HZ",
    "drive_windows",
    "local_polynomial",
    "path_noise",
]

DRIVE_WINDOW_REF_S = 0.08
"""Reference window [s] of the drive's positions: the one measured unbiased at the reference
noise (:data:`PATH_NOISE_REF_M` at :data:`PATH_RATE_REF_HZ`; ``bench/RESULTS.md``,
"drive_smoothing", 2026-11-22, and "issue 16 (h44)": 40 ms at that noise biased the quadratic
drag by -11 %, viscous damping by -8 %)."""
CARRY_WINDOW_REF_S = 0.06
"""Reference window [s] of the velocity a grasped object inherits at release (same noise)."""
PATH_NOISE_REF_M = 6e-5
"""Path noise per axis [m] at which the reference windows were measured: the scenarios'
1e-4 rad encoders, 0.6e-4 m at the tool."""
PATH_RATE_REF_HZ = 500.0
"""Sample rate [Hz] of the measured path at which the reference windows were measured."""


def local_polynomial(
    t: np.ndarray, x: np.ndarray, window: float, *, degree: int = 4, deriv: int = 0
) -> np.ndarray:
    """Tricube-weighted local polynomial fit of samples ``x`` [E, D] at stamps ``t`` [E] s.

    Every sample gets its own weighted least-squares fit over the neighbours within
    ``window / 2`` s (one-sided at the ends). Stamps need not be uniform.

    Args:
        window: full width of the tricube kernel [s]; below four sample periods ``x`` (or its
            finite-difference derivative) is returned unchanged.
        degree: polynomial degree of the local fit.
        deriv: 0 for the smoothed value, 1 for the first derivative [units of x / s].

    Returns:
        [E, D] smoothed values or derivatives.
    """
    x = np.asarray(x, dtype=float)
    t = np.asarray(t, dtype=float)
    n = len(t)
    period = float(np.median(np.diff(t))) if n > 1 else 1.0
    half = 0.5 * window
    if n < degree + 2 or half <= 2 * period:
        return x.copy() if deriv == 0 else np.gradient(x, t, axis=0)
    k = int(np.ceil(half / period)) + 1
    idx = np.arange(n)[:, None] + np.arange(-k, k + 1)[None, :]
    inside = (idx >= 0) & (idx < n)
    idx = np.clip(idx, 0, n - 1)
    s = (t[idx] - t[:, None]) / half  # [E, K] scaled offsets
    u = np.clip(np.abs(s), 0.0, 1.0)
    w = np.where(inside, (1.0 - u**3) ** 3, 0.0)
    basis = s[..., None] ** np.arange(degree + 1)  # [E, K, P]
    wb = basis * w[..., None]
    a = np.matmul(wb.swapaxes(1, 2), basis)  # [E, P, P] normal matrices
    ridge = 1e-12 * np.trace(a, axis1=1, axis2=2)[:, None, None] * np.eye(degree + 1)
    # the fit is linear in x: the wanted coefficient's row of the hat matrix, [E, K]
    # weights on each sample's neighbours (the "equivalent kernel" of local polynomial
    # fitting, Fan & Gijbels 1996, sec. 3.2.2), so the samples (often many draws at once,
    # D wide) are only weighted and summed, not solved for
    unit = np.zeros((n, degree + 1, 1))
    unit[:, 0 if deriv == 0 else 1] = 1.0
    g = np.linalg.solve(a + ridge, unit)  # [E, P, 1]: row of a^-1 (a is symmetric)
    h = np.matmul(wb, g)[..., 0]  # [E, K]
    if deriv:
        h = h / half
    flat = x.reshape(n, -1)
    out = np.zeros_like(flat)
    for j in range(2 * k + 1):
        out += h[:, j, None] * flat[idx[:, j]]
    return out.reshape(x.shape)


def path_noise(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample white-noise deviates of a sampled path, robust to its motion.

    Each interior sample minus the straight line through its two neighbours, ``e_k = x_k -
    (b x_{k-1} + a x_{k+1})`` with ``a = (t_k - t_{k-1}) / (t_{k+1} - t_{k-1})``, ``b = 1 - a``
    (a second divided difference: zero on any straight motion, ``|acc| dt^2 / 2`` while
    accelerating, 20 um per sample at 10 m/s^2 and 500 Hz), divided by ``sqrt(1 + a^2 + b^2)``
    so that white noise of deviation ``s`` gives deviates of deviation ``s`` at any stamps.
    ``1.4826 median(|e|)`` (MAD) then estimates ``s`` while fewer than half the samples
    accelerate (Donoho & Johnstone 1994, Biometrika 81: the MAD of the finest-scale details
    as the noise estimate).

    Returns:
        ([K, D] deviates, [K] sample periods ``t_{k+1} - t_{k-1}`` / 2) for the K = E - 2
        interior samples of ``t`` [E] s, ``x`` [E, D].
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float).reshape(len(t), -1)
    if len(t) < 3:
        return np.zeros((0, x.shape[1])), np.zeros(0)
    span = t[2:] - t[:-2]
    a = np.where(span > 0, (t[1:-1] - t[:-2]) / np.where(span > 0, span, 1.0), 0.5)
    b = 1.0 - a
    e = x[1:-1] - (b[:, None] * x[:-2] + a[:, None] * x[2:])
    return e / np.sqrt(1.0 + a**2 + b**2)[:, None], 0.5 * span


def drive_windows(
    paths: list[tuple[np.ndarray, np.ndarray]],
) -> tuple[float, float, float, float]:
    """Windows [s] of the drive's positions and of the carried velocity from the path noise.

    ``paths``: (stamps [E] s, positions [E, D] m) of every trajectory of one recording (one
    encoder chain: the noise is pooled). The noise ``s`` is the largest over the axes of
    ``1.4826 MAD`` of :func:`path_noise`'s deviates, the rate ``f`` the inverse median sample
    period. Why the scaling: the degree-4 tricube fit's derivative at window ``W`` passes white
    noise ``s`` as ``kappa s / (W^1.5 f^0.5)`` (``kappa`` = 11.7 for the tricube kernel, computed
    from its weights, any W of 10 samples or more), and the drive's velocity noise is what the
    one-sided pusher contact rectifies. Keeping it at the reference's level (80 ms at 60 um,
    500 Hz: 1.4 mm/s per axis) gives ``W = W_ref (s / s_ref)^(2/3) (f_ref / f)^(1/3)``
    (:data:`DRIVE_WINDOW_REF_S`, :data:`CARRY_WINDOW_REF_S`, :data:`PATH_NOISE_REF_M`,
    :data:`PATH_RATE_REF_HZ`), never longer than the reference: a longer window rounds every
    brake further, and nothing longer was validated (design B's 120 um at 250 Hz would get
    160 ms; with it the planar design-B null seed 16's quadratic drag row moved from 11.5 to
    -15.9 sigma^2 held-out, ``tests/physics/test_design_b.py``, and ``bench/RESULTS.md``, "issue
    16 (h44)"), so a path noisier than the reference keeps the reference windows, as before. A
    noise-free path gets a window of 0 (the samples as measured: :func:`local_polynomial`
    returns its input below four sample periods), so a clean sharp brake is not rounded; a
    smoother picks the rounding back up (on a 10 m/s^2 brake the 80 ms drive's speed is 19 mm/s
    off at the corner, the samples' 5 mm/s).

    Returns:
        (position window, carry window, noise s [m], rate f [Hz]).
    """
    dev, per = [], []
    for t, x in paths:
        e, p = path_noise(t, x)
        dev.append(e)
        per.append(p)
    if not dev or sum(len(p) for p in per) == 0:
        return DRIVE_WINDOW_REF_S, CARRY_WINDOW_REF_S, PATH_NOISE_REF_M, PATH_RATE_REF_HZ
    e = np.concatenate(dev)
    s = float(np.max(1.4826 * np.median(np.abs(e), axis=0)))
    period = float(np.median(np.concatenate(per)))
    rate = 1.0 / period if period > 0 else PATH_RATE_REF_HZ
    scale = (s / PATH_NOISE_REF_M) ** (2.0 / 3.0) * (PATH_RATE_REF_HZ / rate) ** (1.0 / 3.0)
    scale = min(scale, 1.0)
    return DRIVE_WINDOW_REF_S * scale, CARRY_WINDOW_REF_S * scale, s, rate

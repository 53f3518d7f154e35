"""Time derivatives of sampled joint signals: Savitzky-Golay on the int64-ns time base.

A Savitzky-Golay filter (Savitzky & Golay 1964) fits a polynomial of degree ``polyorder`` to a
window of samples around each sample by least squares and returns the polynomial's value or
derivative at that sample.

* **Uniform sampling** (every step within 1 % of the median step): ``scipy.signal.savgol_filter``
  with ``delta`` = the median step in seconds and ``mode="interp"`` (the edge samples use the
  polynomial fitted to the first/last full window).
* **Non-uniform sampling**: the same least-squares polynomial fitted *locally on the true
  stamps* (no resampling): for sample ``i`` the window holds the ``w`` samples centred on ``i``
  (shifted inwards at the edges), the abscissa is ``t_k - t_i`` in seconds, and the derivative
  is read from the fitted coefficients at ``t_i``. On uniform data this equals the filter above.

The window length in samples is ``round(window_s / median_step)`` made odd and at least
``polyorder + 2``; it shrinks to the (odd) series length for short series.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import savgol_filter

from robogs.format.errors import InputError

__all__ = ["savgol_derivative", "describe_differentiator", "WINDOW_S", "POLYORDER"]

WINDOW_S = 0.1
"""Default window, seconds."""
POLYORDER = 3
"""Default polynomial degree."""


def describe_differentiator(
    order: int, *, window_s: float = WINDOW_S, polyorder: int = POLYORDER
) -> str:
    """One-line description recorded in a stream's ``derived`` entry."""
    return f"savitzky_golay(deriv={order}, window_s={window_s:g}, polyorder={polyorder}, t_ns time base)"


def _window(n: int, step_s: float, window_s: float, polyorder: int) -> int:
    w = int(round(window_s / step_s)) if step_s > 0 else n
    w = max(w, polyorder + 2)
    if w % 2 == 0:
        w += 1
    if w > n:
        w = n if n % 2 == 1 else n - 1
    return w


def savgol_derivative(
    t_ns: np.ndarray,
    y: np.ndarray,
    *,
    order: int = 1,
    window_s: float = WINDOW_S,
    polyorder: int = POLYORDER,
) -> np.ndarray:
    """Derivative of order ``order`` (0 = smoothing) of ``y`` with respect to time.

    Args:
        t_ns: [N] int64 stamps, strictly increasing, ns.
        y: [N] or [N, C] samples (e.g. rad).
        order: derivative order (0, 1 or 2 typically); must not exceed ``polyorder``.
        window_s: window length, seconds.
        polyorder: degree of the local polynomial.

    Returns:
        Array shaped like ``y`` in units of ``y`` per s^order.

    Raises:
        InputError: too few samples, non-increasing stamps or ``order > polyorder``.
    """
    t_ns = np.asarray(t_ns)
    y = np.asarray(y, dtype=np.float64)
    n = t_ns.shape[0]
    if order > polyorder:
        raise InputError(
            f"derivative order {order} exceeds polyorder {polyorder}", where="differentiator"
        )
    if n < polyorder + 2:
        raise InputError(
            f"{n} samples are too few to differentiate (need at least {polyorder + 2})",
            where="differentiator",
            hint="record longer segments or provide the velocity columns",
        )
    steps = np.diff(t_ns.astype(np.int64))
    if np.any(steps <= 0):
        raise InputError("stamps are not strictly increasing", where="differentiator")
    step_med = float(np.median(steps)) * 1e-9
    w = _window(n, step_med, window_s, polyorder)
    p = min(polyorder, w - 1)
    if order > p:
        raise InputError(
            f"window of {w} samples too short for derivative order {order}", where="differentiator"
        )
    uniform = np.max(np.abs(steps - np.median(steps))) <= 0.01 * np.median(steps)
    if uniform:
        return savgol_filter(y, w, p, deriv=order, delta=step_med, axis=0, mode="interp")
    return _local_poly(t_ns, y, w, p, order)


def _local_poly(t_ns: np.ndarray, y: np.ndarray, w: int, p: int, order: int) -> np.ndarray:
    n = t_ns.shape[0]
    half = w // 2
    start = np.clip(np.arange(n) - half, 0, n - w)
    idx = start[:, None] + np.arange(w)[None, :]  # [N, w]
    t0 = t_ns.astype(np.int64)
    dx = (t0[idx] - t0[:, None]).astype(np.float64) * 1e-9  # [N, w] s
    scale = np.maximum(np.abs(dx).max(axis=1, keepdims=True), 1e-12)
    xs = dx / scale
    vander = xs[..., None] ** np.arange(p + 1)  # [N, w, p+1]
    flat = y.reshape(n, -1)
    coef = np.linalg.pinv(vander) @ flat[idx]  # [N, p+1, C]
    out = coef[:, order, :] * math.factorial(order) / scale**order
    return out.reshape(y.shape)

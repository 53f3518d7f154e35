"""Compiled pusher-contact steps of the planar model (optional ``numba``, the ``fast`` extra).

:func:`robogs.physics.model._pusher_impulse` and :func:`~robogs.physics.model._pusher_apart` are
the reference: numpy on ``[M, T]`` states, where a few hundred states per step leave the cost in
numpy's per-operation overhead (about 100 operations a step; 0.26 ms of 0.5 ms a step on design
A's fits). The functions here are the same arithmetic as one loop per state, in the same order
and without fused or reassociated operations (``fastmath=False``), so their results are the
reference's to the bit (tests/physics/test_contact_kernels.py checks it on random states).

:func:`kernels` returns them when numba loads, else None with the reason, and
:func:`robogs.physics.model.simulate` then uses the numpy reference. Serial loops (no
``prange``): the caller's thread budget is left as set. Compiled once per machine and cached
next to this file (or in numba's user cache where the package folder is read-only).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["kernels", "unavailable_reason"]


def _build() -> tuple[Callable[..., Any], Callable[..., Any]]:
    import numba

    @numba.njit(cache=True, fastmath=False)
    def impulse(
        hx: float,
        hy: float,
        hz: float,
        radius: float,
        p: np.ndarray,
        cos_y: np.ndarray,
        sin_y: np.ndarray,
        vx: np.ndarray,
        vy: np.ndarray,
        wf: np.ndarray,
        com_x: np.ndarray,
        com_y: np.ndarray,
        mass: np.ndarray,
        inertia: np.ndarray,
        pts: np.ndarray,
        pv: np.ndarray,
        grasping: np.ndarray,
        dt: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m_n, t_n = vx.shape
        j_n = pts.shape[1]
        ovx, ovy, owf = np.empty_like(vx), np.empty_like(vy), np.empty_like(wf)
        ojx, ojy = np.empty_like(vx), np.empty_like(vy)
        nx_, ny_, rxn_, b_, gap_ = np.empty(2), np.empty(2), np.empty(2), np.empty(2), np.empty(2)
        act_ = np.zeros(2, np.bool_)
        for m in range(m_n):
            cx, cy = com_x[m, 0], com_y[m, 0]
            ms, ine = mass[m, 0], inertia[m, 0]
            for t in range(t_n):
                c, s = cos_y[m, t], sin_y[m, t]
                px, py, pz = p[m, t, 0], p[m, t, 1], p[m, t, 2]
                ox = px - (c * cx - s * cy)
                oy = py - (s * cx + c * cy)
                w = wf[m, t]
                for j in range(j_n):
                    dx, dy, dz = pts[t, j, 0] - ox, pts[t, j, 1] - oy, pts[t, j, 2] - pz
                    lx, ly = c * dx + s * dy, c * dy - s * dx
                    qx = min(max(lx, -hx), hx)
                    qy = min(max(ly, -hy), hy)
                    ex, ey = lx - qx, ly - qy
                    dist = math.sqrt(ex * ex + ey * ey)
                    pen_x, pen_y = hx - abs(lx), hy - abs(ly)
                    if dist > 1e-9:
                        safe = max(dist, 1e-12)
                        nlx, nly = ex / safe, ey / safe
                        g = dist - radius
                    else:
                        if pen_x < pen_y:
                            nlx, nly = np.sign(lx), 0.0
                        else:
                            nlx, nly = 0.0, np.sign(ly)
                        g = -min(pen_x, pen_y) - radius
                    nx, ny = c * nlx - s * nly, s * nlx + c * nly
                    qwx, qwy = c * qx - s * qy, s * qx + c * qy
                    rcx, rcy = ox + qwx - px, oy + qwy - py
                    vptx, vpty = vx[m, t] - w * rcy, vy[m, t] + w * rcx
                    rate_n = (pv[t, j, 0] - vptx) * nx + (pv[t, j, 1] - vpty) * ny
                    active = abs(dz) <= hz and not grasping[t]
                    target = (-g if g > 0 else -0.2 * g) / dt
                    nx_[j], ny_[j], rxn_[j], gap_[j] = nx, ny, rcx * ny - rcy * nx, g
                    b_[j] = target - rate_n if active else -1.0
                    act_[j] = active
                if j_n == 1:
                    lam = max(b_[0] / (1.0 / ms + rxn_[0] * rxn_[0] / ine), 0.0)
                    jx, jy, dw = lam * nx_[0], lam * ny_[0], lam * rxn_[0]
                else:
                    n1x, n1y, n2x, n2y = nx_[0], ny_[0], nx_[1], ny_[1]
                    r1, r2, b1, b2 = rxn_[0], rxn_[1], b_[0], b_[1]
                    inv_m, inv_i = 1.0 / ms, 1.0 / ine
                    k11 = inv_m + r1 * r1 * inv_i
                    k22 = inv_m + r2 * r2 * inv_i
                    k12 = (n1x * n2x + n1y * n2y) * inv_m + r1 * r2 * inv_i
                    det = max(k11 * k22 - k12 * k12, 1e-12)
                    l1b, l2b = (k22 * b1 - k12 * b2) / det, (k11 * b2 - k12 * b1) / det
                    l1s, l2s = b1 / k11, b2 / k22
                    only1 = b1 > 0 and b2 - k12 * l1s <= 0
                    only2 = b2 > 0 and b1 - k12 * l2s <= 0
                    if b1 <= 0 and b2 <= 0:
                        l1, l2 = 0.0, 0.0
                    elif only1:
                        l1, l2 = l1s, 0.0
                    elif only2:
                        l1, l2 = 0.0, l2s
                    else:
                        l1, l2 = l1b, l2b
                    l1, l2 = max(l1, 0.0), max(l2, 0.0)
                    flush = gap_[0] < 1e-3 and gap_[1] < 1e-3 and act_[0] and act_[1]
                    if flush and l1b + l2b > 0:
                        l1, l2 = l1b, l2b
                    jx, jy = l1 * n1x + l2 * n2x, l1 * n1y + l2 * n2y
                    dw = l1 * r1 + l2 * r2
                ovx[m, t], ovy[m, t] = vx[m, t] - jx / ms, vy[m, t] - jy / ms
                owf[m, t] = w - dw / ine
                ojx[m, t], ojy[m, t] = jx, jy
        return ovx, ovy, owf, ojx, ojy

    @numba.njit(cache=True, fastmath=False)
    def apart(
        half_diag: float,
        half_h: float,
        radius: float,
        p: np.ndarray,
        vx: np.ndarray,
        vy: np.ndarray,
        wf: np.ndarray,
        com_r: np.ndarray,
        pts: np.ndarray,
        pts_speed: np.ndarray,
        grasping: np.ndarray,
        two_dt: float,
    ) -> bool:
        m_n, t_n = vx.shape
        for m in range(m_n):
            lever = half_diag + com_r[m, 0]
            for t in range(t_n):
                if grasping[t]:
                    continue
                box_speed = math.sqrt(vx[m, t] * vx[m, t] + vy[m, t] * vy[m, t])
                box_speed = box_speed + abs(wf[m, t]) * lever
                for j in range(pts.shape[1]):
                    if abs(pts[t, j, 2] - p[m, t, 2]) > half_h:
                        continue
                    dx, dy = pts[t, j, 0] - p[m, t, 0], pts[t, j, 1] - p[m, t, 1]
                    gap_lb = math.sqrt(dx * dx + dy * dy) - (lever + radius)
                    reach = two_dt * (pts_speed[t, j] + box_speed)
                    if not gap_lb > max(reach, 1e-3):
                        return False
        return True

    return impulse, apart


_REASON: list[str] = []


@functools.lru_cache(maxsize=1)
def kernels() -> tuple[Callable[..., Any], Callable[..., Any]] | None:
    """The compiled ``(impulse, apart)`` kernels, or None when numba is missing or fails to
    load (:func:`unavailable_reason` says which)."""
    import importlib.util

    _REASON.clear()
    if importlib.util.find_spec("numba") is None:
        _REASON.append("needs the optional package numba (pip install 'robogs[fast]')")
        return None
    try:
        return _build()
    except Exception as exc:  # numba present but broken (e.g. numpy too new for it)
        _REASON.append(f"numba failed to load: {exc}")
        return None


def unavailable_reason() -> str | None:
    """Why :func:`kernels` is None (None when the kernels are available or not yet asked)."""
    return _REASON[-1] if _REASON else None

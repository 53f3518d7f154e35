"""Compiled steps of the planar model (optional ``numba``, the ``fast`` extra).

:data:`robogs.physics.model.REFERENCE_STEPS` are the reference: numpy on ``[M, T]`` states
(M parameter sets x T trajectories), where a few hundred states a step leave the cost in numpy's
per-operation overhead (in a profiled design-A diagnosis the model took 144 s on the reference
and 67 s on these kernels; bench/planar_steps.py times them in one run). The kernels here are
the same arithmetic as one loop per state, in the same order and without fused or reassociated
operations (``fastmath=False``), so their results are the reference's to the bit
(tests/physics/test_step_kernels.py checks each on random states, and whole rollouts). Effect
hooks stay in Python between them (:func:`~robogs.physics.model.simulate`).

:func:`kernels` returns them when numba loads, else None with the reason
(:func:`unavailable_reason`); the model then runs the reference. Serial loops (no ``prange``):
the caller's thread budget is left as set. Compiled once per machine and cached next to this
file (or in numba's user cache where the package folder is read-only).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["Kernels", "kernels", "unavailable_reason"]


class Kernels(NamedTuple):
    """The compiled steps (arguments: :data:`robogs.physics.model.REFERENCE_STEPS`' with the
    scene's scalars first for ``impulse`` and ``apart``; ``friction`` takes ``mu_s``, ``mu_d`` as
    [M, 1] or [M, T])."""

    normal: Callable[..., Any]
    friction: Callable[..., Any]
    apart: Callable[..., Any]
    impulse: Callable[..., Any]
    integrate: Callable[..., Any]
    carry: Callable[..., Any]


def _build() -> Kernels:
    import numba

    @numba.njit(cache=True, fastmath=False)
    def normal(
        v: np.ndarray,
        w: np.ndarray,
        acc: np.ndarray,
        alpha: np.ndarray,
        gap: np.ndarray,
        e_rest: np.ndarray,
        dt: float,
        g: float,
        bounce_min: float,
    ) -> tuple[np.ndarray, ...]:
        m_n, t_n = w.shape
        shape = (m_n, t_n)
        vx, vy, vz, wf = np.empty(shape), np.empty(shape), np.empty(shape), np.empty(shape)
        lam_n, approach = np.empty(shape), np.empty(shape)
        speed2, speed = np.empty(shape), np.empty(shape)
        contact = np.empty((m_n, t_n), np.bool_)
        rebound = np.empty((m_n, t_n), np.bool_)
        for m in range(m_n):
            e = e_rest[m, 0]
            for t in range(t_n):
                x = v[m, t, 0] + dt * acc[m, t, 0]
                y = v[m, t, 1] + dt * acc[m, t, 1]
                z = v[m, t, 2] + dt * (acc[m, t, 2] - g)
                ap = -z
                c = (gap[m, t] + dt * z) <= 0.0
                b = ap > bounce_min
                target = e * ap if b else -max(gap[m, t], 0.0) / dt
                lam = max(target - z, 0.0) if c else 0.0
                s2 = x * x + y * y
                vx[m, t], vy[m, t], vz[m, t] = x, y, z + lam
                wf[m, t] = w[m, t] + dt * alpha[m, t]
                lam_n[m, t], approach[m, t] = lam, ap
                contact[m, t], rebound[m, t] = c, c and b and lam > 0
                speed2[m, t], speed[m, t] = s2, math.sqrt(s2 + 1e-18)
        return vx, vy, vz, wf, lam_n, contact, rebound, approach, speed2, speed

    @numba.njit(cache=True, fastmath=False)
    def friction(
        vx: np.ndarray,
        vy: np.ndarray,
        wf: np.ndarray,
        speed2: np.ndarray,
        lam_n: np.ndarray,
        contact: np.ndarray,
        mu_s: np.ndarray,
        mu_d: np.ndarray,
        kr: np.ndarray,
        c_r: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m_n, t_n = vx.shape
        ovx, ovy, owf = np.empty((m_n, t_n)), np.empty((m_n, t_n)), np.empty((m_n, t_n))
        per_s, per_d = mu_s.shape[1] > 1, mu_d.shape[1] > 1
        for m in range(m_n):
            k = kr[m, 0]
            for t in range(t_n):
                f_t, f_r = 1.0, 1.0
                if contact[m, t]:
                    cw = c_r * wf[m, t]
                    q = cw / k
                    stop_norm = math.sqrt(speed2[m, t] + q * q)
                    xi = math.sqrt(speed2[m, t] + cw * cw) + 1e-15
                    if stop_norm <= mu_s[m, t if per_s else 0] * lam_n[m, t]:
                        f_t, f_r = 0.0, 0.0
                    else:
                        budget = mu_d[m, t if per_d else 0] * lam_n[m, t]
                        f_t = max(1.0 - budget / xi, 0.0)
                        f_r = max(1.0 - budget * k / xi, 0.0)
                ovx[m, t], ovy[m, t], owf[m, t] = vx[m, t] * f_t, vy[m, t] * f_t, wf[m, t] * f_r
        return ovx, ovy, owf

    @numba.njit(cache=True, fastmath=False)
    def integrate(
        p: np.ndarray,
        vx: np.ndarray,
        vy: np.ndarray,
        vz: np.ndarray,
        wf: np.ndarray,
        yaw: np.ndarray,
        rebound: np.ndarray,
        gap: np.ndarray,
        approach: np.ndarray,
        dt: float,
        z_rest: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        m_n, t_n = vx.shape
        p_new, v_new = np.empty((m_n, t_n, 3)), np.empty((m_n, t_n, 3))
        y_new = np.empty((m_n, t_n))
        for m in range(m_n):
            for t in range(t_n):
                v_new[m, t, 0], v_new[m, t, 1], v_new[m, t, 2] = vx[m, t], vy[m, t], vz[m, t]
                for i in range(3):
                    p_new[m, t, i] = p[m, t, i] + dt * v_new[m, t, i]
                if rebound[m, t]:
                    toi = min(max(gap[m, t], 0.0) / max(approach[m, t], 1e-9), dt)
                    p_new[m, t, 2] = z_rest + vz[m, t] * (dt - toi)
                y_new[m, t] = yaw[m, t] + dt * wf[m, t]
        return p_new, v_new, y_new

    @numba.njit(cache=True, fastmath=False)
    def carry(
        p: np.ndarray,
        v: np.ndarray,
        yaw: np.ndarray,
        w: np.ndarray,
        att: np.ndarray,
        c: np.ndarray,
        s: np.ndarray,
        ee_yaw: np.ndarray,
        rel_p: np.ndarray,
        rel_yaw: np.ndarray,
        ee_pos: np.ndarray,
        ee_rate: np.ndarray,
        ee_vel: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        p_new, v_new, y_new, w_new = p.copy(), v.copy(), yaw.copy(), w.copy()
        m_n, t_n = yaw.shape
        for t in range(t_n):
            if not att[t]:
                continue
            for m in range(m_n):
                rx = c[t] * rel_p[m, t, 0] - s[t] * rel_p[m, t, 1]
                ry = s[t] * rel_p[m, t, 0] + c[t] * rel_p[m, t, 1]
                p_new[m, t, 0] = ee_pos[t, 0] + rx
                p_new[m, t, 1] = ee_pos[t, 1] + ry
                p_new[m, t, 2] = ee_pos[t, 2] + rel_p[m, t, 2]
                v_new[m, t, 0] = ee_vel[t, 0] - ee_rate[t] * ry
                v_new[m, t, 1] = ee_vel[t, 1] + ee_rate[t] * rx
                v_new[m, t, 2] = ee_vel[t, 2]
                y_new[m, t] = ee_yaw[t] + rel_yaw[m, t]
                w_new[m, t] = ee_rate[t]
        return p_new, v_new, y_new, w_new

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

    return Kernels(normal, friction, apart, impulse, integrate, carry)


_REASON: list[str] = []


@functools.lru_cache(maxsize=1)
def kernels() -> Kernels | None:
    """The compiled steps, or None when numba is missing or fails to
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

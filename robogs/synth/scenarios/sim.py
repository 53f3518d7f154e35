"""Ground-truth simulator of the hidden-effect scenarios (numpy, written apart from the model).

It shares no code with ``robogs.physics``; it differs on purpose in its numerics so that
model-versus-truth errors are realistic:

* step 0.25 ms, explicit symplectic Euler (velocity, then position with the new velocity);
* the pusher (a horizontal capsule: two end spheres) is a stiff penalty spring-damper per
  sphere (k = 1e5 N/m, c = 600 N s/m, damper integrated implicitly), not an impulse;
* impacts with the table are events: the vertical velocity is reflected (restitution) and the
  box is put back on the plane;
* Coulomb friction on the planar twist (vx, vy, c_r w) with the ellipsoidal limit surface
  (Howe & Cutkosky 1996), sticking when the impulse needed to stop lies in the static cone.

Hidden effects are implemented here independently (in :func:`simulate_truth` and
``_mu_dynamic``); several may act at once (``TruthEffect("a+b", ...)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["TruthBox", "TruthEffect", "EEPath", "simulate_truth", "mean_radius"]


def mean_radius(sx: float, sy: float, n: int = 400) -> float:
    """Mean distance of a uniform sx x sy rectangle's points from its centre [m]."""
    u = (np.arange(n) + 0.5) / n - 0.5
    xx, yy = np.meshgrid(u * sx, u * sy, indexing="ij")
    return float(np.hypot(xx, yy).mean())


@dataclass(frozen=True)
class TruthBox:
    """The true box and scene: sizes [m], mass [kg], yaw inertia [kg m^2], friction, table."""

    size: tuple[float, float, float] = (0.08, 0.06, 0.05)
    mass: float = 0.4
    mu_s: float = 0.45
    mu_d: float = 0.35
    restitution: float = 0.0
    com: tuple[float, float] = (0.0, 0.0)
    table_z: float = 0.0
    pusher_radius: float = 0.01
    pusher_length: float = 0.04
    gravity: float = 9.81

    @property
    def inertia_z(self) -> float:
        return self.mass * (self.size[0] ** 2 + self.size[1] ** 2) / 12.0


@dataclass(frozen=True)
class TruthEffect:
    """Hidden effect of a scenario: ``name`` (catalogue name or ``"none"``) and its values."""

    name: str = "none"
    params: dict[str, float] = field(default_factory=dict)

    def get(self, key: str, default: float = 0.0) -> float:
        return float(self.params.get(key, default))

    @property
    def names(self) -> frozenset[str]:
        """The effects it holds: ``name`` split at ``+`` (two or more hidden at once, their
        ``params`` merged; the catalogue's contact effects share no parameter name)."""
        return frozenset(self.name.split("+"))


@dataclass
class EEPath:
    """End-effector motion sampled every ``dt`` [s]: positions [T, K, 3], yaw [T, K], grasp [T, K]."""

    dt: float
    pos: np.ndarray
    yaw: np.ndarray
    grasp: np.ndarray


def _rot(x: np.ndarray, y: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(a), np.sin(a)
    return c * x - s * y, s * x + c * y


def _mu_dynamic(box: TruthBox, eff: TruthEffect, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    speed = np.hypot(vx, vy)
    mu = np.full_like(speed, box.mu_d)
    if "stribeck" in eff.names:
        mu = mu * (1.0 + eff.get("dmu") * np.exp(-((speed / eff.get("v_s", 0.1)) ** 2)))
    if "anisotropic_friction" in eff.names:
        phi = np.arctan2(vy, vx)
        fac = 1.0 + eff.get("a_c") * np.cos(2 * phi) + eff.get("a_s") * np.sin(2 * phi)
        mu = np.where(speed > 1e-9, mu * fac, mu)
    return mu


def simulate_truth(
    box: TruthBox,
    eff: TruthEffect,
    path: EEPath,
    init_xy: np.ndarray,
    init_yaw: np.ndarray,
    *,
    mu_d: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate T trajectories; returns object-frame positions [T, K, 3] and yaw [T, K].

    Args:
        box: true scene constants (``mu_d`` overrides its dynamic friction).
        eff: the hidden effect (``"none"`` for the plain model).
        path: EE motion on the fine grid.
        init_xy: initial box centre [T, 2] m; init_yaw: [T] rad.
    """
    dt = path.dt
    n_t, n_k = path.pos.shape[:2]
    mu_dyn = box.mu_d if mu_d is None else mu_d
    mass = box.mass * (1.0 + eff.get("dm")) if "mass" in eff.names else box.mass
    box = TruthBox(**{**box.__dict__, "mu_d": mu_dyn, "mass": mass})
    m, inertia = box.mass, box.inertia_z  # uniform density: the inertia scales with the mass
    hx, hy, hz = (0.5 * s for s in box.size)
    z_rest = box.table_z + hz
    c_r = mean_radius(box.size[0], box.size[1])
    com = np.array(box.com, dtype=float)
    if "com_offset" in eff.names:
        com = com + np.array([eff.get("dx"), eff.get("dy")])
    e_rest = box.restitution + (eff.get("e_delta") if "restitution" in eff.names else 0.0)
    k_p = 1e5
    c_p = 600.0

    yaw = init_yaw.astype(float).copy()
    ox, oy = _rot(np.full(n_t, com[0]), np.full(n_t, com[1]), yaw)
    p = np.stack([init_xy[:, 0] + ox, init_xy[:, 1] + oy, np.full(n_t, z_rest)], axis=-1)
    v = np.zeros((n_t, 3))
    w = np.zeros(n_t)
    held = np.zeros(n_t, dtype=bool)
    rel = np.zeros((n_t, 3))
    rel_yaw = np.zeros(n_t)
    out_p = np.zeros((n_t, n_k, 3))
    out_y = np.zeros((n_t, n_k))
    ee_vel = np.zeros_like(path.pos)
    ee_vel[:, :-1] = np.diff(path.pos, axis=1) / dt
    ee_rate = np.zeros_like(path.yaw)
    ee_rate[:, :-1] = np.diff(path.yaw, axis=1) / dt

    for k in range(n_k):
        g_now = path.grasp[:, k]
        start = g_now & ~held
        if start.any():
            d = p - path.pos[:, k]
            rx, ry = _rot(d[:, 0], d[:, 1], -path.yaw[:, k])
            rel[start] = np.stack([rx, ry, d[:, 2]], axis=-1)[start]
            rel_yaw[start] = (yaw - path.yaw[:, k])[start]
        held = g_now
        # forces on the free box
        force = np.zeros((n_t, 3))
        force[:, 2] -= m * box.gravity
        torque = np.zeros(n_t)
        if "viscous_damping" in eff.names:
            force -= m * eff.get("c") * v
        if "quadratic_drag" in eff.names:
            force -= m * eff.get("k") * np.linalg.norm(v, axis=-1, keepdims=True) * v
        if "table_tilt" in eff.names:
            force[:, 0] += m * eff.get("g_x")
            force[:, 1] += m * eff.get("g_y")
        v = v + dt * force / m
        w = w + dt * torque / inertia
        # pusher: penalty spring-damper per capsule end sphere, damper implicit in velocity
        cx, cy = _rot(np.full(n_t, com[0]), np.full(n_t, com[1]), yaw)
        bx, by = p[:, 0] - cx, p[:, 1] - cy
        half = 0.5 * box.pusher_length
        axis = np.stack(
            [-np.sin(path.yaw[:, k]), np.cos(path.yaw[:, k]), 0 * path.yaw[:, k]], axis=-1
        )
        for sign in (1.0, -1.0) if half > 0 else (0.0,):
            ep = path.pos[:, k] + sign * half * axis
            epv = ee_vel[:, k] + sign * half * ee_rate[:, k, None] * np.stack(
                [-axis[:, 1], axis[:, 0], 0 * axis[:, 0]], axis=-1
            )
            d = ep - np.stack([bx, by, p[:, 2]], axis=-1)
            lx, ly = _rot(d[:, 0], d[:, 1], -yaw)
            qx, qy = np.clip(lx, -hx, hx), np.clip(ly, -hy, hy)
            ex, ey = lx - qx, ly - qy
            dist = np.hypot(ex, ey)
            ok = (dist > 1e-9) & (np.abs(d[:, 2]) <= hz) & ~held
            pen = box.pusher_radius - dist
            touch = ok & (pen > 0)
            if not touch.any():
                continue
            nlx, nly = ex / np.maximum(dist, 1e-12), ey / np.maximum(dist, 1e-12)
            nx, ny = _rot(nlx, nly, yaw)
            qwx, qwy = _rot(qx, qy, yaw)
            rcx, rcy = bx + qwx - p[:, 0], by + qwy - p[:, 1]
            vpx, vpy = v[:, 0] - w * rcy, v[:, 1] + w * rcx
            approach = (epv[:, 0] - vpx) * nx + (epv[:, 1] - vpy) * ny  # < 0: pushing in
            rxn = rcx * ny - rcy * nx
            k_eff = 1.0 / m + rxn * rxn / inertia
            imp = dt * (k_p * pen - c_p * approach) / (1.0 + c_p * dt * k_eff)
            imp = np.where(touch, np.maximum(imp, 0.0), 0.0)
            v[:, 0] -= imp * nx / m
            v[:, 1] -= imp * ny / m
            w = w - imp * rxn / inertia
        # table: impact event or resting contact, then friction with the normal impulse
        on = p[:, 2] + dt * v[:, 2] <= z_rest + 1e-12
        impact = on & (v[:, 2] < -0.05)
        vz_new = np.where(impact, -e_rest * v[:, 2], 0.0)
        jn = np.where(on, vz_new - v[:, 2], 0.0)  # per unit mass
        v[:, 2] = np.where(on, vz_new, v[:, 2])
        vx, vy = v[:, 0], v[:, 1]
        speed2 = vx * vx + vy * vy
        stop = np.sqrt(speed2 + (inertia * w / (m * c_r)) ** 2)
        xi = np.sqrt(speed2 + (c_r * w) ** 2) + 1e-15
        stick = on & (stop <= box.mu_s * jn)
        mu = _mu_dynamic(box, eff, vx, vy)
        kr = m * c_r**2 / inertia
        ft = np.where(on, np.clip(1.0 - mu * jn / xi, 0.0, None), 1.0)
        fr = np.where(on, np.clip(1.0 - mu * jn * kr / xi, 0.0, None), 1.0)
        ft = np.where(stick, 0.0, ft)
        fr = np.where(stick, 0.0, fr)
        v[:, 0] *= ft
        v[:, 1] *= ft
        w = w * fr
        p = p + dt * v
        p[:, 2] = np.maximum(p[:, 2], z_rest)
        yaw = yaw + dt * w
        if held.any():
            rx, ry = _rot(rel[:, 0], rel[:, 1], path.yaw[:, k])
            hp = path.pos[:, k] + np.stack([rx, ry, rel[:, 2]], axis=-1)
            hv = ee_vel[:, k] + np.stack([-ee_rate[:, k] * ry, ee_rate[:, k] * rx, 0 * rx], axis=-1)
            p[held] = hp[held]
            v[held] = hv[held]
            yaw[held] = (path.yaw[:, k] + rel_yaw)[held]
            w[held] = ee_rate[held, k]
        cx, cy = _rot(np.full(n_t, com[0]), np.full(n_t, com[1]), yaw)
        out_p[:, k] = np.stack([p[:, 0] - cx, p[:, 1] - cy, p[:, 2]], axis=-1)
        out_y[:, k] = yaw
    return out_p, out_y

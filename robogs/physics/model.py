"""Batched rigid-box model: a box on a table, pushed by or attached to the end effector.

Dynamics (per step ``dt``, default 1 ms), for ``M`` parameter sets x ``T`` trajectories at once:

* **Free motion** - Newton-Euler for the CoM position (3-D) and the yaw angle, integrated with
  semi-implicit (symplectic) Euler: velocities first (forces, then contact impulses), then
  positions with the new velocity, which is what the velocity-level contacts assume. Roll and
  pitch are not simulated: the box stays flat on one face (documented limitation; enough for
  pushing, sliding, lifting, placing).
* **Table contact** - a velocity-level impulse (speculative: it may close the remaining gap in
  the step), with Newton restitution ``e`` above ``bounce_min_speed``; a rebound starts at the
  time of impact inside the step. Friction is an impulse on
  the planar twist ``xi = (vx, vy, c_r * w)`` with the ellipsoidal limit surface of Howe &
  Cutkosky (1996): force ``-mu N xi/|xi|`` (torque limit ``mu N c_r``, ``c_r`` = mean distance
  of the footprint from its centre). The box sticks exactly when the impulse needed to stop it
  lies inside the static cone ``mu_s N dt``; otherwise the dynamic impulse ``mu_d N dt`` is
  applied without reversing the motion (Stewart & Trinkle 1996 style velocity-level Coulomb).
* **Pusher** - the end-effector link as a sphere, or a horizontal capsule along the EE y axis
  (its two end spheres), moving kinematically along the measured EE poses. It touches the box
  sides (planar contact while a sphere centre is within the box height). Frictionless,
  perfectly inelastic, speculative impulses keep every gap non-negative:
  ``gap/dt + rate + K lambda >= 0, lambda >= 0`` with complementarity, where ``K`` holds the
  effective inverse masses ``n_i.n_j/m + (r_i x n_i)(r_j x n_j)/I`` (velocity-level contact
  of Stewart & Trinkle 1996 / Catto's speculative contacts; the 2x2 LCP is solved exactly).
  When both capsule ends are within 1 mm of the box the capsule acts as a flat paddle: both
  contact rates are matched (no rigid-body rocking between the two end points).
  A point (sphere) pusher makes pushing unstable in yaw (tiny offsets grow), so scenarios use
  a capsule: a flat push is stable.
* **Grasp** - while the grasp flag is set, the object follows the EE with the relative transform
  it had when the flag rose; when it falls, the object is free with the EE velocity.

Measurement effects (time offset, frame error) act on the sampled poses; see
:func:`simulate`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple

import numpy as np
import torch

from robogs.physics.effects import Effect, overrides
from robogs.physics.space import BASE, ParamSpace

__all__ = ["BoxScene", "Body", "Drive", "FreeState", "Slip", "SimResult", "simulate", "yaw_rotate"]


@dataclass(frozen=True)
class BoxScene:
    """Constants of the scene (nominal physics.json values).

    Attributes:
        size: box edge lengths (x, y, z) [m], object frame = box centre.
        mass: [kg].
        inertia_z: yaw inertia about the CoM [kg m^2].
        com: CoM offset (x, y) in the object frame [m].
        friction_static, friction_dynamic: Coulomb coefficients box-table [-].
        restitution: Newton restitution box-table [-].
        damping_linear: viscous damping of the CoM velocity [1/s] (acceleration -c v).
        table_z: height of the table plane [m], world frame.
        pusher_radius: radius of the end-effector sphere or capsule [m].
        pusher_length: capsule length [m] along the EE y axis (0: a sphere). The capsule is
            modelled by its two end spheres: it must be narrower than the box face it pushes.
        gravity: magnitude of gravity along -z [m/s^2].
        dt: integration step [s].
        bounce_min_speed: approach speeds below this give a plastic impact [m/s].
        friction_bounds: (low, high) of the fitted dynamic friction coefficient [-] (the
            material prior's bounds recorded by ``robogs physics init``, else 0.02-2).
    """

    size: tuple[float, float, float]
    mass: float
    inertia_z: float
    com: tuple[float, float] = (0.0, 0.0)
    friction_static: float = 0.5
    friction_dynamic: float = 0.4
    restitution: float = 0.0
    damping_linear: float = 0.0
    table_z: float = 0.0
    pusher_radius: float = 0.01
    pusher_length: float = 0.0
    gravity: float = 9.81
    dt: float = 1e-3
    bounce_min_speed: float = 0.05
    friction_bounds: tuple[float, float] = (0.02, 2.0)

    @cached_property
    def friction_radius(self) -> float:
        """Mean distance of the footprint from its centre [m] (midpoint rule, 200x200)."""
        n = 200
        gx = (np.arange(n) + 0.5) / n - 0.5
        xx, yy = np.meshgrid(gx * self.size[0], gx * self.size[1], indexing="ij")
        return float(np.mean(np.hypot(xx, yy)))


@dataclass
class Body:
    """Per-parameter-set body constants, tensors of shape [M, 1] (``com``: [M, 1, 2])."""

    mass: torch.Tensor
    inertia_z: torch.Tensor
    com: torch.Tensor
    mu_s: torch.Tensor
    mu_d: torch.Tensor
    restitution: torch.Tensor
    damping: torch.Tensor


@dataclass
class FreeState:
    """What an ``accel`` hook sees: velocities [M, T, 3] m/s, yaw rate and yaw [M, T]."""

    v: torch.Tensor
    w: torch.Tensor
    yaw: torch.Tensor
    on_table: torch.Tensor
    body: Body


@dataclass
class Slip:
    """What a ``friction`` hook sees: planar CoM velocity [M, T] m/s, its norm, the yaw."""

    vx: torch.Tensor
    vy: torch.Tensor
    speed: torch.Tensor
    yaw: torch.Tensor


@dataclass
class Drive:
    """Measured inputs of T trajectories resampled on the simulation grid of S steps.

    Attributes:
        dt: step [s].
        pusher: EE (sphere centre) positions [T, S, 3] m, world.
        pusher_vel: forward-difference EE velocities [T, S, 3] m/s.
        ee_yaw: EE yaw [T, S] rad (unwrapped); ee_yaw_rate [T, S] rad/s.
        grasp: grasp flags [T, S] bool.
        init_pos: measured initial object position [T, 3] m (sensor frame).
        init_yaw: measured initial object yaw [T] rad (sensor frame).
        obs_t: object-pose stamps [T, N] s from the trajectory start; obs_mask [T, N] valid.
        init_vel: optional initial CoM velocity [T, 3] m/s (default: at rest).
        init_rate: optional initial yaw rate [T] rad/s about world z (default: 0).
        carry_vel: optional smoothed EE velocity [T, S, 3] m/s given to a carried object
            (default: ``pusher_vel``).
        wrench_bin: optional [T, S] int64: the wrench sample whose averaging window holds each
            step (-1: none); with it :func:`simulate` returns the pusher's contact force.
        wrench_width: [T, W] duration of each wrench sample's window [s].
        sample_dt: optional [T] s: the sample interval of the stream each trajectory's pusher
            path was linearly interpolated from (the median spacing of its stamps, e.g. 0.002
            for a 500 Hz encoder; NaN where unknown). The MuJoCo engine smooths its servo
            targets over it (``mujoco_engine.sample_steps``); None: not known (a path handed
            in on the grid), the engine then reads the spacing from the path itself.
        pusher_dofs: optional [T, S, J] rad or m: the robot pusher's servo DOFs beyond the
            pusher's position and yaw (``objects.pusher.geometry = "robot"``: the end
            effector's pitch and roll, the joints below the pusher link that move; names
            ``RobotPusher.dofs`` of :mod:`robogs.physics.engines.mujoco_robot`), linearly
            interpolated on the grid as ``ee_yaw``; None: none move.
    """

    dt: float
    pusher: torch.Tensor
    pusher_vel: torch.Tensor
    ee_yaw: torch.Tensor
    ee_yaw_rate: torch.Tensor
    grasp: torch.Tensor
    init_pos: torch.Tensor
    init_yaw: torch.Tensor
    obs_t: torch.Tensor
    obs_mask: torch.Tensor
    init_vel: torch.Tensor | None = None
    carry_vel: torch.Tensor | None = None
    wrench_bin: torch.Tensor | None = None
    wrench_width: torch.Tensor | None = None
    sample_dt: torch.Tensor | None = None
    pusher_dofs: torch.Tensor | None = None
    init_rate: torch.Tensor | None = None

    @property
    def n_traj(self) -> int:
        return int(self.pusher.shape[0])

    @property
    def n_steps(self) -> int:
        return int(self.pusher.shape[1])

    def subset(self, idx: list[int]) -> Drive:
        """The drive of a subset of trajectories."""
        ii = torch.as_tensor(idx, dtype=torch.long, device=self.pusher.device)
        return Drive(
            self.dt,
            *(
                getattr(self, f)[ii]
                for f in ("pusher", "pusher_vel", "ee_yaw", "ee_yaw_rate", "grasp")
            ),
            *(getattr(self, f)[ii] for f in ("init_pos", "init_yaw", "obs_t", "obs_mask")),
            None if self.init_vel is None else self.init_vel[ii],
            None if self.carry_vel is None else self.carry_vel[ii],
            None if self.wrench_bin is None else self.wrench_bin[ii],
            None if self.wrench_width is None else self.wrench_width[ii],
            None if self.sample_dt is None else self.sample_dt[ii],
            pusher_dofs=None if self.pusher_dofs is None else self.pusher_dofs[ii],
            init_rate=None if self.init_rate is None else self.init_rate[ii],
        )


@dataclass
class SimResult:
    """Sampled predictions in the sensor frame: pos [M, T, N, 3] m, yaw [M, T, N] rad.

    ``dense_pos`` [M, T, S, 3] / ``dense_yaw`` [M, T, S] hold the object-frame pose at every
    step (world frame, model clock). ``force`` [M, T, W, 3] N (when the drive has
    ``wrench_bin``): the force the object exerts on the pusher, world frame, averaged over each
    wrench sample's window (the contact impulses of its steps over its duration).
    """

    pos: torch.Tensor
    yaw: torch.Tensor
    dense_pos: torch.Tensor
    dense_yaw: torch.Tensor
    force: torch.Tensor | None = None


def yaw_rotate(
    x: torch.Tensor, y: torch.Tensor, yaw: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Rotate planar vectors (x, y) by ``yaw`` [rad] about z."""
    c, s = torch.cos(yaw), torch.sin(yaw)
    return c * x - s * y, s * x + c * y


def _base_body(scene: BoxScene, theta: torch.Tensor, space: ParamSpace) -> Body:
    m = theta.shape[0]

    def const(v: float) -> torch.Tensor:
        return torch.full((m, 1), float(v), dtype=theta.dtype, device=theta.device)

    base = space.theta_dict(theta, BASE)
    mu_d = base.get("friction_dynamic", const(scene.friction_dynamic))
    mu_s = base.get("friction_static", const(scene.friction_static))
    mu_s = torch.maximum(mu_s, mu_d)
    com = (
        torch.tensor(scene.com, dtype=theta.dtype, device=theta.device)
        .view(1, 1, 2)
        .expand(m, 1, 2)
    )
    return Body(
        mass=base.get("mass", const(scene.mass)),
        inertia_z=const(scene.inertia_z),
        com=com,
        mu_s=mu_s,
        mu_d=mu_d,
        restitution=base.get("restitution", const(scene.restitution)),
        damping=base.get("damping_linear", const(scene.damping_linear)),
    )


def _pusher_points(
    scene: BoxScene, c: torch.Tensor, cv: torch.Tensor, psi: torch.Tensor, rate: torch.Tensor
) -> tuple[np.ndarray, np.ndarray]:
    """End-sphere centres and velocities [T, S, J, 3] of the capsule (J = 1 for a sphere).

    Args:
        c, cv: EE position [m] and velocity [m/s], [T, S, 3], world; psi, rate: EE yaw [rad]
            and yaw rate [rad/s], [T, S]. Computed once for the whole drive.
    """
    if scene.pusher_length <= 0.0:
        return c.unsqueeze(-2).numpy(), cv.unsqueeze(-2).numpy()
    half = 0.5 * scene.pusher_length
    ax, ay = -torch.sin(psi) * half, torch.cos(psi) * half  # EE y axis
    zero = 0 * ax
    off = torch.stack([torch.stack([ax, ay, zero], -1), torch.stack([-ax, -ay, zero], -1)], -2)
    voff = torch.stack(
        [
            torch.stack([-rate * ay, rate * ax, zero], -1),
            torch.stack([rate * ay, -rate * ax, zero], -1),
        ],
        -2,
    )
    return (c.unsqueeze(-2) + off).numpy(), (cv.unsqueeze(-2) + voff).numpy()


class PusherContacts(NamedTuple):
    """The pusher's end spheres against the box sides in one step (:func:`pusher_contacts`),
    each [M, T, J]: world contact normal ``nx, ny`` (box -> sphere), ``rxn`` [m] (the contact
    lever, ``r x n`` about the CoM), ``gap`` [m] (negative: penetration), ``rate_n`` [m/s]
    (the sphere's normal speed relative to the box point, negative: closing) and ``active``
    (the sphere is within the box's height band and not grasping)."""

    nx: np.ndarray
    ny: np.ndarray
    rxn: np.ndarray
    gap: np.ndarray
    rate_n: np.ndarray
    active: np.ndarray


def pusher_contacts(
    scene: BoxScene,
    p: np.ndarray,
    cos_y: np.ndarray,
    sin_y: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    wf: np.ndarray,
    com_x: np.ndarray,
    com_y: np.ndarray,
    pts: np.ndarray,
    pv: np.ndarray,
    grasping: np.ndarray,
) -> PusherContacts:
    """Closest points of the pusher's end spheres on the box sides (arguments as
    :func:`_pusher_impulse`'s; ``com_x``, ``com_y`` [M, 1] or [M, T])."""
    hx, hy, hz = (0.5 * s for s in scene.size)
    pts, pv = pts[None], pv[None]  # [1, T, J, 3]
    c_, s_ = cos_y[..., None], sin_y[..., None]  # [M, T, 1]
    px, py, pz = p[..., 0:1], p[..., 1:2], p[..., 2:3]
    cx, cy = com_x[..., None], com_y[..., None]
    # rotations by +yaw (body -> world) and by -yaw (world -> body) share one cos/sin
    ox_, oy_ = px - (c_ * cx - s_ * cy), py - (s_ * cx + c_ * cy)
    dx, dy, dz = pts[..., 0] - ox_, pts[..., 1] - oy_, pts[..., 2] - pz
    lx, ly = c_ * dx + s_ * dy, c_ * dy - s_ * dx
    qx, qy = np.clip(lx, -hx, hx), np.clip(ly, -hy, hy)
    ex, ey = lx - qx, ly - qy
    dist_c = np.sqrt(ex * ex + ey * ey)
    outside = dist_c > 1e-9
    pen_x, pen_y = hx - np.abs(lx), hy - np.abs(ly)
    use_x = pen_x < pen_y
    safe = np.maximum(dist_c, 1e-12)
    nlx = np.where(outside, ex / safe, np.where(use_x, np.sign(lx), 0.0))
    nly = np.where(outside, ey / safe, np.where(use_x, 0.0, np.sign(ly)))
    gap = np.where(outside, dist_c, -np.minimum(pen_x, pen_y)) - scene.pusher_radius
    nx, ny = c_ * nlx - s_ * nly, s_ * nlx + c_ * nly
    qwx, qwy = c_ * qx - s_ * qy, s_ * qx + c_ * qy
    rcx, rcy = ox_ + qwx - px, oy_ + qwy - py
    w_ = wf[..., None]
    vptx, vpty = vx[..., None] - w_ * rcy, vy[..., None] + w_ * rcx
    rate_n = (pv[..., 0] - vptx) * nx + (pv[..., 1] - vpty) * ny
    active = (np.abs(dz) <= hz) & ~grasping[None, :, None]
    return PusherContacts(nx, ny, rcx * ny - rcy * nx, gap, rate_n, active)


def _pusher_impulse(
    scene: BoxScene,
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
) -> tuple[np.ndarray, ...]:
    """Frictionless, inelastic, speculative contact of the pusher's end spheres with the box.

    With two end spheres the 2x2 linear complementarity problem is solved exactly by
    enumerating its four cases (Cottle, Pang & Stone 1992); one sphere is the scalar case.

    Args:
        p: CoM [M, T, 3] m; cos_y, sin_y: of the box yaw [M, T]; vx, vy [M, T] m/s and wf
            [M, T] rad/s: the box's velocities before the contact; com_x, com_y, mass,
            inertia: [M, 1] (or [M, T]); pts, pv: end-sphere centres [m] and velocities [m/s]
            [T, J, 3]; grasping: [T] bool (no pusher contact while grasped).

    Returns:
        the box's vx, vy, yaw rate after the contact, and the impulse [N s] the box gives the
        pusher in this step (x, y, world; the reaction of the one the pusher gives the box).
    """
    nx, ny, rxn, gap, rate_n, active = pusher_contacts(
        scene, p, cos_y, sin_y, vx, vy, wf, com_x, com_y, pts, pv, grasping
    )
    # speculative for open gaps, soft (Baumgarte 0.2) push-out of penetrations
    target = np.where(gap > 0, -gap, -0.2 * gap) / dt
    b = np.where(active, target - rate_n, -1.0)
    if b.shape[-1] == 1:
        lam = np.maximum(b / (1.0 / mass[..., None] + rxn * rxn / inertia[..., None]), 0.0)
        jx, jy = lam[..., 0] * nx[..., 0], lam[..., 0] * ny[..., 0]
        dw = lam[..., 0] * rxn[..., 0]
    else:
        n1x, n1y, n2x, n2y = nx[..., 0], ny[..., 0], nx[..., 1], ny[..., 1]
        r1, r2 = rxn[..., 0], rxn[..., 1]
        inv_m, inv_i = 1.0 / mass, 1.0 / inertia
        k11 = inv_m + r1 * r1 * inv_i
        k22 = inv_m + r2 * r2 * inv_i
        k12 = (n1x * n2x + n1y * n2y) * inv_m + r1 * r2 * inv_i
        b1, b2 = b[..., 0], b[..., 1]
        det = np.maximum(k11 * k22 - k12 * k12, 1e-12)
        l1b, l2b = (k22 * b1 - k12 * b2) / det, (k11 * b2 - k12 * b1) / det
        l1s, l2s = b1 / k11, b2 / k22
        only1 = (b1 > 0) & (b2 - k12 * l1s <= 0)
        only2 = (b2 > 0) & (b1 - k12 * l2s <= 0)
        none = (b1 <= 0) & (b2 <= 0)
        l1 = np.where(none, 0.0, np.where(only1, l1s, np.where(only2, 0.0, l1b)))
        l2 = np.where(none, 0.0, np.where(only1, 0.0, np.where(only2, l2s, l2b)))
        l1, l2 = np.maximum(l1, 0.0), np.maximum(l2, 0.0)
        # flush face: both ends within 1 mm and pushing -> the capsule holds the face like a
        # paddle (both rates matched, one end may pull slightly), which stops rigid rocking
        flush = (gap[..., 0] < 1e-3) & (gap[..., 1] < 1e-3) & active[..., 0] & active[..., 1]
        flush &= l1b + l2b > 0
        l1, l2 = np.where(flush, l1b, l1), np.where(flush, l2b, l2)
        jx, jy = l1 * n1x + l2 * n2x, l1 * n1y + l2 * n2y
        dw = l1 * r1 + l2 * r2
    return vx - jx / mass, vy - jy / mass, wf - dw / inertia, jx, jy


def _pusher_apart(
    scene: BoxScene,
    p: np.ndarray,
    vx: np.ndarray,
    vy: np.ndarray,
    wf: np.ndarray,
    com_r: np.ndarray,
    pts: np.ndarray,
    pts_speed: np.ndarray,
    grasping: np.ndarray,
    dt: float,
) -> bool:
    """Whether no end sphere can touch its box in this step, so that the contact impulse of
    :func:`_pusher_impulse` is exactly zero and the step may skip it.

    A sphere cannot touch when it is out of the contact band (above or below the box's half
    height, or grasping), or when a lower bound of its gap (its planar distance from the CoM,
    less the CoM offset ``com_r`` [M, 1] m, the box's half diagonal and the radius) exceeds
    the flush-face band (1 mm) and twice the distance the fastest closing motion covers in one
    step: the sphere's planar speed ``pts_speed`` [T, J] m/s plus the box point's (CoM speed +
    yaw rate x lever). Then every speculative target ``-gap / dt`` is below the closing rate
    and no LCP case gives an impulse.
    """
    half_diag = 0.5 * float(np.hypot(scene.size[0], scene.size[1]))
    lever = half_diag + com_r  # [M, 1]
    d = pts[None, :, :, :2] - p[:, :, None, :2]  # [M, T, J, 2]
    gap_lb = np.sqrt((d * d).sum(-1)) - (lever[..., None] + scene.pusher_radius)
    box_speed = np.sqrt(vx * vx + vy * vy) + np.abs(wf) * lever  # [M, T]
    reach = 2.0 * dt * (pts_speed[None] + box_speed[..., None])
    off_band = (np.abs(pts[None, ..., 2] - p[..., 2:3]) > 0.5 * scene.size[2]) | grasping[
        None, :, None
    ]
    return bool((off_band | (gap_lb > np.maximum(reach, 1e-3))).all())


def _table_normal(
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
    """One step's free dynamics and the table's normal impulse (per unit mass, m/s).

    Args:
        v [M, T, 3] m/s, w [M, T] rad/s: velocities at the step's start; acc [M, T, 3] m/s^2,
            alpha [M, T] rad/s^2: external accelerations (gravity ``g`` m/s^2 apart); gap
            [M, T] m: CoM height above its resting height; e_rest [M, 1]: restitution.

    Returns:
        vx, vy, vz, wf after the impulse; lam_n, the impulse; contact, rebound [M, T] bool; the
        approach speed; speed2 and speed (``sqrt(speed2 + 1e-18)``) of the planar velocity.
    """
    vx = v[..., 0] + dt * acc[..., 0]
    vy = v[..., 1] + dt * acc[..., 1]
    vz = v[..., 2] + dt * (acc[..., 2] - g)
    wf = w + dt * alpha
    approach = -vz
    contact = (gap + dt * vz) <= 0.0
    bounce = approach > bounce_min
    target = np.where(bounce, e_rest * approach, -np.maximum(gap, 0.0) / dt)
    lam_n = np.where(contact, np.maximum(target - vz, 0.0), 0.0)
    vz = vz + lam_n
    # a bounce starts at the time of impact inside the step, not at the step's start
    # (otherwise the box would rebound from up to approach * dt above the table)
    rebound = contact & bounce & (lam_n > 0)
    speed2 = vx * vx + vy * vy
    speed = np.sqrt(speed2 + 1e-18)
    return vx, vy, vz, wf, lam_n, contact, rebound, approach, speed2, speed


def _table_friction(
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
    """The table's friction on the twist (vx, vy, c_r w) [M, T]: stick when the impulse that
    stops it is inside the static cone, else shrink it by the dynamic budget (``kr`` [M, 1]:
    mass c_r^2 / inertia; ``mu_s``, ``mu_d`` broadcast to [M, T])."""
    cw = c_r * wf
    stop_norm = np.sqrt(speed2 + (cw / kr) ** 2)
    xi = np.sqrt(speed2 + cw * cw) + 1e-15
    stick = stop_norm <= mu_s * lam_n
    budget = mu_d * lam_n
    f_t = np.where(stick, 0.0, np.maximum(1.0 - budget / xi, 0.0))
    f_r = np.where(stick, 0.0, np.maximum(1.0 - budget * kr / xi, 0.0))
    f_t = np.where(contact, f_t, 1.0)
    f_r = np.where(contact, f_r, 1.0)
    return vx * f_t, vy * f_t, wf * f_r


def _integrate(
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
    """Semi-implicit Euler: the new CoM [M, T, 3] (a rebound from its time of impact), velocity
    [M, T, 3] and yaw [M, T]."""
    v_new = np.stack([vx, vy, vz], axis=-1)
    p = p + dt * v_new
    if rebound.any():
        toi = np.minimum(np.maximum(gap, 0.0) / np.maximum(approach, 1e-9), dt)
        p[..., 2] = np.where(rebound, z_rest + vz * (dt - toi), p[..., 2])
    return p, v_new, yaw + dt * wf


def _grasp_carry(
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
    """Grasped objects ride the end effector rigidly (yaw-only EE frame).

    p [M, T, 3] m, v [M, T, 3] m/s, yaw [M, T] rad, w [M, T] rad/s: the state after the step;
    att [T]: grasping; c, s, ee_yaw [T]: cos, sin and the EE yaw (rad, world); rel_p [M, T, 3]
    m, rel_yaw [M, T] rad: the object in the EE frame at the grasp's onset; ee_pos [T, 3] m,
    ee_rate [T] rad/s, ee_vel [T, 3] m/s: the EE (carry point) at the step's end. Returns new
    p, v, yaw, w (the grasped ones replaced)."""
    rx = c * rel_p[..., 0] - s * rel_p[..., 1]
    ry = s * rel_p[..., 0] + c * rel_p[..., 1]
    p_att = np.stack([ee_pos[..., 0] + rx, ee_pos[..., 1] + ry, ee_pos[..., 2] + rel_p[..., 2]], -1)
    v_att = np.stack(
        [
            ee_vel[..., 0] - ee_rate * ry,
            ee_vel[..., 1] + ee_rate * rx,
            np.broadcast_to(ee_vel[..., 2], rx.shape),
        ],
        -1,
    )
    p = np.where(att[..., None], p_att, p)
    v = np.where(att[..., None], v_att, v)
    yaw = np.where(att, ee_yaw + rel_yaw, yaw)
    w = np.where(att, np.broadcast_to(ee_rate, w.shape), w)
    return p, v, yaw, w


class _Steps(NamedTuple):
    """The step functions of :func:`simulate` (numpy here, or numba's copies)."""

    normal: Callable[..., tuple[np.ndarray, ...]]
    friction: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]]
    apart: Callable[..., bool]
    impulse: Callable[..., tuple[np.ndarray, ...]]
    integrate: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray]]
    carry: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]


REFERENCE_STEPS = _Steps(
    _table_normal, _table_friction, _pusher_apart, _pusher_impulse, _integrate, _grasp_carry
)
"""The numpy step functions: the reference the compiled ones match to the bit."""


def _mt(mu: np.ndarray, like: np.ndarray) -> np.ndarray:
    """A friction coefficient as [M, 1] or [M, T] float64 (``like``: [M, T]), broadcast only
    when it is neither."""
    mu = np.asarray(mu, dtype=np.float64)
    if mu.ndim == 2 and mu.shape[0] == like.shape[0] and mu.shape[1] in (1, like.shape[1]):
        return mu
    return np.broadcast_to(mu, like.shape)


def _steps(dtype: np.dtype) -> _Steps:
    """The step functions: numba's compiled copies where they load and the state is float64
    (:mod:`robogs.physics.step_kernels`; the same results to the bit), else the numpy
    :data:`REFERENCE_STEPS`."""
    from robogs.physics.step_kernels import kernels

    k = kernels() if dtype == np.float64 else None
    if k is None:
        return REFERENCE_STEPS

    def impulse(scene: BoxScene, *args: Any) -> tuple[np.ndarray, ...]:
        hx, hy, hz = (0.5 * s for s in scene.size)
        return k.impulse(hx, hy, hz, scene.pusher_radius, *args)

    def apart(scene: BoxScene, p, vx, vy, wf, com_r, pts, pts_speed, grasping, dt) -> bool:
        half_diag = 0.5 * float(np.hypot(scene.size[0], scene.size[1]))
        args = (p, vx, vy, wf, com_r, pts, pts_speed, grasping, 2.0 * dt)
        return bool(k.apart(half_diag, 0.5 * scene.size[2], scene.pusher_radius, *args))

    def friction(vx, vy, wf, speed2, lam_n, contact, mu_s, mu_d, kr, c_r):
        return k.friction(vx, vy, wf, speed2, lam_n, contact, _mt(mu_s, vx), _mt(mu_d, vx), kr, c_r)

    return _Steps(k.normal, friction, apart, impulse, k.integrate, k.carry)


def _numpy(x: torch.Tensor) -> np.ndarray:
    """A CPU float array of ``x`` (a copy; no autograd)."""
    return x.detach().cpu().numpy().copy()


def _state_view(x: np.ndarray) -> torch.Tensor:
    """The torch view of a state array that effect hooks see."""
    return torch.from_numpy(x)


def _hook_out(x: torch.Tensor | float) -> np.ndarray:
    """An effect hook's output as an array."""
    return np.asarray(x.detach() if isinstance(x, torch.Tensor) else x)


def simulate(
    theta: torch.Tensor,
    space: ParamSpace,
    drive: Drive,
    scene: BoxScene,
    init_offset: torch.Tensor | None = None,
) -> SimResult:
    """Roll out M parameter sets over T trajectories and sample the object poses.

    The rollout steps arrays of [M, T] states in numpy on the CPU: with a few hundred states
    per step the cost is the per-operation overhead, about four times lower than torch's.
    Effect hooks still see torch tensors (views of the state). There are no gradients: the
    fitter differentiates by finite differences. Results are tensors on ``theta``'s device.

    Args:
        theta: [M, Q] parameter sets over ``space`` (float64 recommended).
        space: slots (base parameters + effects); effects with ``model="rigid"`` act.
        drive: measured inputs on the simulation grid.
        scene: nominal constants.
        init_offset: [M, T, 3] corrections (dx [m], dy [m], dyaw [rad]) of the measured
            initial pose, the per-trajectory nuisance parameters of the fitter.

    Returns:
        Object poses at the measurement stamps, as the sensor would report them.
    """
    dev = theta.device
    theta = theta.detach().cpu()
    dt_ = theta.dtype
    m_sets, n_t, n_s = theta.shape[0], drive.n_traj, drive.n_steps
    dt = drive.dt
    effects: list[tuple[Effect, dict[str, torch.Tensor]]] = [
        (e, space.theta_dict(theta, e.name)) for e in space.effects if e.model == "rigid"
    ]
    body = _base_body(scene, theta, space)
    for e, th in effects:
        if overrides(e, "body"):
            body = e.body(th, body)
    accel_fx = [(e, th) for e, th in effects if overrides(e, "accel")]
    fric_fx = [(e, th) for e, th in effects if overrides(e, "friction")]
    sensor_fx = [(e, th) for e, th in effects if e.family == "sensor"]

    hx, hy, hz = (0.5 * s for s in scene.size)
    z_rest = scene.table_z + hz
    c_r = scene.friction_radius
    mass, inertia = _numpy(body.mass), _numpy(body.inertia_z)  # [M, 1]
    kr = mass * c_r**2 / inertia  # [M, 1]
    com_x, com_y = _numpy(body.com[..., 0]), _numpy(body.com[..., 1])  # [M, 1]
    com_r = np.hypot(com_x, com_y)  # [M, 1]
    mu_s0, mu_d0 = _numpy(body.mu_s), _numpy(body.mu_d)
    e_rest, damping = _numpy(body.restitution), _numpy(body.damping)
    has_damping = bool((damping != 0).any())

    def drive_array(x: torch.Tensor) -> torch.Tensor:
        return x.detach().cpu().to(dt_)

    pusher_t = drive_array(drive.pusher)
    pusher = pusher_t.numpy()
    cvel_all = drive_array(drive.pusher_vel if drive.carry_vel is None else drive.carry_vel)
    cvel_all = cvel_all.numpy()
    ee_yaw_t, ee_rate_t = drive_array(drive.ee_yaw), drive_array(drive.ee_yaw_rate)
    ee_yaw, ee_rate = ee_yaw_t.numpy(), ee_rate_t.numpy()
    pts_all, pv_all = _pusher_points(
        scene, pusher_t, drive_array(drive.pusher_vel), ee_yaw_t, ee_rate_t
    )  # [T, S, J, 3]
    pts_speed = np.hypot(pv_all[..., 0], pv_all[..., 1])  # [T, S, J] planar, m/s
    grasp = drive.grasp.detach().cpu().numpy()
    grasp_any = grasp.any(axis=0)
    onset = np.zeros_like(grasp)
    onset[:, 1:] = grasp[:, 1:] & ~grasp[:, :-1]
    onset[:, 0] = grasp[:, 0]
    onset_any = onset.any(axis=0)
    # steps where some pusher could touch a box resting on the table or lifted by < 5 box heights
    pz = drive.pusher[..., 2].cpu().numpy()
    pusher_low = (pz < z_rest + 10 * hz + scene.pusher_radius).any(axis=0)

    # initial state: measured pose -> world (inverse sensor effects, last first)
    ipos = drive.init_pos.to(theta.device, dt_).unsqueeze(0).expand(m_sets, n_t, 3)
    iyaw = drive.init_yaw.to(theta.device, dt_).unsqueeze(0).expand(m_sets, n_t)
    if init_offset is not None:
        off = init_offset.detach().cpu().to(dt_)
        ipos = ipos + torch.nn.functional.pad(off[..., :2], (0, 1))
        iyaw = iyaw + off[..., 2]
    for e, th in reversed(sensor_fx):
        ipos, iyaw = e.from_sensor(th, ipos, iyaw)
    ox, oy = yaw_rotate(body.com[..., 0], body.com[..., 1], iyaw)
    p = _numpy(torch.stack([ipos[..., 0] + ox, ipos[..., 1] + oy, ipos[..., 2]], dim=-1))
    yaw = _numpy(iyaw)
    v = np.zeros_like(p)
    if drive.init_vel is not None:
        v = v + drive_array(drive.init_vel).numpy()[None]
    w = np.zeros_like(yaw)
    if drive.init_rate is not None:
        w = w + drive_array(drive.init_rate).numpy()[None]
    rel_p = np.zeros_like(p)
    rel_yaw = np.zeros_like(yaw)
    g = scene.gravity

    def grasp_onset(k: int, on: np.ndarray) -> None:
        """Relative transform of the object in the EE frame (yaw-only) where a grasp starts."""
        nonlocal rel_p, rel_yaw
        d = p - pusher[None, :, k]
        c, s = np.cos(ee_yaw[None, :, k]), np.sin(ee_yaw[None, :, k])
        rx, ry = c * d[..., 0] + s * d[..., 1], c * d[..., 1] - s * d[..., 0]
        rel_p = np.where(on[None, :, None], np.stack([rx, ry, d[..., 2]], axis=-1), rel_p)
        rel_yaw = np.where(on[None], yaw - ee_yaw[None, :, k], rel_yaw)

    if onset_any[0]:
        grasp_onset(0, onset[:, 0])

    # from which step on the drive no longer changes (EE within 0.5 mm of its final position,
    # grasp constant): once every object is also at rest (exact zeros thanks to the
    # velocity-level sticking), the rest of the rollout is constant and is not integrated
    to_end = np.linalg.norm(pusher - pusher[:, -1:], axis=-1)  # [T, S]
    moving_drive = np.flip(np.maximum.accumulate(np.flip(to_end, axis=1), axis=1), axis=1) > 5e-4
    moving_drive = moving_drive.any(axis=0)
    moving_drive[1:] |= (grasp[:, 1:] != grasp[:, :-1]).any(axis=0)
    idx = np.flatnonzero(moving_drive)
    static_from = int(idx[-1]) + 2 if idx.size else 0

    # until the first step where some pusher gets near its box (or a grasp starts), resting
    # boxes stay as they are: those steps are skipped once the first step shows them at rest
    reach = (
        0.5 * float(np.hypot(*scene.size[:2]))
        + scene.pusher_radius
        + 0.5 * scene.pusher_length
        + 0.01
    )
    near = (drive.pusher[..., :2] - drive.init_pos[:, None, :2]).norm(dim=-1).cpu().numpy() < reach
    near |= grasp
    quiet_until = int(np.argmax(near.any(axis=0))) if near.any() else n_s - 1
    quiet_until = max(quiet_until - 2, 0)

    impulse, wbin, bins_any = None, None, None
    if drive.wrench_bin is not None and drive.wrench_width is not None:
        wbin = drive.wrench_bin.detach().cpu().numpy()
        bins_any = (wbin >= 0).any(axis=0)
        impulse = np.zeros((m_sets, n_t, int(drive.wrench_width.shape[1]), 2), dtype=p.dtype)

    def moving() -> bool:
        return bool(np.abs(v).max() > 0 or np.abs(w).max() > 0)

    steps = _steps(p.dtype)
    zero_acc, zero_alpha = np.zeros_like(v), np.zeros_like(w)
    zero_acc.flags.writeable = zero_alpha.flags.writeable = False

    dense_p = np.empty((m_sets, n_t, n_s, 3), dtype=p.dtype)  # CoM, world
    dense_y = np.empty((m_sets, n_t, n_s), dtype=p.dtype)
    dense_p[:, :, 0], dense_y[:, :, 0] = p, yaw
    last = 0  # the last step written
    k = -1
    while k < n_s - 2:
        k += 1
        if k == 1 and quiet_until > 1 and not moving():
            dense_p[:, :, 2 : quiet_until + 1] = p[:, :, None]
            dense_y[:, :, 2 : quiet_until + 1] = yaw[:, :, None]
            k = last = quiet_until
        if k > static_from and k % 20 == 0 and not moving():
            break
        if onset_any[k + 1]:
            grasp_onset(k, onset[:, k + 1])

        # ---- free dynamics: external accelerations --------------------------------------
        gap = p[..., 2] - z_rest
        acc, alpha = zero_acc, zero_alpha  # read only: the terms below make new arrays
        if has_damping:
            acc = acc - damping[..., None] * v
        if accel_fx:
            st = FreeState(
                v=_state_view(v),
                w=_state_view(w),
                yaw=_state_view(yaw),
                on_table=_state_view(gap < 1e-4),
                body=body,
            )
            for e, th in accel_fx:
                out = e.accel(th, st)
                if out is not None:
                    a_e, al_e = out
                    if a_e is not None:
                        acc = acc + _hook_out(a_e)
                    if al_e is not None:
                        alpha = alpha + _hook_out(al_e)

        # ---- table: normal impulse, then friction on the twist (vx, vy, c_r w) -----------
        vx, vy, vz, wf, lam_n, contact, rebound, approach, speed2, speed = steps.normal(
            v, w, acc, alpha, gap, e_rest, dt, g, scene.bounce_min_speed
        )
        mu_s, mu_d = mu_s0, mu_d0
        if fric_fx:
            slip = Slip(
                vx=_state_view(vx),
                vy=_state_view(vy),
                speed=_state_view(speed),
                yaw=_state_view(yaw),
            )
            mu_s_t, mu_d_t = body.mu_s, body.mu_d
            for e, th in fric_fx:
                mu_s_t, mu_d_t = e.friction(th, mu_s_t, mu_d_t, slip)
            mu_s, mu_d = _hook_out(mu_s_t), _hook_out(mu_d_t)
        vx, vy, wf = steps.friction(vx, vy, wf, speed2, lam_n, contact, mu_s, mu_d, kr, c_r)

        # ---- pusher: frictionless inelastic speculative contact on the box sides ------------
        if pusher_low[k] and not steps.apart(
            scene, p, vx, vy, wf, com_r, pts_all[:, k], pts_speed[:, k], grasp[:, k], dt
        ):
            vx, vy, wf, jx, jy = steps.impulse(
                scene,
                p,
                np.cos(yaw),
                np.sin(yaw),
                vx,
                vy,
                wf,
                com_x,
                com_y,
                mass,
                inertia,
                pts_all[:, k],
                pv_all[:, k],
                grasp[:, k],
                dt,
            )
            if impulse is not None and bins_any[k]:
                b = wbin[:, k]  # [T]
                ts = np.flatnonzero(b >= 0)
                impulse[:, ts, b[ts]] += np.stack([jx, jy], -1)[:, ts]

        p, v, yaw = steps.integrate(p, vx, vy, vz, wf, yaw, rebound, gap, approach, dt, z_rest)
        w = wf

        if grasp_any[k + 1]:
            ey_ = ee_yaw[:, k + 1]
            p, v, yaw, w = steps.carry(
                p, v, yaw, w, grasp[:, k + 1], np.cos(ey_), np.sin(ey_), ey_, rel_p, rel_yaw,
                pusher[:, k + 1], ee_rate[:, k + 1], cvel_all[:, k + 1],
            )  # fmt: skip
        last = k + 1
        dense_p[:, :, last], dense_y[:, :, last] = p, yaw

    # stopped early: everything rests from here on
    dense_p[:, :, last + 1 :] = dense_p[:, :, last : last + 1]
    dense_y[:, :, last + 1 :] = dense_y[:, :, last : last + 1]
    dense_p_t, dense_y_t = torch.from_numpy(dense_p), torch.from_numpy(dense_y)
    com_x_t, com_y_t = body.com[..., 0], body.com[..., 1]
    offx, offy = yaw_rotate(com_x_t.unsqueeze(-1), com_y_t.unsqueeze(-1), dense_y_t)
    dense_o = torch.stack(
        [dense_p_t[..., 0] - offx, dense_p_t[..., 1] - offy, dense_p_t[..., 2]], dim=-1
    )

    # ---- observation: sample at (effect-mapped) stamps, then map into the sensor frame --------
    t_q = drive.obs_t.detach().cpu().to(dt_).unsqueeze(0).expand(m_sets, n_t, -1)
    for e, th in sensor_fx:
        t_q = e.sample_times(_lift(th), t_q)
    fidx = (t_q / dt).clamp(0.0, n_s - 1 - 1e-9)
    i0 = fidx.floor().long()
    frac = fidx - i0
    i1 = (i0 + 1).clamp(max=n_s - 1)
    idx0 = i0.unsqueeze(-1).expand(-1, -1, -1, 3)
    idx1 = i1.unsqueeze(-1).expand(-1, -1, -1, 3)
    pos = torch.gather(dense_o, 2, idx0) * (1 - frac).unsqueeze(-1) + torch.gather(
        dense_o, 2, idx1
    ) * frac.unsqueeze(-1)
    yaw_s = torch.gather(dense_y_t, 2, i0) * (1 - frac) + torch.gather(dense_y_t, 2, i1) * frac
    for e, th in sensor_fx:
        pos, yaw_s = e.to_sensor(_lift(th), pos, yaw_s)
    force = None
    if impulse is not None:
        width = drive.wrench_width.detach().cpu().to(dt_).clamp(min=dt).unsqueeze(0).unsqueeze(-1)
        force = torch.nn.functional.pad(torch.from_numpy(impulse) / width, (0, 1)).to(dev)
    return SimResult(
        pos=pos.to(dev),
        yaw=yaw_s.to(dev),
        dense_pos=dense_o.to(dev),
        dense_yaw=dense_y_t.to(dev),
        force=force,
    )


def _lift(th: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Parameters [M, 1] -> [M, 1, 1] so that they broadcast against [M, T, N] samples."""
    return {k: v.unsqueeze(-1) for k, v in th.items()}

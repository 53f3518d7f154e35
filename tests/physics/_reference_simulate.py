"""Frozen copy of ``robogs.physics.model.simulate`` as of commit ec17b74 (before the h26 speed-ups).

The oracle of ``test_simulate_equiv``: the optimised :func:`robogs.physics.model.simulate` must
reproduce this straightforward per-step rollout to 1e-12. Do not edit except to follow an
intended change of the model's physics (then change both, and say why).
"""

from __future__ import annotations

import numpy as np
import torch

from robogs.physics.effects import Effect, overrides
from robogs.physics.model import (  # unchanged by the speed-ups: shared, not copied
    BoxScene,
    Drive,
    FreeState,
    SimResult,
    Slip,
    _base_body,
    _lift,
    yaw_rotate,
)
from robogs.physics.space import ParamSpace

__all__ = ["simulate_reference"]


def _pusher_points(
    scene: BoxScene, c: torch.Tensor, cv: torch.Tensor, psi: torch.Tensor, rate: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """End-sphere centres [T, J, 3] and velocities of the capsule (J = 1 for a sphere)."""
    if scene.pusher_length <= 0.0:
        return c.unsqueeze(1), cv.unsqueeze(1)
    half = 0.5 * scene.pusher_length
    ax, ay = -torch.sin(psi) * half, torch.cos(psi) * half  # EE y axis
    off = torch.stack([torch.stack([ax, ay, 0 * ax], -1), torch.stack([-ax, -ay, 0 * ax], -1)], 1)
    voff = torch.stack(
        [
            torch.stack([-rate * ay, rate * ax, 0 * ax], -1),
            torch.stack([rate * ay, -rate * ax, 0 * ax], -1),
        ],
        1,
    )
    return c.unsqueeze(1) + off, cv.unsqueeze(1) + voff


def _pusher_impulse(
    scene: BoxScene,
    p: torch.Tensor,
    yaw: torch.Tensor,
    vx: torch.Tensor,
    vy: torch.Tensor,
    wf: torch.Tensor,
    com_x: torch.Tensor,
    com_y: torch.Tensor,
    mass: torch.Tensor,
    inertia: torch.Tensor,
    c: torch.Tensor,
    cv: torch.Tensor,
    psi: torch.Tensor,
    rate: torch.Tensor,
    grasping: torch.Tensor,
    dt: float,
) -> tuple[torch.Tensor, ...]:
    """Frictionless, inelastic, speculative contact of the pusher's end spheres with the box.

    With two end spheres the 2x2 linear complementarity problem is solved exactly by
    enumerating its four cases (Cottle, Pang & Stone 1992); one sphere is the scalar case.

    Returns:
        the box's vx, vy, yaw rate after the contact, and the impulse [N s] the box gives the
        pusher in this step (x, y, world; the reaction of the one the pusher gives the box).
    """
    hx, hy, hz = (0.5 * s for s in scene.size)
    pts, pv = _pusher_points(scene, c, cv, psi, rate)  # [T, J, 3]
    pts, pv = pts.unsqueeze(0), pv.unsqueeze(0)  # [1, T, J, 3]
    yaw_, p_ = yaw.unsqueeze(-1), p.unsqueeze(-2)  # [M, T, 1]
    offx, offy = yaw_rotate(com_x.unsqueeze(-1), com_y.unsqueeze(-1), yaw_)
    ox_, oy_ = p_[..., 0] - offx, p_[..., 1] - offy
    dx, dy, dz = pts[..., 0] - ox_, pts[..., 1] - oy_, pts[..., 2] - p_[..., 2]
    lx, ly = yaw_rotate(dx, dy, -yaw_)
    qx, qy = lx.clamp(-hx, hx), ly.clamp(-hy, hy)
    ex, ey = lx - qx, ly - qy
    dist_c = torch.sqrt(ex * ex + ey * ey)
    outside = dist_c > 1e-9
    pen_x, pen_y = hx - lx.abs(), hy - ly.abs()
    use_x = pen_x < pen_y
    zero = torch.zeros_like(lx)
    safe = dist_c.clamp(min=1e-12)
    nlx = torch.where(outside, ex / safe, torch.where(use_x, torch.sign(lx), zero))
    nly = torch.where(outside, ey / safe, torch.where(use_x, zero, torch.sign(ly)))
    gap = torch.where(outside, dist_c, -torch.minimum(pen_x, pen_y)) - scene.pusher_radius
    nx, ny = yaw_rotate(nlx, nly, yaw_)
    qwx, qwy = yaw_rotate(qx, qy, yaw_)
    rcx, rcy = ox_ + qwx - p_[..., 0], oy_ + qwy - p_[..., 1]
    w_ = wf.unsqueeze(-1)
    vptx, vpty = vx.unsqueeze(-1) - w_ * rcy, vy.unsqueeze(-1) + w_ * rcx
    rate_n = (pv[..., 0] - vptx) * nx + (pv[..., 1] - vpty) * ny
    rxn = rcx * ny - rcy * nx  # [M, T, J]
    m_, i_ = mass.unsqueeze(-1), inertia.unsqueeze(-1)
    active = (dz.abs() <= hz) & ~grasping.view(1, -1, 1)
    # speculative for open gaps, soft (Baumgarte 0.2) push-out of penetrations
    target = torch.where(gap > 0, -gap, -0.2 * gap) / dt
    b = torch.where(active, target - rate_n, torch.full_like(gap, -1.0))
    if b.shape[-1] == 1:
        lam = (b / (1.0 / m_ + rxn * rxn / i_)).clamp(min=0.0)
    else:
        n1x, n1y, n2x, n2y = nx[..., 0], ny[..., 0], nx[..., 1], ny[..., 1]
        r1, r2 = rxn[..., 0], rxn[..., 1]
        inv_m, inv_i = 1.0 / mass, 1.0 / inertia
        k11 = inv_m + r1 * r1 * inv_i
        k22 = inv_m + r2 * r2 * inv_i
        k12 = (n1x * n2x + n1y * n2y) * inv_m + r1 * r2 * inv_i
        b1, b2 = b[..., 0], b[..., 1]
        det = (k11 * k22 - k12 * k12).clamp(min=1e-12)
        l1b, l2b = (k22 * b1 - k12 * b2) / det, (k11 * b2 - k12 * b1) / det
        l1s, l2s = b1 / k11, b2 / k22
        only1 = (b1 > 0) & (b2 - k12 * l1s <= 0)
        only2 = (b2 > 0) & (b1 - k12 * l2s <= 0)
        none = (b1 <= 0) & (b2 <= 0)
        l1 = torch.where(
            none, zero[..., 0], torch.where(only1, l1s, torch.where(only2, zero[..., 0], l1b))
        )
        l2 = torch.where(
            none, zero[..., 0], torch.where(only1, zero[..., 0], torch.where(only2, l2s, l2b))
        )
        lam = torch.stack([l1, l2], -1).clamp(min=0.0)
        # flush face: both ends within 1 mm and pushing -> the capsule holds the face like a
        # paddle (both rates matched, one end may pull slightly), which stops rigid rocking
        flush = (gap[..., 0] < 1e-3) & (gap[..., 1] < 1e-3) & active[..., 0] & active[..., 1]
        flush = flush & (l1b + l2b > 0)
        lam = torch.where(flush.unsqueeze(-1), torch.stack([l1b, l2b], -1), lam)
    jx, jy = (lam * nx).sum(-1), (lam * ny).sum(-1)
    vx = vx - jx / mass
    vy = vy - jy / mass
    wf = wf - (lam * rxn).sum(-1) / inertia
    return vx, vy, wf, jx, jy


def simulate_reference(
    theta: torch.Tensor,
    space: ParamSpace,
    drive: Drive,
    scene: BoxScene,
    init_offset: torch.Tensor | None = None,
) -> SimResult:
    """Roll out M parameter sets over T trajectories and sample the object poses.

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
    dev, dt_ = theta.device, theta.dtype
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
    mass, inertia = body.mass, body.inertia_z
    kr = mass * c_r**2 / inertia  # [M, 1]
    com_x, com_y = body.com[..., 0], body.com[..., 1]  # [M, 1]

    pusher = drive.pusher.to(dev, dt_)
    pvel = drive.pusher_vel.to(dev, dt_)
    cvel_all = pvel if drive.carry_vel is None else drive.carry_vel.to(dev, dt_)
    ee_yaw = drive.ee_yaw.to(dev, dt_)
    ee_rate = drive.ee_yaw_rate.to(dev, dt_)
    grasp = drive.grasp.to(dev)
    grasp_np = grasp.cpu().numpy()
    grasp_any = grasp_np.any(axis=0)
    onset_np = np.zeros_like(grasp_np)
    onset_np[:, 1:] = grasp_np[:, 1:] & ~grasp_np[:, :-1]
    onset_np[:, 0] = grasp_np[:, 0]
    onset_any = onset_np.any(axis=0)
    onset = torch.as_tensor(onset_np, device=dev)
    # steps where some pusher could touch a box resting on the table or lifted by < 5 box heights
    pz = drive.pusher[..., 2].cpu().numpy()
    pusher_low = (pz < z_rest + 10 * hz + scene.pusher_radius).any(axis=0)

    # initial state: measured pose -> world (inverse sensor effects, last first)
    ipos = drive.init_pos.to(dev, dt_).unsqueeze(0).expand(m_sets, n_t, 3)
    iyaw = drive.init_yaw.to(dev, dt_).unsqueeze(0).expand(m_sets, n_t)
    if init_offset is not None:
        off = init_offset.to(dev, dt_)
        ipos = ipos + torch.nn.functional.pad(off[..., :2], (0, 1))
        iyaw = iyaw + off[..., 2]
    for e, th in reversed(sensor_fx):
        ipos, iyaw = e.from_sensor(th, ipos, iyaw)
    ox, oy = yaw_rotate(com_x, com_y, iyaw)
    p = torch.stack([ipos[..., 0] + ox, ipos[..., 1] + oy, ipos[..., 2]], dim=-1)
    yaw = iyaw.clone()
    v = torch.zeros_like(p)
    if drive.init_vel is not None:
        v = v + drive.init_vel.to(dev, dt_).unsqueeze(0)
    w = torch.zeros_like(yaw)
    rel_p = torch.zeros_like(p)
    rel_yaw = torch.zeros_like(yaw)
    g = scene.gravity
    e_rest = body.restitution
    damping = body.damping
    has_damping = bool((damping != 0).any())

    if onset_any[0]:
        on = onset[:, 0].view(1, n_t)
        d = p - pusher[:, 0].unsqueeze(0)
        rx, ry = yaw_rotate(d[..., 0], d[..., 1], -ee_yaw[:, 0].unsqueeze(0))
        rel_p = torch.where(on.unsqueeze(-1), torch.stack([rx, ry, d[..., 2]], dim=-1), rel_p)
        rel_yaw = torch.where(on, yaw - ee_yaw[:, 0].unsqueeze(0), rel_yaw)

    # from which step on the drive no longer changes (EE within 0.5 mm of its final position,
    # grasp constant): once every object is also at rest (exact zeros thanks to the
    # velocity-level sticking), the rest of the rollout is constant and is not integrated
    to_end = (drive.pusher - drive.pusher[:, -1:]).norm(dim=-1).cpu().numpy()  # [T, S]
    moving_drive = np.flip(np.maximum.accumulate(np.flip(to_end, axis=1), axis=1), axis=1) > 5e-4
    moving_drive = moving_drive.any(axis=0)
    moving_drive[1:] |= (grasp_np[:, 1:] != grasp_np[:, :-1]).any(axis=0)
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
    near |= grasp_np
    quiet_until = int(np.argmax(near.any(axis=0))) if near.any() else n_s - 1
    quiet_until = max(quiet_until - 2, 0)

    impulse, wbin, bins_any = None, None, None
    if drive.wrench_bin is not None and drive.wrench_width is not None:
        wbin = drive.wrench_bin.to(dev)
        bins_any = (wbin >= 0).any(dim=0).cpu().numpy()
        impulse = torch.zeros(
            (m_sets, n_t, int(drive.wrench_width.shape[1]), 2), dtype=dt_, device=dev
        )

    traj_p = [p]
    traj_y = [yaw]
    k = -1
    while k < n_s - 2:
        k += 1
        if k == 1 and quiet_until > 1 and not bool((v.abs().amax() > 0) | (w.abs().amax() > 0)):
            traj_p.extend([p] * (quiet_until - 1))
            traj_y.extend([yaw] * (quiet_until - 1))
            k = quiet_until
        if (
            k > static_from
            and k % 20 == 0
            and not bool((v.abs().amax() > 0) | (w.abs().amax() > 0))
        ):
            break
        if onset_any[k + 1]:
            # relative transform of the object in the EE frame at grasp onset (yaw-only EE frame)
            on = onset[:, k + 1].view(1, n_t)
            d = p - pusher[:, k].unsqueeze(0)
            rx, ry = yaw_rotate(d[..., 0], d[..., 1], -ee_yaw[:, k].unsqueeze(0))
            new_rel = torch.stack([rx, ry, d[..., 2]], dim=-1)
            rel_p = torch.where(on.unsqueeze(-1), new_rel, rel_p)
            rel_yaw = torch.where(on, yaw - ee_yaw[:, k].unsqueeze(0), rel_yaw)

        # ---- free dynamics: external accelerations --------------------------------------
        gap = p[..., 2] - z_rest
        acc = torch.zeros_like(v)
        alpha = torch.zeros_like(w)
        if has_damping:
            acc = acc - damping.unsqueeze(-1) * v
        if accel_fx:
            st = FreeState(v=v, w=w, yaw=yaw, on_table=gap < 1e-4, body=body)
            for e, th in accel_fx:
                out = e.accel(th, st)
                if out is not None:
                    a_e, al_e = out
                    if a_e is not None:
                        acc = acc + a_e
                    if al_e is not None:
                        alpha = alpha + al_e
        vx = v[..., 0] + dt * acc[..., 0]
        vy = v[..., 1] + dt * acc[..., 1]
        vz = v[..., 2] + dt * (acc[..., 2] - g)
        wf = w + dt * alpha

        # ---- table: normal impulse (per unit mass, m/s) -----------------------------------
        approach = -vz
        contact = (gap + dt * vz) <= 0.0
        bounce = approach > scene.bounce_min_speed
        target = torch.where(bounce, e_rest * approach, -gap.clamp(min=0.0) / dt)
        lam_n = torch.where(contact, (target - vz).clamp(min=0.0), torch.zeros_like(vz))
        vz = vz + lam_n
        # a bounce starts at the time of impact inside the step, not at the step's start
        # (otherwise the box would rebound from up to approach * dt above the table)
        rebound = contact & bounce & (lam_n > 0)
        toi = (gap.clamp(min=0.0) / approach.clamp(min=1e-9)).clamp(max=dt)

        # ---- table: friction on the twist (vx, vy, c_r w) --------------------------------
        speed2 = vx * vx + vy * vy
        speed = torch.sqrt(speed2 + 1e-18)
        mu_s, mu_d = body.mu_s, body.mu_d
        if fric_fx:
            slip = Slip(vx=vx, vy=vy, speed=speed, yaw=yaw)
            for e, th in fric_fx:
                mu_s, mu_d = e.friction(th, mu_s, mu_d, slip)
        cw = c_r * wf
        stop_norm = torch.sqrt(speed2 + (cw / kr) ** 2)
        xi = torch.sqrt(speed2 + cw * cw) + 1e-15
        stick = stop_norm <= mu_s * lam_n
        budget = mu_d * lam_n
        f_t = torch.where(stick, torch.zeros_like(xi), (1.0 - budget / xi).clamp(min=0.0))
        f_r = torch.where(stick, torch.zeros_like(xi), (1.0 - budget * kr / xi).clamp(min=0.0))
        f_t = torch.where(contact, f_t, torch.ones_like(f_t))
        f_r = torch.where(contact, f_r, torch.ones_like(f_r))
        vx = vx * f_t
        vy = vy * f_t
        wf = wf * f_r

        # ---- pusher: frictionless inelastic speculative contact on the box sides ------------
        if pusher_low[k]:
            vx, vy, wf, jx, jy = _pusher_impulse(
                scene,
                p,
                yaw,
                vx,
                vy,
                wf,
                com_x,
                com_y,
                mass,
                inertia,
                pusher[:, k],
                pvel[:, k],
                ee_yaw[:, k],
                ee_rate[:, k],
                grasp[:, k],
                dt,
            )
            if impulse is not None and bins_any[k]:
                b = wbin[:, k]  # [T]
                ts = torch.nonzero(b >= 0).squeeze(1)
                impulse[:, ts, b[ts]] += torch.stack([jx, jy], -1)[:, ts]

        v_new = torch.stack([vx, vy, vz], dim=-1)
        p = p + dt * v_new
        if bool(rebound.any()):
            z_up = z_rest + vz * (dt - toi)
            p = torch.cat([p[..., :2], torch.where(rebound, z_up, p[..., 2]).unsqueeze(-1)], -1)
        yaw = yaw + dt * wf
        v, w = v_new, wf

        if grasp_any[k + 1]:
            att = grasp[:, k + 1].view(1, n_t)
            ey_ = ee_yaw[:, k + 1].unsqueeze(0)
            rx, ry = yaw_rotate(rel_p[..., 0], rel_p[..., 1], ey_)
            cp = pusher[:, k + 1].unsqueeze(0)
            p_att = torch.stack(
                [cp[..., 0] + rx, cp[..., 1] + ry, cp[..., 2] + rel_p[..., 2]], dim=-1
            )
            rate_ = ee_rate[:, k + 1].unsqueeze(0)
            cv = cvel_all[:, k + 1].unsqueeze(0)
            v_att = torch.stack(
                [cv[..., 0] - rate_ * ry, cv[..., 1] + rate_ * rx, cv[..., 2].expand_as(rx)], dim=-1
            )
            p = torch.where(att.unsqueeze(-1), p_att, p)
            v = torch.where(att.unsqueeze(-1), v_att, v)
            yaw = torch.where(att, ey_ + rel_yaw, yaw)
            w = torch.where(att, rate_.expand_as(w), w)
        traj_p.append(p)
        traj_y.append(yaw)

    dense_p = torch.stack(traj_p, dim=2)  # CoM [M, T, S, 3]
    dense_y = torch.stack(traj_y, dim=2)
    if dense_p.shape[2] < n_s:  # stopped early: everything rests from here on
        pad = n_s - dense_p.shape[2]
        dense_p = torch.cat([dense_p, dense_p[:, :, -1:].expand(-1, -1, pad, -1)], dim=2)
        dense_y = torch.cat([dense_y, dense_y[:, :, -1:].expand(-1, -1, pad)], dim=2)
    offx, offy = yaw_rotate(com_x.unsqueeze(-1), com_y.unsqueeze(-1), dense_y)
    dense_o = torch.stack([dense_p[..., 0] - offx, dense_p[..., 1] - offy, dense_p[..., 2]], dim=-1)

    # ---- observation: sample at (effect-mapped) stamps, then map into the sensor frame --------
    t_q = drive.obs_t.to(dev, dt_).unsqueeze(0).expand(m_sets, n_t, -1)
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
    yaw_s = torch.gather(dense_y, 2, i0) * (1 - frac) + torch.gather(dense_y, 2, i1) * frac
    for e, th in sensor_fx:
        pos, yaw_s = e.to_sensor(_lift(th), pos, yaw_s)
    force = None
    if impulse is not None:
        width = drive.wrench_width.to(dev, dt_).clamp(min=dt).unsqueeze(0).unsqueeze(-1)
        force = torch.nn.functional.pad(impulse / width, (0, 1))
    return SimResult(pos=pos, yaw=yaw_s, dense_pos=dense_o, dense_yaw=dense_y, force=force)

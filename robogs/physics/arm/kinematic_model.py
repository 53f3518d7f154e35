"""The arm's kinematic model against recorded end-effector poses: data, noise floor, batched FK.

Residual, per end-effector sample (world frame):

* position ``p_meas - p_model`` in mm (channels ``x y z``);
* orientation ``log(R_meas R_model^T)`` in degrees (channels ``rx ry rz``, a rotation vector
  in the world frame), when every pose carries a finite unit quaternion (else position only).

The model pose is the forward kinematics of the moving bodies of the URDF
(:class:`~robogs.physics.arm.rnea.ArmModel`) at the *link* angles
``theta = q + sum_e dq_e`` with ``q`` the measured (motor-side) joint angles interpolated
linearly to the pose stamps and ``dq_e`` the effects' ``joint_offset``. Each body hangs from
its parent by

    T_parent_body = origin_b · Trans(da_j u_b + dd_j z_b) · Rot(z_b, theta_b)

(the effects' ``frame_offset``; only for the body moved directly by actuated joint ``j``).
This is the convention of :mod:`robogs.format.kinematics.offsets` (which check G008 and the
URDF export use; ``u`` is its :func:`~robogs.format.kinematics.offsets.perpendicular`).
``u_b`` is the joint frame's x axis made perpendicular to the axis ``z_b`` (its y axis when the
axis lies along x). On a URDF written on modified-DH frames (origin ``RotX(alpha_{i-1})
TransX(a_{i-1}) TransZ(d_i)``, axis +z, e.g. :mod:`robogs.synth.armlogs.ur5`) that x axis is
``x_{i-1}``, the common normal of axes ``i-1`` and ``i``: ``da`` is then the MDH
``delta a_{i-1}`` and ``dd`` the MDH ``delta d_i`` (Khalil & Kleinfinger 1986). The common normal
is chosen because it is the one perpendicular direction along which a length error of the
link before the joint shows; the third direction (``z x u``) is a rotation error of the
previous axis (``delta alpha``), not modelled.

The noise floor of each channel is estimated from the data, never assumed: 1.4826 MAD of the
second differences of the base model's residual divided by sqrt 6, pooled over trajectories
(the residual varies slowly, so its second differences are noise).

Everything is batched over M parameter sets in torch float64 on the device of the data.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.format.frames import quat_to_matrix_np
from robogs.format.interp import interp_linear
from robogs.format.kinematics.offsets import perpendicular
from robogs.physics.arm.effects import InertialContext, KinState
from robogs.physics.arm.kinematic_effects import REST_SPEED
from robogs.physics.arm.rnea import ArmModel, inertial_vector, regressor
from robogs.physics.arm.torque_model import _rates, active_effects, inertial_parameters
from robogs.physics.space import ParamSpace

__all__ = [
    "KinData",
    "KinProblem",
    "load_kinematic_data",
    "prepare_kinematic",
    "predict_ee",
    "forward_ee",
    "perpendicular",
    "play_offset",
    "play_scan",
    "base_residual",
    "describe",
    "kinematic_residual",
    "ee_noise",
    "POSITION_CHANNELS",
    "ORIENTATION_CHANNELS",
]

POSITION_CHANNELS = ("x", "y", "z")
"""Position residual channels, mm."""
ORIENTATION_CHANNELS = ("rx", "ry", "rz")
"""Orientation residual channels (world-frame rotation vector), degrees."""

_CHUNK_ELEMENTS = 200_000
"""Parameter sets x samples evaluated per forward-kinematics batch (bounds memory)."""


@dataclass
class KinData:
    """Joint angles at the end-effector stamps of T trajectories, and the recorded poses.

    Attributes:
        joint_names: [J] in model order; link: the end-effector link.
        t_ns: [N] pose stamps, ns; traj: [N] trajectory index; traj_names: [T].
        q, qd, qdd: [N, J] joint angles, rates, accelerations at the pose stamps.
        q_clock: [T, L, J] measured joint angles on the joint clock, each trajectory padded
            with its last sample (the backlash play operator runs on them).
        dir0: [T, J] direction of motion at each trajectory's first joint sample (the sign of
            its velocity, 0 below ``REST_SPEED``).
        at: ([N] i0, [N] i1, [N] w): the pose stamps as ``(1 - w) x[i0] + w x[i1]`` of the
            flattened joint clock ``[T * L]``.
        pos: [N, 3] recorded position, m, world.
        quat: [N, 4] recorded orientation (w, x, y, z), or None (position only).
        derived: how signals were derived; notes: what was left out and why.
    """

    joint_names: tuple[str, ...]
    link: str
    t_ns: np.ndarray
    traj: np.ndarray
    traj_names: list[str]
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    q_clock: np.ndarray
    dir0: np.ndarray
    at: tuple[np.ndarray, np.ndarray, np.ndarray]
    pos: np.ndarray
    quat: np.ndarray | None
    derived: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def num_traj(self) -> int:
        return len(self.traj_names)


@dataclass
class _Part:
    """One trajectory: joint clock and the poses inside it."""

    name: str
    q_js: np.ndarray  # [L, J]
    dir0: np.ndarray  # [J]
    t_ee: np.ndarray  # [n]
    at_ee: list[np.ndarray]  # q, qd, qdd at the pose stamps, [n, J] each
    pos: np.ndarray  # [n, 3]
    quat: np.ndarray  # [n, 4]
    i0: np.ndarray  # [n] bracketing joint samples
    w: np.ndarray  # [n]


def _ee_link(ds: Dataset, links: set[str]) -> str:
    declared = (ds.manifest.get("robot") or {}).get("ee_link")
    if declared in links:
        return str(declared)
    if len(links) == 1:
        return next(iter(links))
    raise InputError(
        f"ee_poses holds several links {sorted(links)} and the manifest names none of them",
        path=ds.root,
        where="manifest robot.ee_link",
        hint="set robot.ee_link to the link whose pose the kinematic model should explain",
    )


def _joint_log(ep, joints: tuple[str, ...]):
    """(t_ns [L], q [L, J], qd [L, J] or None) of an episode, non-finite rows dropped."""
    js = ep.table("joint_states")
    names = js.schema.names
    if "t_ns" not in names:
        raise InputError(
            "joint_states lacks t_ns",
            path=ep.table_path("joint_states"),
            where=f"episodes/{ep.id}",
            hint="see spec/FORMAT.md section 9 (run robogs validate)",
        )
    if not all(f"position.{j}" in names for j in joints):
        return None
    t = js.column("t_ns").to_numpy().astype(np.int64)
    q = np.stack([js.column(f"position.{j}").to_numpy() for j in joints], 1).astype(float)
    qd = None
    if all(f"velocity.{j}" in names for j in joints):
        qd = np.stack([js.column(f"velocity.{j}").to_numpy() for j in joints], 1).astype(float)
    good = np.isfinite(q).all(1) & (np.isfinite(qd).all(1) if qd is not None else True)
    return t[good], q[good], (qd[good] if qd is not None else None)


_EE_COLUMNS = ("t_ns", "link", "x", "y", "z", "qw", "qx", "qy", "qz")


def _part(ep, ee, link: str, joints: tuple[str, ...], derived: set[str], notes: list[str]):
    log = _joint_log(ep, joints)
    if log is None or len(log[0]) < 8:
        notes.append(f"{ep.id}: joint_states lacks positions of some joints, or has < 8 rows")
        return None
    t_js, q, qd = log
    qd_, qdd_, d = _rates(t_js, q, qd)
    derived |= set(d)
    sel = np.asarray(ee.column("link").to_pylist()) == link
    t_ee = ee.column("t_ns").to_numpy().astype(np.int64)[sel]
    pos = np.stack([ee.column(c).to_numpy()[sel] for c in ("x", "y", "z")], 1).astype(float)
    quat = np.stack([ee.column(c).to_numpy()[sel] for c in ("qw", "qx", "qy", "qz")], 1)
    keep = (t_ee >= t_js[0]) & (t_ee <= t_js[-1]) & np.isfinite(pos).all(1)
    if (~keep).any():
        notes.append(f"{ep.id}: {int((~keep).sum())} poses outside the joint log or not finite")
    order = np.flatnonzero(keep)[np.argsort(t_ee[keep], kind="stable")]
    if len(order) < 4:
        return None
    t_ee = t_ee[order]
    i1 = np.clip(np.searchsorted(t_js, t_ee, side="right"), 1, len(t_js) - 1)
    i0 = i1 - 1
    step = (t_js[i1] - t_js[i0]).astype(float)
    w = np.where(step > 0, (t_ee - t_js[i0]) / np.where(step > 0, step, 1.0), 0.0)
    dir0 = np.where(np.abs(qd_[0]) >= REST_SPEED, np.sign(qd_[0]), 0.0)
    name = ep.id if ep.segment == ep.id else f"{ep.id}/{ep.segment}"
    at_ee = [interp_linear(t_ee, t_js, x) for x in (q, qd_, qdd_)]
    return _Part(name, q, dir0, t_ee, at_ee, pos[order], quat[order].astype(float), i0, w)


def load_kinematic_data(
    ds: Dataset,
    model: ArmModel,
    *,
    link: str | None = None,
    orientation: bool | None = None,
) -> KinData:
    """Joint angles interpolated to the end-effector pose stamps of every episode with both.

    Pose rows outside the span of the joint stamps, or with a non-finite position, are left
    out. The orientation is used when ``orientation`` is True, or None and every kept pose has
    a finite quaternion of norm 1 +- 1e-3. Velocities and accelerations as for the torque
    model (:func:`robogs.physics.arm.torque_model.load_arm_data`).

    Raises:
        InputError: no episode has ``joint_states`` with positions of every joint and
            ``ee_poses`` of a link of the robot; several recorded links and no ``ee_link``.
    """
    joints = tuple(model.joint_names)
    episodes = [ep for ep in ds.episodes if ep.has("joint_states") and ep.has("ee_poses")]
    tables = {ep.id: ep.table("ee_poses") for ep in episodes}
    for ep in episodes:
        missing = [c for c in _EE_COLUMNS if c not in tables[ep.id].schema.names]
        if missing:
            raise InputError(
                f"ee_poses lacks columns {missing}",
                path=ep.table_path("ee_poses"),
                where=f"episodes/{ep.id}",
                hint="see spec/FORMAT.md section 9 (run robogs validate)",
            )
    if link is None:
        links: set[str] = set()
        for t in tables.values():
            links |= set(t.column("link").to_pylist())
        link = _ee_link(ds, links) if links else None
    if link is not None and link not in model.link_body:
        raise InputError(
            f"ee_poses link {link!r} is not a link of the robot",
            path=ds.root,
            where="episodes/*/ee_poses",
            hint=f"links: {sorted(model.link_body)}",
        )
    derived: set[str] = set()
    notes: list[str] = []
    parts = [_part(ep, tables[ep.id], str(link), joints, derived, notes) for ep in episodes]
    parts = [p for p in parts if p is not None]
    if not parts:
        raise InputError(
            "no episode has joint positions and end-effector poses of the robot",
            path=ds.root,
            where="episodes/*/ee_poses",
            hint=f"needs position.<j> for {list(joints)} and ee_poses rows of one robot link"
            + (f"; {notes[0]}" if notes else ""),
        )
    length = max(len(p.q_js) for p in parts)
    q_clock = np.stack(
        [np.concatenate([p.q_js, np.repeat(p.q_js[-1:], length - len(p.q_js), 0)]) for p in parts]
    )
    base = np.concatenate([np.full(len(p.t_ee), k * length) for k, p in enumerate(parts)])
    i0 = base.astype(np.int64) + np.concatenate([p.i0 for p in parts])
    quat = np.concatenate([p.quat for p in parts])
    norm = np.linalg.norm(quat, axis=1)
    usable = bool(np.all(np.isfinite(quat)) and np.all(np.abs(norm - 1.0) < 1e-3))
    if orientation is None:
        orientation = usable
        if not usable:
            notes.append("orientation not used: some quaternions are not finite unit quaternions")
    elif orientation and not usable:
        raise InputError(
            "ee_poses quaternions are not all finite unit quaternions",
            path=ds.root,
            where="episodes/*/ee_poses qw..qz",
            hint="fit on positions only (orientation=False)",
        )
    return KinData(
        joint_names=joints,
        link=str(link),
        t_ns=np.concatenate([p.t_ee for p in parts]),
        traj=np.concatenate([np.full(len(p.t_ee), k, dtype=np.int64) for k, p in enumerate(parts)]),
        traj_names=[p.name for p in parts],
        q=np.concatenate([p.at_ee[0] for p in parts]),
        qd=np.concatenate([p.at_ee[1] for p in parts]),
        qdd=np.concatenate([p.at_ee[2] for p in parts]),
        q_clock=q_clock,
        dir0=np.stack([p.dir0 for p in parts]),
        at=(i0, i0 + 1, np.concatenate([p.w for p in parts])),
        pos=np.concatenate([p.pos for p in parts]),
        quat=quat / norm[:, None] if orientation else None,
        derived=sorted(derived),
        notes=notes,
    )


@dataclass
class _Frames:
    """Constants of the forward kinematics to the end-effector body (torch)."""

    path: list[int]  # bodies from the base to the end-effector body (parents first)
    parent: list[int]
    src: torch.Tensor  # [B] joint index of each body
    mul: torch.Tensor  # [B]
    off: torch.Tensor  # [B]
    revolute: list[bool]
    r_o: torch.Tensor  # [B, 3, 3] origin rotation
    t_o: torch.Tensor  # [B, 3] origin translation
    rk: torch.Tensor  # [B, 3, 3] origin rotation @ skew(axis)
    rk2: torch.Tensor  # [B, 3, 3] origin rotation @ skew(axis)^2
    z_p: torch.Tensor  # [B, 3] axis in the parent frame (prismatic motion, dd)
    u_p: torch.Tensor  # [B, 3] perpendicular in the parent frame (da)
    primary: list[int]  # [B] actuated joint index moving the body directly, -1 for mimics
    T_bl: torch.Tensor  # [4, 4] end-effector link in its body frame


def _frames(model: ArmModel, link: str, dt: torch.dtype, dev) -> _Frames:
    body, t_bl = model.link_frame(link)
    if body < 0:
        raise InputError(
            f"end-effector link {link!r} is fixed to the base", hint="record a moving link"
        )
    path = []
    b = body
    while b >= 0:
        path.append(b)
        b = model.parent[b]
    path.reverse()

    def tt(x) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=dt, device=dev)

    axes = np.asarray(model.axis, dtype=float)
    k = np.zeros((len(axes), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axes[:, 2], axes[:, 1], -axes[:, 0]
    k = k - k.transpose(0, 2, 1)
    r_o = model.origin[:, :3, :3]
    perp = np.stack([perpendicular(a) for a in axes]) if len(axes) else np.zeros((0, 3))
    index = {j: i for i, j in enumerate(model.joint_names)}
    primary = [index.get(n, -1) for n in model.body_joints]
    return _Frames(
        path=path,
        parent=list(model.parent),
        src=torch.as_tensor(model.source, dtype=torch.long, device=dev),
        mul=tt(model.multiplier),
        off=tt(model.offset),
        revolute=[t == "revolute" for t in model.joint_type],
        r_o=tt(r_o),
        t_o=tt(model.origin[:, :3, 3]),
        rk=tt(r_o @ k),
        rk2=tt(r_o @ k @ k),
        z_p=tt(np.einsum("bij,bj->bi", r_o, axes)),
        u_p=tt(np.einsum("bij,bj->bi", r_o, perp)),
        primary=primary,
        T_bl=tt(t_bl),
    )


def forward_ee(
    fr: _Frames, theta: torch.Tensor, frame_offsets: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """End-effector pose for link angles ``theta`` [M, N, J] and joint-frame translations
    ``frame_offsets`` [M, J, 2] m (``da``, ``dd``; None for none).

    Returns:
        position [M, N, 3] m and rotation [M, N, 3, 3], world frame.
    """
    m, n = theta.shape[0], theta.shape[1]
    dt, dev = theta.dtype, theta.device
    R = {-1: torch.eye(3, dtype=dt, device=dev).expand(m, n, 3, 3)}
    p = {-1: torch.zeros(m, n, 3, dtype=dt, device=dev)}
    for b in fr.path:
        qb = theta[..., fr.src[b]] * fr.mul[b] + fr.off[b]  # [M, N]
        t = fr.t_o[b].expand(m, 1, 3)
        j = fr.primary[b]
        if frame_offsets is not None and j >= 0:
            da, dd = frame_offsets[:, j, 0:1], frame_offsets[:, j, 1:2]  # [M, 1]
            t = t + (da * fr.u_p[b] + dd * fr.z_p[b]).unsqueeze(1)
        if fr.revolute[b]:
            s, c = torch.sin(qb)[..., None, None], torch.cos(qb)[..., None, None]
            r_pb = fr.r_o[b] + s * fr.rk[b] + (1.0 - c) * fr.rk2[b]
        else:
            r_pb = fr.r_o[b].expand(m, n, 3, 3)
            t = t + qb.unsqueeze(-1) * fr.z_p[b]
        par = fr.parent[b]
        rp, pp = R[par], p[par]
        p[b] = pp + (rp @ t.unsqueeze(-1).expand(m, n, 3, 1)).squeeze(-1)
        R[b] = rp @ r_pb
    last = fr.path[-1]
    pos = p[last] + torch.einsum("mnij,j->mni", R[last], fr.T_bl[:3, 3])
    return pos, R[last] @ fr.T_bl[:3, :3]


@dataclass
class KinProblem:
    """Torch-ready data for the kinematic model.

    Attributes:
        model, data: the arm and the data.
        channels: residual channel names (``x y z`` mm, then ``rx ry rz`` deg if oriented).
        sigma: [K] noise floor per channel (mm, deg).
        q, qd: [N, J] measured state at the pose stamps.
        q_clock, dir0, at: joint clock for the play operator (see :class:`KinData`).
        Yg: [N, J, B*10] gravity regressor ``ID(q, 0, 0) = Yg pi``.
        pi_links: [B, 10] nominal link parameters; ctx: payload placement.
        pos: [N, 3] recorded positions m; R: [N, 3, 3] recorded rotations (or None).
        frames: forward-kinematics constants.
    """

    model: ArmModel
    data: KinData
    channels: tuple[str, ...]
    sigma: torch.Tensor
    q: torch.Tensor
    qd: torch.Tensor
    q_clock: torch.Tensor
    dir0: torch.Tensor
    at: tuple[torch.Tensor, torch.Tensor, torch.Tensor]
    Yg: torch.Tensor
    pi_links: torch.Tensor
    ctx: InertialContext
    pos: torch.Tensor
    R: torch.Tensor | None
    frames: _Frames

    @property
    def n(self) -> int:
        return int(self.q.shape[0])

    @property
    def oriented(self) -> bool:
        return self.R is not None


def prepare_kinematic(
    model: ArmModel,
    data: KinData,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    payload_link: str | None = None,
    sigma: np.ndarray | None = None,
    device: torch.device | str | None = None,
) -> KinProblem:
    """Stack the data for :func:`predict_ee`; the noise floor comes from the residual of the
    model with the ``fixed`` effects (:func:`ee_noise`) unless ``sigma`` is given."""
    dt = torch.float64
    q = torch.as_tensor(data.q, dtype=dt, device=device)
    zero = torch.zeros_like(q)
    Yg = regressor(model, q, zero, zero).reshape(q.shape[0], model.num_joints, -1)
    link = payload_link or model.last_link
    body, t_bl = model.link_frame(link)
    ctx = InertialContext(link, body, t_bl, model.num_bodies)
    channels = POSITION_CHANNELS + (ORIENTATION_CHANNELS if data.quat is not None else ())
    kp = KinProblem(
        model=model,
        data=data,
        channels=channels,
        sigma=torch.ones(len(channels), dtype=dt, device=device),
        q=q,
        qd=torch.as_tensor(data.qd, dtype=dt, device=device),
        q_clock=torch.as_tensor(data.q_clock, dtype=dt, device=device),
        dir0=torch.as_tensor(data.dir0, dtype=dt, device=device),
        at=(
            torch.as_tensor(data.at[0], device=device),
            torch.as_tensor(data.at[1], device=device),
            torch.as_tensor(data.at[2], dtype=dt, device=device).unsqueeze(-1),
        ),
        Yg=Yg,
        pi_links=torch.as_tensor(inertial_vector(model.inertials), dtype=dt, device=device),
        ctx=ctx,
        pos=torch.as_tensor(data.pos, dtype=dt, device=device),
        R=None
        if data.quat is None
        else torch.as_tensor(quat_to_matrix_np(data.quat), dtype=dt, device=device),
        frames=_frames(model, data.link, dt, device),
    )
    if sigma is None:
        raw = base_residual(kp, fixed)  # sigma = 1: physical units
        sigma = ee_noise(raw, data.traj)
    kp.sigma = torch.as_tensor(np.asarray(sigma, dtype=float), dtype=dt, device=device)
    return kp


def predict_ee(
    theta: torch.Tensor,
    space: ParamSpace,
    kp: KinProblem,
    fixed: dict[str, dict[str, float]] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Model end-effector poses for M parameter sets.

    Args:
        theta: [M, Q] values of the slots of ``space`` (effects expanded for the robot).
        space, fixed: as in :func:`robogs.physics.arm.torque_model.predict`; torque
            effects of ``fixed`` act only through the gravity torque (payload, mass scale).

    Returns:
        position [M, N, 3] m and rotation [M, N, 3, 3], world frame.
    """
    dt = kp.q.dtype
    theta = theta.to(dtype=dt, device=kp.q.device)
    m = theta.shape[0]
    active = active_effects(theta, space, tuple(kp.model.joint_names), fixed)
    kin = [(e, th) for e, th in active if e.residual == "kinematic"]
    tau_g = None
    if any(e.uses_gravity for e, _ in kin):
        pi = inertial_parameters(active, kp.pi_links, kp.ctx, m)
        tau_g = -torch.einsum("njp,mp->mnj", kp.Yg, pi)
    ks = KinState(kp.q, kp.qd, tau_g, tuple(kp.model.joint_names), lambda b: play_offset(kp, b))
    theta_link = kp.q.unsqueeze(0).expand(m, -1, -1)
    offsets = None
    for eff, th in kin:
        d = eff.joint_offset(th, ks)
        if d is not None:
            theta_link = theta_link + d
        f = eff.frame_offset(th)
        if f is not None:
            offsets = f if offsets is None else offsets + f
    return forward_ee(kp.frames, theta_link, offsets)


def play_scan(x0: torch.Tensor, q: torch.Tensor, half_width: torch.Tensor) -> torch.Tensor:
    """The play operator ``x_k = clip(x_{k-1}, q_k - w, q_k + w)`` for every k, in blocks.

    A clip followed by a clip is a clip: ``clip(clip(x, l1, h1), l2, h2) = clip(x, clip(l1,
    l2, h2), clip(h1, l2, h2))``. The samples are cut into about sqrt(N) blocks of about
    sqrt(N); one loop over the position inside a block composes the clips of all blocks at once
    (each block's prefix ``L_k, H_k``), a short loop over blocks carries the state from block
    to block, and ``x_k = clip(x_block_start, L_k, H_k)``: 2 sqrt(N) vectorised steps instead
    of N.

    Args:
        x0: [..., J] state before the first sample.
        q: [..., N, J] input (motor angles).
        half_width: [..., 1, J] dead-band half-width (>= 0), broadcast against ``q``.

    Returns:
        [..., N, J] the state after each sample.
    """
    n = q.shape[-2]
    lead = torch.broadcast_shapes(q.shape[:-2], half_width.shape[:-2], x0.shape[:-1])
    j = q.shape[-1]
    size = max(1, int(np.ceil(np.sqrt(n))))
    n_blk = -(-n // size)
    pad = n_blk * size - n
    qp = q.expand(*lead, n, j)
    if pad:
        qp = torch.cat([qp, qp[..., -1:, :].expand(*lead, pad, j)], dim=-2)
    # [size, ..., n_blk, J]: the position inside the block first, so each step is contiguous
    qb = qp.reshape(*lead, n_blk, size, j).movedim(-2, 0).contiguous()
    w = half_width.expand(*lead, 1, j)  # [..., 1, J] against [..., n_blk, J]
    lo, hi = [qb[0] - w], [qb[0] + w]
    for k in range(1, size):
        lk, hk = qb[k] - w, qb[k] + w
        lo.append(torch.minimum(torch.maximum(lo[-1], lk), hk))
        hi.append(torch.minimum(torch.maximum(hi[-1], lk), hk))
    starts = [x0.expand(*lead, j)]
    for blk in range(n_blk - 1):
        starts.append(
            torch.minimum(torch.maximum(starts[-1], lo[-1][..., blk, :]), hi[-1][..., blk, :])
        )
    start = torch.stack(starts, dim=-2)  # [..., n_blk, J]
    x = torch.stack(
        [torch.minimum(torch.maximum(start, a), b) for a, b in zip(lo, hi, strict=True)], dim=-2
    )
    return x.reshape(*lead, n_blk * size, j)[..., :n, :]


def play_offset(kp: KinProblem, b: torch.Tensor) -> torch.Tensor:
    """Link minus motor angle [M, N, J] of dead bands of half-width ``b`` [M, J] rad.

    The play operator ``x_k = clip(x_{k-1}, q_k - |b|, q_k + |b|)``, ``x_0 = q_0 - |b| s_0``
    (:func:`play_scan`), runs along the measured joint clock of every trajectory at once;
    ``x - q`` is interpolated to the pose stamps and multiplied by ``sign(b)``.
    """
    q = kp.q_clock  # [T, L, J]
    bb = b.abs().unsqueeze(1)  # [M, 1, J]
    x0 = q[:, 0].unsqueeze(0) - bb * kp.dir0.unsqueeze(0)  # [M, T, J]
    x = play_scan(x0, q.unsqueeze(0).expand(b.shape[0], -1, -1, -1), bb.unsqueeze(1))
    d = (x - q.unsqueeze(0)).reshape(b.shape[0], -1, q.shape[-1])
    i0, i1, w = kp.at
    return torch.sign(b).unsqueeze(1) * (d[:, i0] * (1.0 - w) + d[:, i1] * w)


def _residual(kp: KinProblem, pos: torch.Tensor, R: torch.Tensor) -> torch.Tensor:
    """Residual [M, N, K] in mm and degrees (not whitened)."""
    r_pos = (kp.pos.unsqueeze(0) - pos) * 1000.0
    if kp.R is None:
        return r_pos
    e = kp.R.unsqueeze(0) @ R.transpose(-1, -2)  # R_meas R_model^T
    v = torch.stack(
        (e[..., 2, 1] - e[..., 1, 2], e[..., 0, 2] - e[..., 2, 0], e[..., 1, 0] - e[..., 0, 1]),
        dim=-1,
    )  # 2 sin(angle) axis
    s = v.norm(dim=-1, keepdim=True)
    tr = e[..., 0, 0] + e[..., 1, 1] + e[..., 2, 2]
    ang = torch.atan2(0.5 * s, 0.5 * (tr - 1.0).unsqueeze(-1))
    scale = torch.where(s > 1e-12, ang / s.clamp_min(1e-300), torch.full_like(s, 0.5))
    return torch.cat([r_pos, torch.rad2deg(v * scale)], dim=-1)


def kinematic_residual(
    theta: torch.Tensor,
    space: ParamSpace,
    kp: KinProblem,
    fixed: dict[str, dict[str, float]] | None = None,
) -> torch.Tensor:
    """Whitened residual ``(measured - model) / sigma`` [M, N, K], in chunks of parameter sets."""
    step = max(1, _CHUNK_ELEMENTS // max(kp.n, 1))
    out = []
    for lo in range(0, theta.shape[0], step):
        pos, R = predict_ee(theta[lo : lo + step], space, kp, fixed)
        out.append(_residual(kp, pos, R) / kp.sigma)
    return torch.cat(out, dim=0)


def base_residual(kp: KinProblem, fixed: dict[str, dict[str, float]] | None) -> np.ndarray:
    """Residual [N, K] (mm, deg) of the model with only the ``fixed`` effects."""
    space = ParamSpace((), ())
    theta = space.defaults(1, dtype=kp.q.dtype, device=kp.q.device)
    pos, R = predict_ee(theta, space, kp, fixed)
    return _residual(kp, pos, R)[0].cpu().numpy()


def ee_noise(resid: np.ndarray, traj: np.ndarray) -> np.ndarray:
    """Noise floor per channel [K]: 1.4826 MAD of the second differences / sqrt 6, pooled
    over trajectories, of a residual [N, K] that varies slowly apart from the noise."""
    d2s = []
    for k in np.unique(traj):
        x = resid[traj == k]
        if len(x) >= 3:
            d2s.append(x[2:] - 2 * x[1:-1] + x[:-2])
    if not d2s:
        return np.full(resid.shape[1], np.nan)
    d2 = np.concatenate(d2s)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return np.maximum(1.4826 * mad / np.sqrt(6.0), 1e-9)


def describe(kp: KinProblem) -> dict[str, Any]:
    """Units and noise floor of the channels (JSON-ready)."""
    units = {c: ("mm" if c in POSITION_CHANNELS else "deg") for c in kp.channels}
    sig = kp.sigma.cpu().numpy()
    return {
        "link": kp.data.link,
        "channels": list(kp.channels),
        "units": units,
        "noise_floor": {c: float(s) for c, s in zip(kp.channels, sig, strict=True)},
    }

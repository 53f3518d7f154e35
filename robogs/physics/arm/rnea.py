"""Rigid-body inverse dynamics of a URDF arm: recursive Newton-Euler and its linear regressor.

The arm is reduced to *moving bodies*: every link hanging from an actuated (revolute,
continuous, prismatic) joint together with the links welded to it by fixed joints, whose
inertials are folded into one composite mass, CoM and inertia. The root link and everything
welded to it are the base, fixed at the world origin with the world's orientation; gravity acts
along ``gravity`` (default ``(0, 0, -9.81)`` m/s^2, world frame).

Two evaluations of ``tau = ID(q, qd, qdd)`` are provided:

* :func:`inverse_dynamics` - the recursive Newton-Euler algorithm in body frames (Luh, Walker
  & Paul 1980; Featherstone, *Rigid Body Dynamics Algorithms*, 2008, ch. 5): an outward pass of
  velocities and accelerations (gravity entered as a base acceleration ``-g``) and an inward
  pass of link wrenches projected on the joint axes.
* :func:`regressor` - the same torques written as ``Y(q, qd, qdd) @ pi``, linear in the ten
  inertial parameters of every body ``pi_b = (m, m c_x, m c_y, m c_z, Ixx, Ixy, Ixz, Iyy, Iyz,
  Izz)`` with the inertia taken about the body origin (Atkeson, An & Hollerbach 1986; the form
  pinocchio's ``computeJointTorqueRegressor`` returns). The identification code uses it so that
  inertial effects (payload, mass scale) cost one matrix product per parameter set.

Mimic joints are followed: a body driven by ``multiplier * q[source] + offset`` moves with its
source, and its joint torque is added to the source's torque times the multiplier (the
transpose of the coupling Jacobian).

Shapes: ``q, qd, qdd`` are [..., J] in the order of :attr:`ArmModel.joint_names` (rad, rad/s,
rad/s^2 for revolute joints; m, m/s, m/s^2 for prismatic); torques are [..., J] in N m (N for
prismatic). All float64 recommended; CPU or CUDA, following the input tensors.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch
import yourdfpy

from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics import Chain

__all__ = [
    "ArmModel",
    "Inertials",
    "inverse_dynamics",
    "regressor",
    "inertial_vector",
    "point_mass_vector",
    "GRAVITY",
]

GRAVITY: tuple[float, float, float] = (0.0, 0.0, -9.81)
"""Default gravity, m/s^2, world frame (z up)."""


@dataclass(frozen=True)
class Inertials:
    """Composite inertial parameters of the B moving bodies (numpy, float64).

    Attributes:
        mass: [B] kg.
        com: [B, 3] centre of mass in the body frame, m.
        inertia: [B, 3, 3] inertia about the CoM, body-frame axes, kg m^2.
    """

    mass: np.ndarray
    com: np.ndarray
    inertia: np.ndarray

    def scaled(self, s: float) -> Inertials:
        """All masses and inertias times ``s`` (CoMs unchanged)."""
        return Inertials(self.mass * s, self.com.copy(), self.inertia * s)


@dataclass(frozen=True)
class ArmModel:
    """The moving bodies of a URDF arm, ready for inverse dynamics.

    Attributes:
        joint_names: [J] actuated joints (``q`` order), as in :class:`Chain`.
        body_names: [B] name of the link that starts each moving body.
        parent: [B] index of each body's parent body (-1: the base).
        joint_type: [B] ``"revolute"`` (also continuous) or ``"prismatic"``.
        origin: [B, 4, 4] ``T_parentbody_jointframe``: the fixed transform from the parent
            body frame, through any fixed joints, to this body's joint frame.
        axis: [B, 3] unit joint axis in the joint (= body) frame.
        source: [B] index in ``q`` of the joint driving the body.
        multiplier: [B] mimic multiplier (1 for an actuated joint).
        offset: [B] mimic offset, rad or m.
        inertials: nominal composite inertials.
        link_body: link name -> (body index or -1 for the base, ``T_body_link`` [4, 4]).
        joint_lower, joint_upper: [J] limits (rad or m, +-inf when none).
        joint_dynamics: joint name -> ``{"damping": ..., "friction": ...}`` from the URDF.
        body_joints: [B] name of the joint that moves each body (an actuated or a mimic joint).
    """

    joint_names: tuple[str, ...]
    body_names: tuple[str, ...]
    parent: tuple[int, ...]
    joint_type: tuple[str, ...]
    origin: np.ndarray
    axis: np.ndarray
    source: np.ndarray
    multiplier: np.ndarray
    offset: np.ndarray
    inertials: Inertials
    link_body: dict[str, tuple[int, np.ndarray]]
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    joint_dynamics: dict[str, dict[str, float]]
    body_joints: tuple[str, ...] = ()

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_bodies(self) -> int:
        return len(self.body_names)

    @property
    def last_link(self) -> str:
        """The link that starts the deepest moving body (default payload carrier)."""
        depth = [0] * self.num_bodies
        for b, p in enumerate(self.parent):
            depth[b] = 0 if p < 0 else depth[p] + 1
        return self.body_names[int(np.argmax(depth))]

    def with_inertials(self, inertials: Inertials) -> ArmModel:
        """A copy with other inertial parameters."""
        return replace(self, inertials=inertials)

    @classmethod
    def from_urdf(cls, urdf: yourdfpy.URDF) -> ArmModel:
        """Build the model from a ``yourdfpy.URDF`` (meshes need not be loaded).

        Links without ``<inertial>`` count as massless. ``floating``/``planar`` joints are
        refused (the base is fixed).

        Raises:
            FormatError: unsupported joints or a negative/non-finite mass or inertia.
        """
        chain = Chain.from_urdf(urdf)
        links = {lk.name: lk for lk in urdf.robot.links}
        joints = {j.name: j for j in urdf.robot.joints}
        n_links = chain.num_links
        group = [-1] * n_links  # body index of each link (-1: base)
        t_group_link = [np.eye(4)] * n_links
        body_names: list[str] = []
        body_joints: list[str] = []
        parent: list[int] = []
        jtype: list[str] = []
        origin: list[np.ndarray] = []
        axis: list[np.ndarray] = []
        source: list[int] = []
        mult: list[float] = []
        off: list[float] = []
        for k in range(1, n_links):
            p = chain.parents[k]
            jt = chain.joint_types[k - 1]
            t_origin = t_group_link[p] @ chain.origins[k - 1]
            if jt == "fixed":
                group[k] = group[p]
                t_group_link[k] = t_origin
                continue
            b = len(body_names)
            body_names.append(chain.link_names[k])
            body_joints.append(chain.tree_joint_names[k - 1])
            parent.append(group[p])
            jtype.append("prismatic" if jt == "prismatic" else "revolute")
            origin.append(t_origin)
            axis.append(chain.axes[k - 1])
            source.append(int(chain.source[k - 1]))
            mult.append(float(chain.multiplier[k - 1]))
            off.append(float(chain.offset[k - 1]))
            group[k] = b
            t_group_link[k] = np.eye(4)
        n_b = len(body_names)
        mass = np.zeros(n_b)
        first = np.zeros((n_b, 3))
        inertia_o = np.zeros((n_b, 3, 3))  # about the body origin
        for k, name in enumerate(chain.link_names):
            b = group[k]
            inert = links[name].inertial
            if b < 0 or inert is None:
                continue
            m = float(inert.mass or 0.0)
            t_li = np.eye(4) if inert.origin is None else np.asarray(inert.origin, dtype=float)
            i_c = (
                np.zeros((3, 3))
                if inert.inertia is None
                else np.asarray(inert.inertia, dtype=float)
            )
            if not np.isfinite(m) or m < 0 or not np.all(np.isfinite(i_c)):
                raise FormatError(
                    "negative or non-finite inertial", where=f"link '{name}' <inertial>"
                )
            t_bi = t_group_link[k] @ t_li
            r, c = t_bi[:3, :3], t_bi[:3, 3]
            first[b] += m * c
            mass[b] += m
            inertia_o[b] += r @ i_c @ r.T + m * (c @ c * np.eye(3) - np.outer(c, c))
        com = np.where(mass[:, None] > 0, first / np.maximum(mass, 1e-300)[:, None], 0.0)
        inertia_c = inertia_o - mass[:, None, None] * (
            np.einsum("bi,bi->b", com, com)[:, None, None] * np.eye(3)
            - np.einsum("bi,bj->bij", com, com)
        )
        link_body = {n: (group[k], t_group_link[k]) for k, n in enumerate(chain.link_names)}
        dyn: dict[str, dict[str, float]] = {}
        for name in chain.joint_names:
            d = joints[name].dynamics
            if d is not None:
                dyn[name] = {
                    "damping": float(d.damping or 0.0),
                    "friction": float(d.friction or 0.0),
                }
        return cls(
            joint_names=tuple(chain.joint_names),
            body_names=tuple(body_names),
            parent=tuple(parent),
            joint_type=tuple(jtype),
            origin=np.asarray(origin, dtype=float).reshape(n_b, 4, 4),
            axis=np.asarray(axis, dtype=float).reshape(n_b, 3),
            source=np.asarray(source, dtype=np.int64),
            multiplier=np.asarray(mult, dtype=float),
            offset=np.asarray(off, dtype=float),
            inertials=Inertials(mass, com, inertia_c),
            link_body=link_body,
            joint_lower=np.asarray(chain.joint_lower, dtype=float),
            joint_upper=np.asarray(chain.joint_upper, dtype=float),
            joint_dynamics=dyn,
            body_joints=tuple(body_joints),
        )

    def link_frame(self, link: str) -> tuple[int, np.ndarray]:
        """(body index, ``T_body_link``) of a link; the base has index -1."""
        try:
            return self.link_body[link]
        except KeyError:
            raise InputError(
                f"unknown link {link!r}", hint=f"links: {sorted(self.link_body)}"
            ) from None


# ----------------------------------------------------------------------------- kinematics


@dataclass
class _Kinematics:
    """Per-body motion, tensors [N, B, ...] in body frames (``R_pb``: parent <- body)."""

    R_pb: torch.Tensor  # [N, B, 3, 3]
    p_pb: torch.Tensor  # [N, B, 3] body origin in the parent frame
    w: torch.Tensor  # [N, B, 3] angular velocity
    dw: torch.Tensor  # [N, B, 3] angular acceleration
    a: torch.Tensor  # [N, B, 3] linear acceleration of the origin (gravity included)
    z: torch.Tensor  # [B, 3] joint axis
    qd_b: torch.Tensor  # [N, B] joint rate of each body's joint


def _cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.linalg.cross(a, b, dim=-1)


def _mv(r: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    return (r @ v.unsqueeze(-1)).squeeze(-1)


def _mtv(r: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    return (r.transpose(-1, -2) @ v.unsqueeze(-1)).squeeze(-1)


def _flatten(model: ArmModel, q: torch.Tensor, qd: torch.Tensor, qdd: torch.Tensor):
    q = torch.as_tensor(q)
    if not q.is_floating_point():
        q = q.to(torch.float64)
    qd = torch.as_tensor(qd, dtype=q.dtype, device=q.device)
    qdd = torch.as_tensor(qdd, dtype=q.dtype, device=q.device)
    j = model.num_joints
    for name, x in (("q", q), ("qd", qd), ("qdd", qdd)):
        if x.ndim == 0 or x.shape[-1] != j or x.shape != q.shape:
            raise InputError(
                f"{name} has shape {tuple(x.shape)}, expected [..., {j}] like q {tuple(q.shape)}",
                hint=f"joint order: {list(model.joint_names)}",
            )
    batch = q.shape[:-1]
    return batch, q.reshape(-1, j), qd.reshape(-1, j), qdd.reshape(-1, j)


def _kinematics(model: ArmModel, q, qd, qdd, gravity) -> _Kinematics:
    dev, dt = q.device, q.dtype

    def tt(x) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=dt, device=dev)

    src = torch.as_tensor(model.source, dtype=torch.long, device=dev)
    mul, off = tt(model.multiplier), tt(model.offset)
    qb = q[:, src] * mul + off  # [N, B]
    qdb = qd[:, src] * mul
    qddb = qdd[:, src] * mul
    z = tt(model.axis)  # [B, 3]
    r_o = tt(model.origin[:, :3, :3])
    t_o = tt(model.origin[:, :3, 3])
    kz = torch.zeros(z.shape[0], 3, 3, dtype=dt, device=dev)
    kz[:, 0, 1], kz[:, 0, 2], kz[:, 1, 2] = -z[:, 2], z[:, 1], -z[:, 0]
    kz = kz - kz.transpose(-1, -2)
    is_rev = torch.tensor([t == "revolute" for t in model.joint_type], device=dev)
    ang = torch.where(is_rev, qb, torch.zeros_like(qb))[..., None, None]
    rot = (
        torch.eye(3, dtype=dt, device=dev) + torch.sin(ang) * kz + (1 - torch.cos(ang)) * (kz @ kz)
    )
    R_pb = r_o @ rot  # [N, B, 3, 3]
    disp = torch.where(is_rev, torch.zeros_like(qb), qb)
    p_pb = t_o + disp[..., None] * _mv(r_o, z)  # [N, B, 3]

    n = q.shape[0]
    g = tt(gravity)
    w_base = torch.zeros(n, 3, dtype=dt, device=dev)
    a_base = (-g).expand(n, 3)
    ws, dws, accs = [], [], []
    for b in range(model.num_bodies):
        p = model.parent[b]
        w_p, dw_p, a_p = (w_base, w_base, a_base) if p < 0 else (ws[p], dws[p], accs[p])
        R, pos = R_pb[:, b], p_pb[:, b]
        zb = z[b].expand(n, 3)
        a_org = _mtv(R, a_p + _cross(dw_p, pos) + _cross(w_p, _cross(w_p, pos)))
        w_in, dw_in = _mtv(R, w_p), _mtv(R, dw_p)
        if model.joint_type[b] == "revolute":
            w_b = w_in + zb * qdb[:, b : b + 1]
            dw_b = dw_in + zb * qddb[:, b : b + 1] + _cross(w_in, zb * qdb[:, b : b + 1])
            a_b = a_org
        else:
            w_b, dw_b = w_in, dw_in
            a_b = a_org + zb * qddb[:, b : b + 1] + 2.0 * _cross(w_b, zb * qdb[:, b : b + 1])
        ws.append(w_b)
        dws.append(dw_b)
        accs.append(a_b)
    return _Kinematics(
        R_pb=R_pb,
        p_pb=p_pb,
        w=torch.stack(ws, 1),
        dw=torch.stack(dws, 1),
        a=torch.stack(accs, 1),
        z=z,
        qd_b=qdb,
    )


# ----------------------------------------------------------------------------- dynamics


def inverse_dynamics(
    model: ArmModel,
    q: torch.Tensor,
    qd: torch.Tensor,
    qdd: torch.Tensor,
    *,
    inertials: Inertials | None = None,
    gravity: tuple[float, float, float] = GRAVITY,
) -> torch.Tensor:
    """Joint torques of the rigid arm by recursive Newton-Euler.

    Args:
        model: the arm.
        q, qd, qdd: [..., J] joint positions, rates and accelerations.
        inertials: composite inertials to use (default ``model.inertials``).
        gravity: world-frame gravity, m/s^2.

    Returns:
        [..., J] joint torques (N m; N for prismatic joints), dtype and device of ``q``.
    """
    batch, q, qd, qdd = _flatten(model, q, qd, qdd)
    kin = _kinematics(model, q, qd, qdd, gravity)
    ine = model.inertials if inertials is None else inertials
    dev, dt = q.device, q.dtype
    mass = torch.as_tensor(ine.mass, dtype=dt, device=dev)
    com = torch.as_tensor(ine.com, dtype=dt, device=dev)
    i_c = torch.as_tensor(ine.inertia, dtype=dt, device=dev)
    w, dw, a = kin.w, kin.dw, kin.a
    com_n = com.expand_as(dw)
    a_c = a + _cross(dw, com_n) + _cross(w, _cross(w, com_n))
    force = mass[:, None] * a_c  # [N, B, 3]
    moment = _mv(i_c, dw) + _cross(w, _mv(i_c, w))
    f = [force[:, b] for b in range(model.num_bodies)]
    nm = [
        moment[:, b] + _cross(com[b].expand_as(force[:, b]), force[:, b])
        for b in range(model.num_bodies)
    ]
    tau_b = [None] * model.num_bodies
    for b in reversed(range(model.num_bodies)):
        z = kin.z[b]
        tau_b[b] = (nm[b] if model.joint_type[b] == "revolute" else f[b]) @ z
        p = model.parent[b]
        if p >= 0:
            R, pos = kin.R_pb[:, b], kin.p_pb[:, b]
            f_p = _mv(R, f[b])
            f[p] = f[p] + f_p
            nm[p] = nm[p] + _mv(R, nm[b]) + _cross(pos, f_p)
    tau = torch.zeros(q.shape[0], model.num_joints, dtype=dt, device=dev)
    mul = torch.as_tensor(model.multiplier, dtype=dt, device=dev)
    src = torch.as_tensor(model.source, dtype=torch.long, device=dev)
    tau = tau.index_add(1, src, torch.stack(tau_b, 1) * mul)
    return tau.reshape(*batch, model.num_joints)


def inertial_vector(inertials: Inertials) -> np.ndarray:
    """The [B, 10] parameter vectors ``(m, m c, I_origin xx xy xz yy yz zz)`` of the bodies."""
    m, c, i_c = inertials.mass, inertials.com, inertials.inertia
    i_o = i_c + m[:, None, None] * (
        np.einsum("bi,bi->b", c, c)[:, None, None] * np.eye(3) - np.einsum("bi,bj->bij", c, c)
    )
    iu = i_o[:, [0, 0, 0, 1, 1, 2], [0, 1, 2, 1, 2, 2]]
    return np.concatenate([m[:, None], m[:, None] * c, iu], axis=1)


def point_mass_vector(mass: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
    """Inertial parameter vectors [..., 10] of point masses ``mass`` [...] kg at ``com`` [..., 3] m."""
    h = mass[..., None] * com
    cc = (com * com).sum(-1)
    x, y, z = com[..., 0], com[..., 1], com[..., 2]
    iu = (
        torch.stack([cc - x * x, -x * y, -x * z, cc - y * y, -y * z, cc - z * z], dim=-1)
        * mass[..., None]
    )
    return torch.cat([mass[..., None], h, iu], dim=-1)


def regressor(
    model: ArmModel,
    q: torch.Tensor,
    qd: torch.Tensor,
    qdd: torch.Tensor,
    *,
    gravity: tuple[float, float, float] = GRAVITY,
) -> torch.Tensor:
    """The inverse-dynamics regressor: ``tau = Y @ pi.reshape(-1)``.

    Args:
        model: the arm.
        q, qd, qdd: [..., J] joint states.
        gravity: world-frame gravity, m/s^2.

    Returns:
        ``Y`` [..., J, B, 10]; ``pi`` [B, 10] from :func:`inertial_vector` (body-origin
        inertia), so ``torch.einsum('...jbk,bk->...j', Y, pi)`` equals :func:`inverse_dynamics`.
    """
    batch, q, qd, qdd = _flatten(model, q, qd, qdd)
    kin = _kinematics(model, q, qd, qdd, gravity)
    n, n_b, dev, dt = q.shape[0], model.num_bodies, q.device, q.dtype
    w, dw, a = kin.w, kin.dw, kin.a  # [N, B, 3]
    # force = m a + dw x h + w x (w x h); moment about origin = I dw + w x (I w) + h x a

    def skew(v: torch.Tensor) -> torch.Tensor:
        s = torch.zeros(*v.shape, 3, dtype=dt, device=dev)
        s[..., 0, 1], s[..., 0, 2], s[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
        return s - s.transpose(-1, -2)

    sw, sdw, sa = skew(w), skew(dw), skew(a)
    a_f = torch.cat(
        [a.unsqueeze(-1), sdw + sw @ sw, torch.zeros(n, n_b, 3, 6, dtype=dt, device=dev)], -1
    )

    def lin_i(v: torch.Tensor) -> torch.Tensor:
        # I v = L(v) @ (Ixx, Ixy, Ixz, Iyy, Iyz, Izz)
        x, y, z = v[..., 0], v[..., 1], v[..., 2]
        zero = torch.zeros_like(x)
        rows = [
            torch.stack([x, y, z, zero, zero, zero], -1),
            torch.stack([zero, x, zero, y, z, zero], -1),
            torch.stack([zero, zero, x, zero, y, z], -1),
        ]
        return torch.stack(rows, -2)

    a_n_i = lin_i(dw) + sw @ lin_i(w)
    a_n = torch.cat([torch.zeros(n, n_b, 3, 1, dtype=dt, device=dev), -sa, a_n_i], -1)
    # world poses of the bodies
    R0 = [None] * n_b
    p0 = [None] * n_b
    for b in range(n_b):
        p = model.parent[b]
        if p < 0:
            R0[b], p0[b] = kin.R_pb[:, b], kin.p_pb[:, b]
        else:
            R0[b] = R0[p] @ kin.R_pb[:, b]
            p0[b] = p0[p] + _mv(R0[p], kin.p_pb[:, b])
    Y = torch.zeros(n, model.num_joints, n_b, 10, dtype=dt, device=dev)
    for b in range(n_b):
        f_w = R0[b] @ a_f[:, b]  # [N, 3, 10]
        n_w = R0[b] @ a_n[:, b]
        k = b
        while k >= 0:
            zk = _mv(R0[k], kin.z[k].expand(n, 3))  # [N, 3]
            if model.joint_type[k] == "revolute":
                lever = skew(p0[b] - p0[k])
                row = (zk.unsqueeze(-2) @ (n_w + lever @ f_w)).squeeze(-2)
            else:
                row = (zk.unsqueeze(-2) @ f_w).squeeze(-2)
            Y[:, int(model.source[k]), b] += float(model.multiplier[k]) * row
            k = model.parent[k]
    return Y.reshape(*batch, model.num_joints, n_b, 10)

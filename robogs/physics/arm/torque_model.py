"""The arm torque model on measured joint logs: data, noise floor, and batched prediction.

``tau_model(t) = [Y(q, qd, qdd) (pi_links + pi_extra) + sum_e tau_e(q, qd, qdd)](t - delta)``

* ``Y`` is the inverse-dynamics regressor of :mod:`robogs.physics.arm.rnea` computed
  once per data set, ``pi_links`` the URDF inertials (changed by e.g. a mass scale), and
  ``pi_extra`` added bodies (payload);
* ``tau_e`` the joint-torque effects (friction, armature);
* ``delta`` the effort time offset, applied by linear interpolation of the model series inside
  each trajectory (end values held).

Velocities are the measured ones when the log has them, smoothed by the same Savitzky-Golay
filter (order 0; it keeps the encoder-rate noise out of the Coulomb term near reversals).
Accelerations always come from the second derivative of the *positions* (encoder positions are
far less noisy than logged velocities, whose derivative would put noise on every inertial
torque), and missing velocities from the first derivative; both by
:func:`~robogs.format.differentiate.savgol_derivative`. The noise floor
of each joint's effort is estimated from the data (1.4826 MAD of second differences / sqrt 6),
never assumed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from robogs.format.dataset import Dataset
from robogs.format.differentiate import describe_differentiator, savgol_derivative
from robogs.format.errors import InputError
from robogs.physics.arm.effects import ArmEffect, ArmState, InertialContext
from robogs.physics.arm.rnea import ArmModel, inertial_vector, regressor
from robogs.physics.effects import get_effect
from robogs.physics.space import ParamSpace

__all__ = [
    "ArmData",
    "ArmProblem",
    "load_arm_data",
    "prepare_arm",
    "effort_noise",
    "predict",
    "fixed_effects",
    "active_effects",
    "inertial_parameters",
]


@dataclass
class ArmData:
    """Joint logs of T trajectories, concatenated in time order per trajectory.

    Attributes:
        joint_names: [J] in model order.
        t_ns: [N] int64 stamps, ns.
        traj: [N] trajectory index of each sample.
        traj_names: [T] episode ids (``<episode>`` or ``<episode>/<segment>``).
        q, qd, qdd, tau: [N, J] rad, rad/s, rad/s^2, N m.
        derived: which signals were differentiated, and how.
        has: streams present (``efforts``, ``ee_poses``).
    """

    joint_names: tuple[str, ...]
    t_ns: np.ndarray
    traj: np.ndarray
    traj_names: list[str]
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    derived: list[str] = field(default_factory=list)
    has: set[str] = field(default_factory=set)

    @property
    def num_traj(self) -> int:
        return len(self.traj_names)

    def subset(self, idx: list[int]) -> ArmData:
        """The data of some trajectories."""
        keep = np.isin(self.traj, idx)
        remap = {k: i for i, k in enumerate(idx)}
        return ArmData(
            self.joint_names,
            self.t_ns[keep],
            np.array([remap[k] for k in self.traj[keep]], dtype=np.int64),
            [self.traj_names[k] for k in idx],
            self.q[keep],
            self.qd[keep],
            self.qdd[keep],
            self.tau[keep],
            list(self.derived),
            set(self.has),
        )


def _rates(
    t_ns: np.ndarray, q: np.ndarray, qd: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    derived = []
    if qd is None:
        qd = savgol_derivative(t_ns, q, order=1)
        qdd = savgol_derivative(t_ns, q, order=2)
        derived += [
            f"velocity: {describe_differentiator(1)} of position",
            f"acceleration: {describe_differentiator(2)} of position",
        ]
    else:
        qdd = savgol_derivative(t_ns, q, order=2)
        qd = savgol_derivative(t_ns, qd, order=0)
        derived += [
            f"velocity: measured, smoothed by {describe_differentiator(0)}",
            f"acceleration: {describe_differentiator(2)} of position",
        ]
    return qd, qdd, derived


def load_arm_data(ds: Dataset, joint_names: tuple[str, ...] | list[str]) -> ArmData:
    """Read the joint logs with efforts of every episode of a dataset.

    Episodes without ``joint_states`` or without effort columns are skipped; one trajectory per
    episode.

    Raises:
        InputError: no episode has efforts for all ``joint_names``.
    """
    joints = tuple(joint_names)
    parts: list[tuple[str, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]] = []
    skipped: list[str] = []
    for ep in ds.episodes:
        if not ep.has("joint_states"):
            continue
        table = ep.table("joint_states")
        names = table.schema.names
        if not all(f"effort.{j}" in names and f"position.{j}" in names for j in joints):
            skipped.append(ep.id)
            continue
        t = table.column("t_ns").to_numpy().astype(np.int64)
        q = np.stack([table.column(f"position.{j}").to_numpy() for j in joints], axis=1).astype(
            float
        )
        tau = np.stack([table.column(f"effort.{j}").to_numpy() for j in joints], axis=1).astype(
            float
        )
        qd = None
        if all(f"velocity.{j}" in names for j in joints):
            qd = np.stack(
                [table.column(f"velocity.{j}").to_numpy() for j in joints], axis=1
            ).astype(float)
        good = (
            np.isfinite(q).all(1)
            & np.isfinite(tau).all(1)
            & (np.isfinite(qd).all(1) if qd is not None else True)
        )
        if not good.all():
            t, q, tau = t[good], q[good], tau[good]
            qd = qd[good] if qd is not None else None
        name = ep.id if ep.segment == ep.id else f"{ep.id}/{ep.segment}"
        parts.append((name, t, q, qd, tau))
    if not parts:
        raise InputError(
            "no episode has joint positions and efforts for all joints of the robot",
            path=ds.root,
            where="episodes/*/joint_states",
            hint=f"needs position.<j> and effort.<j> for {list(joints)}"
            + (f"; episodes without efforts: {skipped[:5]}" if skipped else ""),
        )
    ts, trs, qs, qds, qdds, taus = [], [], [], [], [], []
    derived: list[str] = []
    for k, (_, t, q, qd, tau) in enumerate(parts):
        qd_, qdd_, d = _rates(t, q, qd)
        derived = sorted(set(derived) | set(d))
        ts.append(t)
        trs.append(np.full(len(t), k, dtype=np.int64))
        qs.append(q)
        qds.append(qd_)
        qdds.append(qdd_)
        taus.append(tau)
    has = {"efforts"}
    if any(ep.has("ee_poses") for ep in ds.episodes):
        has.add("ee_poses")
    return ArmData(
        joints,
        np.concatenate(ts),
        np.concatenate(trs),
        [p[0] for p in parts],
        np.concatenate(qs),
        np.concatenate(qds),
        np.concatenate(qdds),
        np.concatenate(taus),
        derived,
        has,
    )


def effort_noise(data: ArmData) -> np.ndarray:
    """Effort noise per joint [J] N m: 1.4826 MAD of the second differences / sqrt(6), pooled
    over trajectories (the smooth torque contributes little at joint-log rates)."""
    d2s = []
    for k in range(data.num_traj):
        x = data.tau[data.traj == k]
        if len(x) >= 3:
            d2s.append(x[2:] - 2 * x[1:-1] + x[:-2])
    if not d2s:
        return np.full(len(data.joint_names), np.nan)
    d2 = np.concatenate(d2s)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    return np.maximum(1.4826 * mad / np.sqrt(6.0), 1e-9)


@dataclass
class ArmProblem:
    """Torch-ready data for the torque model.

    Attributes:
        model: the arm; data: the logs; sigma: [J] effort noise, N m.
        Y: [N, J, B*10] regressor; pi_links: [B, 10] nominal link parameters.
        state: measured state for the hooks; tau: [N, J] measured efforts.
        t_s: [N] seconds since each trajectory's start, offset by 1e6 s per trajectory so
            that one sorted axis holds all of them.
        traj_first, traj_last: [N] row index of the first / last sample of each row's trajectory.
        ctx: payload placement.
    """

    model: ArmModel
    data: ArmData
    sigma: torch.Tensor
    Y: torch.Tensor
    pi_links: torch.Tensor
    state: ArmState
    tau: torch.Tensor
    t_s: torch.Tensor
    traj_first: torch.Tensor
    traj_last: torch.Tensor
    ctx: InertialContext

    @property
    def n(self) -> int:
        return int(self.tau.shape[0])

    @property
    def channels(self) -> tuple[str, ...]:
        """Residual channels: one per joint."""
        return tuple(self.state.joint_names)


_TRAJ_GAP_S = 1.0e6


def prepare_arm(
    model: ArmModel,
    data: ArmData,
    *,
    payload_link: str | None = None,
    sigma: np.ndarray | None = None,
    device: torch.device | str | None = None,
) -> ArmProblem:
    """Stack the data for :func:`predict` (regressor computed once, float64)."""
    dt = torch.float64
    q = torch.as_tensor(data.q, dtype=dt, device=device)
    qd = torch.as_tensor(data.qd, dtype=dt, device=device)
    qdd = torch.as_tensor(data.qdd, dtype=dt, device=device)
    Y = regressor(model, q, qd, qdd).reshape(q.shape[0], model.num_joints, -1)
    link = payload_link or model.last_link
    body, t_bl = model.link_frame(link)
    if body < 0:
        raise InputError(f"payload link {link!r} is fixed to the base", hint="choose a moving link")
    ctx = InertialContext(link, body, t_bl, model.num_bodies)
    t_rel = np.zeros(len(data.t_ns))
    first = np.zeros(len(data.t_ns), dtype=np.int64)
    last = np.zeros(len(data.t_ns), dtype=np.int64)
    for k in range(data.num_traj):
        rows = np.flatnonzero(data.traj == k)
        t_rel[rows] = (data.t_ns[rows] - data.t_ns[rows[0]]) * 1e-9 + k * _TRAJ_GAP_S
        first[rows], last[rows] = rows[0], rows[-1]
    sig = effort_noise(data) if sigma is None else np.asarray(sigma, dtype=float)
    return ArmProblem(
        model=model,
        data=data,
        sigma=torch.as_tensor(sig, dtype=dt, device=device),
        Y=Y,
        pi_links=torch.as_tensor(inertial_vector(model.inertials), dtype=dt, device=device),
        state=ArmState(q, qd, qdd, tuple(data.joint_names)),
        tau=torch.as_tensor(data.tau, dtype=dt, device=device),
        t_s=torch.as_tensor(t_rel, dtype=dt, device=device),
        traj_first=torch.as_tensor(first, device=device),
        traj_last=torch.as_tensor(last, device=device),
        ctx=ctx,
    )


def fixed_effects(
    physics: dict[str, Any] | None, joint_names: tuple[str, ...]
) -> dict[str, dict[str, float]]:
    """Arm effects already stored in ``physics.json``: effect name -> parameter values."""
    from robogs.physics.effects import available_effects

    out: dict[str, dict[str, float]] = {}
    if not physics:
        return out
    for name in available_effects(model="arm"):
        eff = get_effect(name)
        if not isinstance(eff, ArmEffect):
            continue
        vals = eff.for_robot(joint_names).read_physics(physics)
        if vals is not None:
            out[name] = vals
    return out


def _shift(pb: ArmProblem, tau: torch.Tensor, delta: torch.Tensor) -> torch.Tensor:
    """``tau`` [M, N, J] sampled at ``t - delta`` ([M, 1] s) inside each trajectory."""
    tq = pb.t_s.unsqueeze(0) - delta  # [M, N]
    idx = torch.searchsorted(pb.t_s.contiguous(), tq.contiguous(), right=True) - 1
    lo = pb.traj_first.unsqueeze(0).expand_as(idx)
    hi = pb.traj_last.unsqueeze(0).expand_as(idx)
    i0 = torch.minimum(torch.maximum(idx, lo), hi)
    i1 = torch.minimum(i0 + 1, hi)
    t0, t1 = pb.t_s[i0], pb.t_s[i1]
    span = torch.where(i1 > i0, t1 - t0, torch.ones_like(t0))
    w = ((tq - t0) / span).clamp(0.0, 1.0)
    w = torch.where(i1 > i0, w, torch.zeros_like(w)).unsqueeze(-1)
    j = tau.shape[-1]
    g0 = torch.gather(tau, 1, i0.unsqueeze(-1).expand(-1, -1, j))
    g1 = torch.gather(tau, 1, i1.unsqueeze(-1).expand(-1, -1, j))
    return g0 * (1 - w) + g1 * w


def active_effects(
    theta: torch.Tensor,
    space: ParamSpace,
    joint_names: tuple[str, ...],
    fixed: dict[str, dict[str, float]] | None,
) -> list[tuple[ArmEffect, dict[str, torch.Tensor]]]:
    """The arm effects acting on a prediction and their parameters ``name -> [M, 1]``.

    Effects of ``fixed`` (physics.json values, constant over the M sets) come first, then the
    effects of ``space`` (values from ``theta`` [M, Q]); an effect in both is taken from
    ``theta``.
    """
    m, dt, dev = theta.shape[0], theta.dtype, theta.device
    active: list[tuple[ArmEffect, dict[str, torch.Tensor]]] = []
    in_space = {e.name for e in space.effects}
    for name, vals in (fixed or {}).items():
        if name in in_space:
            continue
        eff = get_effect(name)
        if not isinstance(eff, ArmEffect):
            continue
        eff = eff.for_robot(joint_names)
        active.append(
            (eff, {k: torch.full((m, 1), float(v), dtype=dt, device=dev) for k, v in vals.items()})
        )
    for eff in space.effects:
        if isinstance(eff, ArmEffect) and eff.model == "arm":
            active.append((eff, space.theta_dict(theta, eff.name)))
    return active


def inertial_parameters(
    active: list[tuple[ArmEffect, dict[str, torch.Tensor]]],
    pi_links: torch.Tensor,
    ctx: InertialContext,
    m: int,
) -> torch.Tensor:
    """Inertial parameters ``pi_links + pi_extra`` [M, B*10] after the effects' ``inertial`` hooks."""
    links = pi_links.unsqueeze(0).expand(m, -1, -1)
    extra = torch.zeros_like(links)
    for eff, th in active:
        links, extra = eff.inertial(th, links, extra, ctx)
    return (links + extra).reshape(m, -1)


def predict(
    theta: torch.Tensor,
    space: ParamSpace,
    pb: ArmProblem,
    fixed: dict[str, dict[str, float]] | None = None,
) -> torch.Tensor:
    """Model torques for M parameter sets.

    Args:
        theta: [M, Q] values of the slots of ``space`` (its effects must be expanded for the
            robot with :meth:`ArmEffect.for_robot`).
        space: the slots; effects of other models are ignored.
        pb: prepared data.
        fixed: effect name -> values held constant (e.g. read from physics.json); an effect
            also in ``space`` is taken from ``theta`` instead.

    Returns:
        [M, N, J] predicted efforts, N m.
    """
    m = theta.shape[0]
    dt, dev = pb.Y.dtype, pb.Y.device
    theta = theta.to(dt)
    active = active_effects(theta, space, pb.state.joint_names, fixed)
    pi = inertial_parameters(active, pb.pi_links, pb.ctx, m)  # [M, B*10]
    tau = torch.einsum("njp,mp->mnj", pb.Y, pi)
    delta = torch.zeros(m, 1, dtype=dt, device=dev)
    shifted = False
    for eff, th in active:
        extra_tau = eff.joint_torque(th, pb.state)
        if extra_tau is not None:
            tau = tau + extra_tau
        d = eff.time_shift(th)
        if d is not None:
            delta = delta + d
            shifted = True
    if shifted:
        tau = _shift(pb, tau, delta)
    return tau

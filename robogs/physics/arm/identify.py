"""Fit arm effects to joint-torque logs or end-effector poses with the physics fitter
(:mod:`robogs.physics.fit`).

The torque model is handed to :func:`~robogs.physics.fit.fit_problems` as a weighted
residual function ``fn(theta [M, Q], local [M, U, 0]) -> [M, U, K]``: residuals are whitened
per joint by the effort noise floor, ``(tau_meas - tau_model) / sigma_j``, and grouped by
*unit* (a trajectory, or one of 4 contiguous blocks when the data hold a single trajectory),
each unit padded with zeros to the longest. There are no local parameters. Units are what
held-out splits select, so a fold is simply a problem whose ``traj`` mask leaves units out.

The fitter is bounded Levenberg-Marquardt with forward differences; most arm effects are
linear in their parameters (friction, armature, mass scale, payload mass and first moment), so
the first step is the linear least-squares solution and the covariance ``s^2 (J^T J)^-1`` is
exact; the payload's point-mass inertia and the time offset take a few more steps.

The kinematic problem (:class:`~robogs.physics.arm.kinematic_model.KinProblem`) plugs
into the same machinery: its residual is the whitened end-effector pose error (channels
``x y z`` mm and ``rx ry rz`` deg instead of joints). Kinematic parameters often come in
groups that act only together (translations along parallel axes, a joint zero about an axis
through the end effector when only positions are measured), so before fitting a kinematic
problem its free columns are screened at the start point (:func:`identifiable_columns`):
Gram-Schmidt on the scaled Jacobian columns in declared order keeps a column only if it
does not vanish and is not within ``1e-3`` (sine of the angle) of the span of the columns kept
before it; the dropped ones stay at their start values and are reported unidentifiable, with
the kept columns they act together with (the first of a group stands for the group: the
"base parameters" of geometric robot calibration, Khalil & Dombre 2002). The fitter's own
covariance check (insensitive, interval wider than the bounds, near-singular information)
then applies to the rest.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.physics.arm.effects import ArmEffect
from robogs.physics.arm.kinematic_model import KinProblem, kinematic_residual
from robogs.physics.arm.torque_model import ArmProblem, predict
from robogs.physics.effects import get_effect
from robogs.physics.fit import FitOutcome, Problem, ResidualFn, fit_problems, jacobian_fd
from robogs.physics.space import ParamSpace

__all__ = [
    "ArmFit",
    "UnitLayout",
    "fit_effects",
    "fit_many",
    "expand_effects",
    "unit_layout",
    "residual_fn",
    "identifiable_columns",
    "channels_of",
]

COLLINEAR_SINE = 1e-3
"""A kinematic column closer than this (sine of the angle) to the span of the columns kept
before it is unidentifiable (:func:`identifiable_columns`)."""

_Z95 = 1.959963984540054


@dataclass
class UnitLayout:
    """Grouping of the samples into units (trajectories or blocks) for the fitter.

    Attributes:
        unit: [N] unit of every sample; slot: [N] flat index ``unit * max_len + position``.
        n_units, max_len: padded layout sizes.
        how: description of the split.
    """

    unit: np.ndarray
    slot: np.ndarray
    n_units: int
    max_len: int
    how: str


def channels_of(pb: ArmProblem | KinProblem) -> tuple[str, ...]:
    """Residual channels of a problem: joints (torque) or pose components (kinematic)."""
    return tuple(pb.channels)


def unit_layout(pb: ArmProblem | KinProblem, *, blocks: int = 4) -> UnitLayout:
    """Trajectories as units, or ``blocks`` contiguous blocks of a single trajectory."""
    d = pb.data
    if d.num_traj >= 2:
        unit = d.traj.astype(np.int64)
        how = f"by trajectory ({d.num_traj} trajectories)"
    else:
        unit = np.zeros(pb.n, dtype=np.int64)
        for k, b in enumerate(np.array_split(np.arange(pb.n), blocks)):
            unit[b] = k
        how = f"single trajectory cut into {blocks} contiguous blocks"
    n_units = int(unit.max()) + 1
    pos = np.zeros(pb.n, dtype=np.int64)
    counts = np.zeros(n_units, dtype=np.int64)
    for u in range(n_units):
        rows = np.flatnonzero(unit == u)
        pos[rows] = np.arange(len(rows))
        counts[u] = len(rows)
    max_len = int(counts.max())
    return UnitLayout(unit, unit * max_len + pos, n_units, max_len, how)


def residual_fn(
    pb: ArmProblem | KinProblem, space: ParamSpace, fixed, layout: UnitLayout
) -> ResidualFn:
    """The whitened residuals in the fitter's ``[M, U, K]`` layout (K = max_len * channels):
    torques ``(tau - tau_model) / sigma`` or pose errors (:func:`.kinematic_residual`)."""
    dev = pb.sigma.device
    slot = torch.as_tensor(layout.slot, device=dev)
    nj = len(channels_of(pb))

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        theta = theta.to(dev)
        if isinstance(pb, KinProblem):
            r = kinematic_residual(theta, space, pb, fixed)  # [M, N, K]
        else:
            r = (pb.tau - predict(theta, space, pb, fixed)) / pb.sigma  # [M, N, J]
        out = torch.zeros(
            theta.shape[0], layout.n_units * layout.max_len, nj, dtype=r.dtype, device=r.device
        )
        out[:, slot] = r
        return out.reshape(theta.shape[0], layout.n_units, layout.max_len * nj)

    return fn


@dataclass
class ArmFit:
    """Result of fitting some effects.

    Attributes:
        space: the parameter space (all effects of the call).
        free: fitted columns of ``space``.
        theta: [Q] values (columns not free at their start values).
        std: [P] standard deviations of the free columns (inf: unidentifiable).
        cov: [P, P] covariance of the free columns.
        resid: [N, J] whitened residuals at ``theta`` (all samples).
        jac: [N * J, P] whitened Jacobian d resid / d theta_free (all samples, row-major).
        rss: [J] residual sum of squares per joint over the fitted units, N^2 m^2.
        iterations, converged: optimiser bookkeeping.
        why: column -> why it is not identifiable (screened out before the fit, or flagged by
            the fitter's covariance check); only filled for kinematic problems.
    """

    space: ParamSpace
    free: list[int]
    theta: np.ndarray
    std: np.ndarray
    cov: np.ndarray
    resid: np.ndarray
    jac: np.ndarray
    rss: np.ndarray
    iterations: int
    converged: bool
    why: dict[int, str] = field(default_factory=dict)

    def unidentifiable(self, effect: str) -> dict[str, str]:
        """Parameters of ``effect`` the data do not pin down: name -> why."""
        return {
            self.space.slots[i].param.name: self.why[i]
            for i in self.space.owner_columns(effect)
            if i in self.why
        }

    def values(self, effect: str) -> dict[str, float]:
        """Fitted parameters of one effect."""
        return {
            self.space.slots[i].param.name: float(self.theta[i])
            for i in self.space.owner_columns(effect)
        }

    def effect_cov(self, effect: str) -> np.ndarray:
        """Covariance block of one effect's parameters."""
        idx = [self.free.index(i) for i in self.space.owner_columns(effect)]
        return self.cov[np.ix_(idx, idx)]

    def intervals(self, effect: str) -> dict[str, dict[str, float | str | bool | None]]:
        """``name -> {value, low, high, unit}`` (95 %) for one effect; a parameter the data do
        not pin down (:attr:`why`) has ``low = high = None``, ``identifiable: False`` and
        ``why`` (its value is its start value: physics.json or zero)."""
        out: dict[str, dict[str, float | str | bool | None]] = {}
        for i in self.space.owner_columns(effect):
            sd = float(self.std[self.free.index(i)]) if i in self.free else 0.0
            v = float(self.theta[i])
            p = self.space.slots[i].param
            out[p.name] = {"value": v, "low": v - _Z95 * sd, "high": v + _Z95 * sd, "unit": p.unit}
            if i in self.why:
                out[p.name] |= {
                    "low": None,
                    "high": None,
                    "identifiable": False,
                    "why": self.why[i],
                }
        return out


def expand_effects(
    effects: Sequence[str | ArmEffect], joint_names: Sequence[str]
) -> list[ArmEffect]:
    """Registry names or instances -> arm effects expanded for the robot's joints."""
    out: list[ArmEffect] = []
    for e in effects:
        eff = get_effect(e) if isinstance(e, str) else e
        if not isinstance(eff, ArmEffect):
            raise InputError(
                f"effect {eff.name!r} does not act on the arm torque model",
                where="effects",
                hint="choose an effect listed by available_effects(model='arm')",
            )
        out.append(eff.for_robot(tuple(joint_names)))
    return out


def _outcome(
    o: FitOutcome,
    space: ParamSpace,
    free: list[int],
    layout: UnitLayout,
    pb: ArmProblem | KinProblem,
    mask: np.ndarray,
    screened: dict[int, str] | None = None,
) -> ArmFit:
    nj = len(channels_of(pb))
    r = o.resid.reshape(layout.n_units * layout.max_len, nj)[layout.slot]
    jac = o.jac.reshape(layout.n_units * layout.max_len, nj, -1)[layout.slot].reshape(pb.n * nj, -1)
    sig = pb.sigma.cpu().numpy()
    rows = mask[layout.unit]
    rss = ((r[rows] * sig) ** 2).sum(axis=0)
    cov = o.cov if o.cov.size else np.zeros((len(free), len(free)))
    std = o.std if o.std.size else np.zeros(len(free))
    why: dict[int, str] = {}
    if screened is not None:
        why = dict(screened)
        for k, w in enumerate(o.why_param):
            if w:
                why[free[k]] = w
    return ArmFit(space, free, o.theta, std, cov, r, jac, rss, o.iterations, o.converged, why)


def identifiable_columns(
    jac: np.ndarray, cols: Sequence[int], scale: np.ndarray, names: Sequence[str]
) -> tuple[list[int], dict[int, str]]:
    """Screen columns of a Jacobian for identifiability (see the module docstring).

    Args:
        jac: [R, P] residual Jacobian over the fitted rows, columns in the order of ``cols``.
        cols: the parameter-space columns of ``jac`` (declared order).
        scale: [P] typical magnitude of each parameter (columns are compared scaled).
        names: [P] parameter names for the messages.

    Returns:
        the kept columns, and dropped column -> why.
    """
    a = jac * scale[None, :]
    norms = np.linalg.norm(a, axis=0)
    top = float(norms.max()) if norms.size else 0.0
    kept: list[int] = []
    basis: list[np.ndarray] = []
    why: dict[int, str] = {}
    for k, c in enumerate(cols):
        if norms[k] <= 1e-9 * max(top, 1e-300):
            why[c] = "the predictions do not change with it"
            continue
        v = a[:, k] / norms[k]
        res = v.copy()
        for b in basis:  # modified Gram-Schmidt, twice for stability
            res -= (b @ res) * b
        for b in basis:
            res -= (b @ res) * b
        rn = float(np.linalg.norm(res))
        if rn < COLLINEAR_SINE:
            sub = np.stack([a[:, cols.index(i)] / norms[cols.index(i)] for i in kept], axis=1)
            coef = np.linalg.lstsq(sub, v, rcond=None)[0]
            mates = [names[cols.index(kept[i])] for i in np.flatnonzero(np.abs(coef) > 0.05)]
            why[c] = "acts only together with " + ", ".join(mates) + " (which stands for the group)"
            continue
        basis.append(res / rn)
        kept.append(c)
    return kept, why


def fit_many(
    pb: ArmProblem | KinProblem,
    groups: Sequence[Sequence[str | ArmEffect]],
    *,
    fixed: dict[str, dict[str, float]] | None = None,
    masks: Sequence[np.ndarray | None] | None = None,
    layout: UnitLayout | None = None,
    max_iter: int = 30,
) -> list[ArmFit]:
    """Fit several effect sets (and unit subsets) at once with one batched model per iteration.

    Args:
        pb: prepared data.
        groups: effect sets, one problem each (their effects may overlap).
        fixed: effects held at given values (physics.json); fitted effects replace them and
            start from them.
        masks: per problem, [U] bool units in the objective (None: all).
        layout: unit layout (default :func:`unit_layout`).
        max_iter: LM iterations at most.
    """
    names = tuple(pb.model.joint_names)
    all_effects: dict[str, ArmEffect] = {}
    for g in groups:
        for e in expand_effects(g, names):
            all_effects.setdefault(e.name, e)
    space = ParamSpace((), tuple(all_effects.values()))
    layout = layout or unit_layout(pb)
    fn = residual_fn(pb, space, fixed, layout)
    masks = list(masks) if masks is not None else [None] * len(groups)
    # every effect of the space starts at its physics.json value (or its zero): effects that a
    # problem does not fit then act exactly as in the base model
    theta0 = space.zero.copy()
    for name in all_effects:
        for k, v in ((fixed or {}).get(name) or {}).items():
            if (name, k) in space._index:
                theta0[space.index(name, k)] = v
    theta0 = np.clip(theta0, space.lower, space.upper)
    problems, frees = [], []
    for g, m in zip(groups, masks, strict=True):
        free = [i for e in expand_effects(g, names) for i in space.owner_columns(e.name)]
        problems.append(Problem(free, traj=m, theta0=theta0, fit_local=False))
        frees.append(free)
    screened: list[dict[int, str] | None] = [None] * len(problems)
    if isinstance(pb, KinProblem):
        problems, frees, screened = _screen(fn, space, problems, theta0, layout, pb)
    outs = fit_problems(fn, space, problems, n_traj=layout.n_units, n_local=0, max_iter=max_iter)
    return [
        _outcome(
            o,
            space,
            f,
            layout,
            pb,
            np.ones(layout.n_units, bool) if m is None else np.asarray(m, bool),
            sc,
        )
        for o, f, m, sc in zip(outs, frees, masks, screened, strict=True)
    ]


def _screen(
    fn: ResidualFn,
    space: ParamSpace,
    problems: list[Problem],
    theta0: np.ndarray,
    layout: UnitLayout,
    pb: KinProblem,
) -> tuple[list[Problem], list[list[int]], list[dict[int, str] | None]]:
    """Drop the columns each problem cannot identify (:func:`identifiable_columns`), using one
    forward-difference Jacobian at the common start point."""
    union = sorted({c for p in problems for c in p.free})
    if not union:
        return problems, [list(p.free) for p in problems], [{} for _ in problems]
    local = np.zeros((layout.n_units, 0))
    _, jac, _ = jacobian_fd(fn, space, theta0, local, union, fit_local=False)  # [U, K, P]
    names = [space.slots[c].param.name for c in union]
    out, frees, why = [], [], []
    for p in problems:
        mask = np.ones(layout.n_units, bool) if p.traj is None else np.asarray(p.traj, bool)
        idx = [union.index(c) for c in p.free]
        sub = jac[mask][:, :, idx].reshape(-1, len(idx))
        kept, w = identifiable_columns(
            sub, list(p.free), space.scale[list(p.free)], [names[i] for i in idx]
        )
        out.append(Problem(kept, traj=p.traj, theta0=p.theta0, fit_local=p.fit_local))
        frees.append(kept)
        why.append(w)
    return out, frees, why


def fit_effects(
    pb: ArmProblem | KinProblem,
    effects: Sequence[str | ArmEffect],
    *,
    fixed: dict[str, dict[str, float]] | None = None,
    max_iter: int = 30,
) -> ArmFit:
    """Fit the parameters of ``effects`` together on all samples (see :func:`fit_many`)."""
    return fit_many(pb, [effects], fixed=fixed, max_iter=max_iter)[0]

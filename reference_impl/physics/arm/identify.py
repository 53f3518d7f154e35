"""Fit arm effects to joint-torque logs: bounded Levenberg-Marquardt with intervals.

Residuals are whitened per joint by the effort noise floor (``r = (tau_meas - tau_model) /
sigma_j``). The Jacobian comes from central differences of :func:`~.torque_model.predict`,
evaluated for all perturbed parameter sets in one batched call; most arm effects are linear
in their parameters (friction, armature, mass scale, payload mass and first moment), for which
central differences are exact and the first Gauss-Newton step is the linear least-squares
solution. The payload CoM (point-mass inertia) and the time offset are mildly nonlinear and
take a few more steps (Marquardt 1963 damping, bounds by projection).

The covariance is ``s^2 (J^T J)^-1`` with ``s^2`` the whitened residual variance; directions
of ``J^T J`` with eigenvalues below 1e-10 of the largest are unidentifiable and give infinite
intervals for the parameters they involve (the convention of ``mujoco.sysid``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from reference_impl.physics.arm.effects import ArmEffect
from reference_impl.physics.arm.torque_model import ArmProblem, predict
from reference_impl.physics.effects import get_effect
from reference_impl.physics.space import ParamSpace
from robogs_format.errors import InputError

__all__ = ["ArmFit", "fit_effects", "expand_effects", "residuals"]

_Z95 = 1.959963984540054


@dataclass
class ArmFit:
    """Result of :func:`fit_effects`.

    Attributes:
        space: the fitted slots (effects expanded for the robot).
        theta: [Q] fitted values.
        cov: [Q, Q] covariance (inf on the diagonal for unidentifiable parameters).
        rss: [J] residual sum of squares per joint on the fitted rows, N^2 m^2.
        n_rows: samples per joint used.
        iterations: LM iterations; converged: whether the cost settled.
        jac: [R, Q] whitened Jacobian of the model at ``theta`` on the fitted rows.
    """

    space: ParamSpace
    theta: np.ndarray
    cov: np.ndarray
    rss: np.ndarray
    n_rows: int
    iterations: int
    converged: bool
    jac: np.ndarray

    def values(self, effect: str) -> dict[str, float]:
        """Fitted parameters of one effect."""
        return {self.space.slots[i].param.name: float(self.theta[i]) for i in self.space.owner_columns(effect)}

    def intervals(self, effect: str) -> dict[str, dict[str, float | str]]:
        """``name -> {value, low, high, unit}`` (95 %) for one effect."""
        out: dict[str, dict[str, float | str]] = {}
        for i in self.space.owner_columns(effect):
            sd = float(np.sqrt(self.cov[i, i])) if np.isfinite(self.cov[i, i]) else float("inf")
            v = float(self.theta[i])
            p = self.space.slots[i].param
            out[p.name] = {"value": v, "low": v - _Z95 * sd, "high": v + _Z95 * sd, "unit": p.unit}
        return out


def expand_effects(effects: Sequence[str | ArmEffect], joint_names: Sequence[str]) -> list[ArmEffect]:
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


def residuals(pb: ArmProblem, tau_model: torch.Tensor) -> torch.Tensor:
    """Whitened residuals ``(tau - tau_model) / sigma`` [..., N, J]."""
    return (pb.tau - tau_model) / pb.sigma


def _whitened(theta: torch.Tensor, space: ParamSpace, pb: ArmProblem, fixed, rows: torch.Tensor) -> torch.Tensor:
    """[M, R] whitened residuals on ``rows`` (flattened sample x joint)."""
    r = residuals(pb, predict(theta, space, pb, fixed))[:, rows]
    return r.reshape(theta.shape[0], -1)


def _jacobian(theta: np.ndarray, space: ParamSpace, pb: ArmProblem, fixed, rows, step: np.ndarray,
              chunk: int = 8) -> np.ndarray:
    q = len(theta)
    cols = []
    dt, dev = pb.Y.dtype, pb.Y.device
    for a in range(0, q, chunk):
        idx = list(range(a, min(q, a + chunk)))
        th = np.repeat(theta[None, :], 2 * len(idx), axis=0)
        for k, i in enumerate(idx):
            th[2 * k, i] += step[i]
            th[2 * k + 1, i] -= step[i]
        r = _whitened(torch.as_tensor(th, dtype=dt, device=dev), space, pb, fixed, rows).cpu().numpy()
        for k, i in enumerate(idx):
            cols.append((r[2 * k] - r[2 * k + 1]) / (2 * step[i]))
    return np.stack(cols, axis=1) if cols else np.zeros((0, 0))


def _covariance(jac: np.ndarray, s2: float, scale: np.ndarray) -> np.ndarray:
    js = jac * scale[None, :]
    h = js.T @ js
    w, v = np.linalg.eigh(h)
    tol = 1e-10 * max(float(w.max()), 1e-300)
    good = w > tol
    inv = (v[:, good] / w[good]) @ v[:, good].T
    cov = s2 * inv * np.outer(scale, scale)
    if not good.all():
        involved = (np.abs(v[:, ~good]) > 0.1).any(axis=1)
        cov[involved, :] = np.inf
        cov[:, involved] = np.inf
    return cov


def fit_effects(
    pb: ArmProblem,
    effects: Sequence[str | ArmEffect],
    *,
    fixed: dict[str, dict[str, float]] | None = None,
    rows: np.ndarray | None = None,
    start: dict[str, dict[str, float]] | None = None,
    max_iter: int = 30,
) -> ArmFit:
    """Fit the parameters of ``effects`` (together) to the efforts.

    Args:
        pb: prepared data.
        effects: registry names or arm effects.
        fixed: effects held at given values (physics.json); fitted effects replace them.
        rows: sample indices to fit on (whole trajectories for held-out tests); default all.
        start: effect -> {param: value} starting point (default: the ``fixed`` values of the
            same effect, else the parameters' zero values).
        max_iter: LM iterations.

    Returns:
        The fit (values, covariance, per-joint RSS).
    """
    effs = expand_effects(effects, pb.state.joint_names)
    space = ParamSpace((), effs)
    dt, dev = pb.Y.dtype, pb.Y.device
    theta = space.zero.copy()
    for e in effs:
        init = (start or {}).get(e.name) or (fixed or {}).get(e.name) or {}
        for k, v in init.items():
            if (e.name, k) in space._index:
                theta[space.index(e.name, k)] = v
    lo, hi = space.lower, space.upper
    theta = np.clip(theta, lo, hi)
    row_idx = torch.arange(pb.n, device=dev) if rows is None else torch.as_tensor(rows, dtype=torch.long, device=dev)
    step = 1e-4 * space.scale

    def cost_of(th: np.ndarray) -> float:
        r = _whitened(torch.as_tensor(th[None], dtype=dt, device=dev), space, pb, fixed, row_idx)
        return float((r * r).sum())

    r0 = _whitened(torch.as_tensor(theta[None], dtype=dt, device=dev), space, pb, fixed, row_idx)[0].cpu().numpy()
    cost = float(r0 @ r0)
    lam = 1e-6
    it = 0
    converged = len(theta) == 0
    jac = np.zeros((r0.size, len(theta)))
    for it in range(1, max_iter + 1):
        if len(theta) == 0:
            break
        jac = _jacobian(theta, space, pb, fixed, row_idx, step)
        # residual r = meas - model, so d r / d theta = -jac_model; jac here is d r / d theta
        g = jac.T @ r0
        h = jac.T @ jac
        d = np.maximum(np.diag(h), 1e-12 * max(np.diag(h).max(), 1e-300))
        improved = False
        for _ in range(12):
            try:
                delta = -np.linalg.solve(h + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            cand = np.clip(theta + delta, lo, hi)
            c_new = cost_of(cand)
            if c_new <= cost:
                improved = True
                rel = (cost - c_new) / max(cost, 1e-300)
                step_small = np.all(np.abs(cand - theta) <= 1e-9 * np.maximum(space.scale, np.abs(theta)))
                theta, cost = cand, c_new
                lam = max(lam / 10, 1e-12)
                break
            lam *= 10
        r0 = _whitened(torch.as_tensor(theta[None], dtype=dt, device=dev), space, pb, fixed, row_idx)[0].cpu().numpy()
        if not improved or rel < 1e-9 or step_small:
            converged = True
            break
    if len(theta):
        jac = _jacobian(theta, space, pb, fixed, row_idx, step)
    n_obs = r0.size
    s2 = cost / max(n_obs - len(theta), 1)
    cov = _covariance(jac, s2, space.scale) if len(theta) else np.zeros((0, 0))
    sig = pb.sigma.cpu().numpy()
    r_nm = r0.reshape(-1, len(sig)) * sig
    return ArmFit(space, theta, cov, (r_nm**2).sum(axis=0), int(r_nm.shape[0]), it, converged, jac)

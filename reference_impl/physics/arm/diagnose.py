"""Rank the arm effects the torque model is missing (nested-model comparison on torque logs).

For every candidate effect (registered with ``model="arm"``, and whose ``needs`` the data
meet) the effect is added to the base model (URDF + the effects already in physics.json) and
fitted (:func:`~reference_impl.physics.arm.identify.fit_effects`). It is *reported* only when
all of the gate's tests pass (research notes, sections 6.3-6.4):

1. information criterion: ``dBIC = sum_j N ln(RSS_j' / RSS_j) + k ln(N J) <= -10`` (per-joint
   noise variances profiled out, so the figure does not rest on the noise estimate);
2. held-out error: the data are split by trajectory (leave one trajectory out; 5 groups above
   five trajectories; a single trajectory is cut into 4 contiguous blocks, never by sample).
   Each fold is refitted on its training units by the physics fitter. The held-out mean squared
   whitened residual must fall by more than the 95th percentile of the fall the same effect
   achieves on null data (white noise at the estimated noise floor, 40 draws, same split; the
   effect linearised at its full-data optimum, exact for the linear effects);
3. effect size: the fitted effect must move the predicted efforts by at least
   ``effect_size_min`` (0.5) noise standard deviations RMS over a whole trajectory of at least
   one joint (aggregated, so single noisy samples cannot pass it).

Effects are ranked reported first, then by dBIC. Each row names the phases where the effect
reduces the residual most, the rivals whose fitted corrections look alike (cosine > 0.7), and
the experiment that separates them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from reference_impl.physics.arm.compare import ARM_PHASES, base_prediction, label_phases
from reference_impl.physics.arm.effects import ArmEffect, payload_com
from reference_impl.physics.arm.identify import ArmFit, UnitLayout, fit_many, unit_layout
from reference_impl.physics.arm.torque_model import ArmProblem
from reference_impl.physics.effects import available_effects, get_effect

__all__ = ["diagnose_torques", "unit_folds", "DEFAULT_GATE"]

DEFAULT_GATE: dict[str, float] = {
    "delta_bic_max": -10.0,
    "effect_size_min": 0.5,
    "null_quantile": 0.95,
}

_NOT_IN_TORQUE_MODEL = {
    "joint_elasticity": "gravity droop shows in end-effector or camera positions, not in joint torques; "
    "needs an ee_poses stream and a kinematic residual (not implemented)",
    "backlash": "a dead band between motor and link angle; needs link-side or end-effector measurements "
    "(not implemented)",
    "kinematic_offsets": "MDH offsets need end-effector or camera measurements (not implemented)",
}


def unit_folds(layout: UnitLayout) -> list[np.ndarray]:
    """Held-out unit groups: each unit alone up to five units, else five round-robin groups."""
    n = layout.n_units
    groups = [[k] for k in range(n)] if n <= 5 else [list(range(g, n, 5)) for g in range(5)]
    return [np.asarray(g, dtype=np.int64) for g in groups]


def _ms(x: np.ndarray) -> float:
    return float(np.mean(x * x)) if x.size else 0.0


def _candidates(
    names: Sequence[str] | None, pb: ArmProblem
) -> tuple[list[ArmEffect], list[dict[str, str]]]:
    given = names
    names = list(names) if names is not None else available_effects(model="arm")
    out, skipped = [], []
    for n in names:
        e = get_effect(n)
        if not isinstance(e, ArmEffect):
            skipped.append({"name": n, "reason": "not an arm torque-model effect"})
            continue
        missing = [x for x in e.needs if x not in pb.data.has]
        if missing:
            skipped.append({"name": n, "reason": f"needs {', '.join(missing)} (not in the data)"})
            continue
        out.append(e)
    if given is None:
        registered = set(available_effects())
        skipped += [
            {"name": k, "reason": v} for k, v in _NOT_IN_TORQUE_MODEL.items() if k not in registered
        ]
    return out, skipped


def _params(fit: ArmFit, eff: ArmEffect) -> dict[str, Any]:
    params = fit.intervals(eff.name)
    if eff.name == "payload":
        com = payload_com(fit.values("payload"), fit.effect_cov("payload"))
        for k, (v, sd) in com.items():
            params[k] = {
                "value": v,
                "low": v - 1.96 * sd,
                "high": v + 1.96 * sd,
                "unit": "m",
                "derived": True,
            }
    return params


def diagnose_torques(
    pb: ArmProblem,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    candidates: Sequence[str] | None = None,
    gate: dict[str, float] | None = None,
    null_draws: int = 40,
    seed: int = 0,
) -> dict[str, Any]:
    """Fit and rank candidate arm effects.

    Args:
        pb: prepared data; fixed: effects held at physics.json values.
        candidates: effect names (default: every registered arm effect).
        gate: thresholds overriding :data:`DEFAULT_GATE`.
        null_draws: white-noise draws for the held-out null distribution.
        seed: random seed of the null draws.

    Returns:
        JSON-ready dict with ``effects`` (ranked rows: name, family, reported, delta_bic,
        heldout_rms_before, heldout_rms_after [N m], effect_size_sigma, params {value, low,
        high, unit}, phases, rivals, separate_by, reasons), ``skipped``, ``noise_floor_nm``,
        ``split`` and ``gate``.
    """
    g = {**DEFAULT_GATE, **(gate or {})}
    effs, skipped = _candidates(candidates, pb)
    sig = pb.sigma.cpu().numpy()
    n, nj = pb.n, len(sig)
    base = base_prediction(pb, fixed)
    r0 = ((pb.tau - base) / pb.sigma).cpu().numpy()  # [N, J] whitened
    rss0 = (r0**2).sum(axis=0) * sig**2
    layout = unit_layout(pb)
    folds = unit_folds(layout)
    test_rows = [np.flatnonzero(np.isin(layout.unit, f)) for f in folds]
    groups, masks = [], []
    for eff in effs:
        groups.append([eff.name])
        masks.append(None)
        for f in folds:
            m = np.ones(layout.n_units, bool)
            m[f] = False
            groups.append([eff.name])
            masks.append(m)
    fits = fit_many(pb, groups, fixed=fixed, masks=masks, layout=layout) if groups else []
    lab = label_phases(pb)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((n * nj, null_draws))
    rows_flat = [(t[:, None] * nj + np.arange(nj)[None, :]).ravel() for t in test_rows]
    rows_out = []
    deltas: dict[str, np.ndarray] = {}
    per = 1 + len(folds)
    for c, eff in enumerate(effs):
        fit = fits[c * per]
        k = len(fit.free)
        r1 = fit.resid
        rss1 = (r1**2).sum(axis=0) * sig**2
        dbic = float(
            np.sum(n * np.log(np.maximum(rss1, 1e-300) / np.maximum(rss0, 1e-300)))
            + k * np.log(n * nj)
        )
        before = np.concatenate([r0[t] for t in test_rows])
        after = np.concatenate([fits[c * per + 1 + i].resid[t] for i, t in enumerate(test_rows)])
        gain = _ms(before) - _ms(after)
        # null: the same effect fitted (linearised at its optimum) to white noise, same split
        jac = fit.jac
        h_all, gn_all = jac.T @ jac, jac.T @ noise
        null_gain = np.zeros(null_draws)
        for rows in rows_flat:
            js = jac[rows]
            coef = np.linalg.pinv(h_all - js.T @ js, rcond=1e-12, hermitian=True) @ (
                gn_all - js.T @ noise[rows]
            )
            null_gain += (noise[rows] ** 2).sum(0) - ((noise[rows] - js @ coef) ** 2).sum(0)
        null_gain /= max(sum(len(r) for r in rows_flat), 1)
        null_thr = float(np.quantile(null_gain, g["null_quantile"]))
        delta = r0 - r1  # whitened change of the prediction, [N, J]
        deltas[eff.name] = delta.ravel()
        size = 0.0
        for tr in range(pb.data.num_traj):
            sel = pb.data.traj == tr
            size = max(size, float(np.sqrt(np.mean(delta[sel] ** 2, axis=0)).max()))
        reasons = []
        if not dbic <= g["delta_bic_max"]:
            reasons.append(f"dBIC {dbic:.1f} > {g['delta_bic_max']:g}")
        if not gain > max(null_thr, 0.0):
            reasons.append(
                f"held-out gain {gain:.3g} sigma^2 not above null {max(null_thr, 0.0):.3g}"
            )
        if not size >= g["effect_size_min"]:
            reasons.append(f"effect size {size:.2f} sigma < {g['effect_size_min']:g}")
        drop = r0**2 - r1**2
        phase_gain = {}
        for p, name in enumerate(ARM_PHASES):
            sel = lab == p
            if sel.any():
                phase_gain[name] = float(drop[sel].mean())
        phases = [p for p, v in sorted(phase_gain.items(), key=lambda kv: -kv[1]) if v > 0][:2]
        sig_rows = np.tile(sig, before.size // nj)
        rows_out.append(
            {
                "name": eff.name,
                "family": eff.family,
                "reported": not reasons,
                "delta_bic": dbic,
                "heldout_rms_before": float(np.sqrt(_ms(before.ravel() * sig_rows))),
                "heldout_rms_after": float(np.sqrt(_ms(after.ravel() * sig_rows))),
                "heldout_gain_sigma2": gain,
                "null_gain_p95_sigma2": null_thr,
                "effect_size_sigma": size,
                "params": _params(fit, eff),
                "phases": phases,
                "rivals": [],
                "separate_by": eff.separate_by,
                "description": eff.description,
                "converged": fit.converged,
                "reasons": reasons,
            }
        )
    for row in rows_out:
        a = deltas[row["name"]]
        na = np.linalg.norm(a)
        for other in rows_out:
            if other is row or na == 0:
                continue
            b = deltas[other["name"]]
            nb = np.linalg.norm(b)
            if nb > 0 and float(a @ b) / (na * nb) > 0.7:
                row["rivals"].append(other["name"])
    rows_out.sort(key=lambda r: (not r["reported"], r["delta_bic"]))
    return {
        "model": "arm",
        "n_samples": n,
        "n_trajectories": pb.data.num_traj,
        "noise_floor_nm": {j: float(s) for j, s in zip(pb.data.joint_names, sig, strict=True)},
        "baseline_rms_nm": {
            j: float(np.sqrt(r / n)) for j, r in zip(pb.data.joint_names, rss0, strict=True)
        },
        "split": layout.how + f", {len(folds)} held-out folds",
        "gate": g,
        "effects": rows_out,
        "skipped": skipped,
    }

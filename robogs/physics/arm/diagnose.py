"""Rank the arm effects the model is missing: forward selection of nested models.

There are two residuals, and each candidate is judged on its own (``ArmEffect.residual``):
the joint torques (friction, armature, payload, mass scale, effort time offset; whitened by
the effort noise floor of each joint) and the end-effector poses (elasticity, backlash,
kinematic offsets; whitened by the pose noise floor of each channel ``x y z`` mm, ``rx ry rz``
deg, see :mod:`robogs.physics.arm.kinematic_model`). A dataset with efforts and
``ee_poses`` runs both selections independently, each against its own base model, and
reports their rows together (``residual`` names the one a row was judged on); the procedure
and the gate below are the same for both, with "joint" read as "channel" for the poses.

Candidates are the effects registered with ``model="arm"`` whose ``needs`` the data meet. The
selection is forward stepwise (Efroymson 1960, "Multiple regression analysis"): at each step
every remaining candidate ``C`` is fitted *together with* the effects accepted so far ``S``
(:func:`~robogs.physics.arm.identify.fit_many`; step 1 has ``S`` empty, i.e. the
base model = URDF + the effects already in physics.json) and judged against the model with
``S`` alone by the gate below. The passing candidate with the lowest dBIC is accepted, and the
next step refits the rest on top of ``S + C``; selection stops when no candidate passes. This
keeps look-alikes out: a hidden payload lets a mass scale or an armature pass the gate against
the bare base model, but not once the payload is in it.

The gate (research notes, sections 6.3-6.4), every test against the model with ``S``:

1. information criterion: ``dBIC = sum_j N ln(RSS_j' / RSS_j) + k ln(N J) <= -10`` (per-joint
   noise variances profiled out, so the figure does not rest on the noise estimate; ``k`` the
   candidate's parameters);
2. held-out error: the data are split by trajectory (leave one trajectory out; 5 groups above
   five trajectories; a single trajectory is cut into 4 contiguous blocks, never by sample).
   Each fold refits ``S`` and ``S + C`` on its training units with the physics fitter. The
   held-out mean squared whitened residual must fall by more than the family-wise 95 %
   quantile of the null: white noise at the residual scale of each joint under ``S`` (the
   noise floor times any misfit ``S`` leaves, never below the floor), 40 draws, the same split;
   every candidate of the step fitted to the same draws (the model linearised at the full-data
   optimum of ``S + C``, exact for the linear effects), the largest null fall over the step's
   candidates taken per draw, so that the whole step keeps a 5 % false-positive rate whatever
   the dataset's design (``family_wise=0``: the candidate's own quantile). Each row carries the
   quantile it was judged against (``gate_heldout_sigma2``) and its own
   (``null_gain_p95_sigma2``);
3. effect size: reported (``effect_size_sigma``, the RMS move of the predicted efforts over a
   whole trajectory of one joint, in noise standard deviations), not gated by default
   (``effect_size_min`` 0): the simulated null above is the dataset's own threshold, and a
   fixed size gate (0.5 sigma before) dropped an 8 ms effort lag under 4x effort noise.

Rows: the accepted effects first, in the order they were accepted (``step``), with the
parameters of the final joint fit of all accepted effects; then the others by dBIC, judged at
the last step (against the base model plus every accepted effect, named in ``given``). Each row
names the phases where the effect reduces the residual most, the rivals whose fitted
corrections alone look alike (cosine > 0.7), and the experiment that separates them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robogs.format.errors import InputError
from robogs.physics.arm.compare import ARM_PHASES, base_prediction, label_phases
from robogs.physics.arm.effects import ArmEffect, payload_com
from robogs.physics.arm.identify import (
    ArmFit,
    UnitLayout,
    channels_of,
    fit_many,
    unit_layout,
)
from robogs.physics.arm.kinematic_compare import pose_phases
from robogs.physics.arm.kinematic_model import (
    POSITION_CHANNELS,
    KinProblem,
    base_residual,
    describe,
)
from robogs.physics.arm.torque_model import ArmProblem
from robogs.physics.effects import available_effects, get_effect

__all__ = [
    "diagnose_torques",
    "diagnose_kinematic",
    "split_candidates",
    "unit_folds",
    "holdout_folds",
    "DEFAULT_GATE",
    "RESIDUAL_STREAM",
]

RESIDUAL_STREAM = {"torque": "efforts", "kinematic": "ee_poses"}
"""The stream each residual needs."""

DEFAULT_GATE: dict[str, float] = {
    "delta_bic_max": -10.0,
    "effect_size_min": 0.0,
    "null_quantile": 0.95,
    "family_wise": 1.0,
}


def unit_folds(layout: UnitLayout) -> list[np.ndarray]:
    """Held-out unit groups: each unit alone up to five units, else five round-robin groups."""
    n = layout.n_units
    groups = [[k] for k in range(n)] if n <= 5 else [list(range(g, n, 5)) for g in range(5)]
    return [np.asarray(g, dtype=np.int64) for g in groups]


def holdout_folds(
    pb: ArmProblem | KinProblem, layout: UnitLayout, names: Sequence[str]
) -> list[np.ndarray]:
    """One held-out fold: the units of the named trajectories (``--holdout``).

    Raises:
        InputError: a name that is not a trajectory of the data, all trajectories named, or a
            single-trajectory dataset (its units are blocks, not trajectories).
    """
    known = list(pb.data.traj_names)
    if pb.data.num_traj < 2:
        raise InputError(
            "--holdout needs at least two trajectories", hint="leave it out (default folds)"
        )
    bad = [n for n in names if n not in known]
    if bad:
        raise InputError(
            f"--holdout: no trajectory named {', '.join(bad)}",
            hint="trajectories: " + ", ".join(known[:20]),
        )
    idx = sorted({known.index(n) for n in names})
    if not idx or len(idx) >= len(known):
        raise InputError("--holdout must leave some trajectories to fit on", hint="name fewer")
    return [np.asarray(idx, dtype=np.int64)]


def _ms(x: np.ndarray) -> float:
    return float(np.mean(x * x)) if x.size else 0.0


def split_candidates(
    names: Sequence[str] | None, has: set[str]
) -> tuple[dict[str, list[ArmEffect]], list[dict[str, str]]]:
    """Candidate effects grouped by the residual that judges them, and the skipped ones.

    Args:
        names: effect names (default: every registered arm effect).
        has: streams present in the data (``efforts``, ``ee_poses``).

    Returns:
        ``{"torque": [...], "kinematic": [...]}`` and ``[{name, reason}]`` for effects that are
        not arm effects or whose ``needs`` the data lack.
    """
    if names is None:  # default: every arm effect that is a candidate (not a model correction)
        names = [
            n for n, e in available_effects(model="arm").items() if getattr(e, "candidate", True)
        ]
    names = list(names)
    out: dict[str, list[ArmEffect]] = {k: [] for k in RESIDUAL_STREAM}
    skipped: list[dict[str, str]] = []
    for n in names:
        e = get_effect(n)
        if not isinstance(e, ArmEffect) or e.residual not in RESIDUAL_STREAM:
            skipped.append({"name": n, "reason": "not an arm effect"})
            continue
        missing = [x for x in e.needs if x not in has]
        if missing:
            skipped.append({"name": n, "reason": f"needs {', '.join(missing)} (not in the data)"})
            continue
        out[e.residual].append(e)
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


@dataclass
class _Split:
    """The data split and null draws shared by every step."""

    layout: UnitLayout
    folds: list[np.ndarray]
    test_rows: list[np.ndarray]  # [fold] sample rows held out
    rows_flat: list[np.ndarray]  # [fold] flat (sample * J + joint) rows held out
    noise: np.ndarray  # [N * J, D] white-noise draws
    phases: np.ndarray  # [N, J] phase labels


@dataclass
class _Base:
    """The model a step compares against: the base plus the accepted effects, fitted jointly."""

    names: list[str]
    resid: np.ndarray  # [N, J] whitened residual, all samples
    held: np.ndarray  # [rows of all folds, J] whitened held-out residual
    fit: ArmFit | None


@dataclass
class _Scored:
    row: dict[str, Any]
    fit: ArmFit
    held: np.ndarray
    delta: np.ndarray  # [N * J] whitened change of the prediction against the step's base


def _held_sse(jac: np.ndarray, noise: np.ndarray, rows_flat: list[np.ndarray]) -> np.ndarray:
    """Held-out sum of squared residuals [D] of linear least squares of ``noise`` on ``jac``."""
    sse = np.zeros(noise.shape[1])
    if jac.shape[1] == 0:
        for rows in rows_flat:
            sse += (noise[rows] ** 2).sum(0)
        return sse
    h_all, g_all = jac.T @ jac, jac.T @ noise
    for rows in rows_flat:
        js = jac[rows]
        coef = np.linalg.pinv(h_all - js.T @ js, rcond=1e-12, hermitian=True) @ (
            g_all - js.T @ noise[rows]
        )
        sse += ((noise[rows] - js @ coef) ** 2).sum(0)
    return sse


def _phys_rms(pb: ArmProblem | KinProblem, z: np.ndarray) -> float:
    """RMS in physical units of whitened rows [R, K]: N m over all joints (torque), or the
    RMS length of the position error in mm (kinematic)."""
    x = z * pb.sigma.cpu().numpy()
    if isinstance(pb, KinProblem):
        return float(np.sqrt(np.mean(np.sum(x[:, : len(POSITION_CHANNELS)] ** 2, axis=1))))
    return float(np.sqrt(np.mean(x**2)))


def _sample_phases(pb: ArmProblem | KinProblem) -> np.ndarray:
    """Phase labels [N, K] of the residual channels (joints, or pose channels)."""
    if not isinstance(pb, KinProblem):
        return label_phases(pb)
    return np.repeat(pose_phases(pb)[:, None], len(channels_of(pb)), axis=1)


def _score(
    pb: ArmProblem | KinProblem,
    fixed: dict[str, dict[str, float]] | None,
    base: _Base,
    effs: list[ArmEffect],
    sp: _Split,
    g: dict[str, float],
) -> list[_Scored]:
    """Fit every candidate together with ``base.names`` (and per fold), and apply the gate."""
    sig = pb.sigma.cpu().numpy()
    n, nj = pb.n, len(sig)
    rss0 = (base.resid**2).sum(axis=0) * sig**2
    groups, masks = [], []
    for eff in effs:
        for f in [None, *sp.folds]:
            groups.append([*base.names, eff.name])
            if f is None:
                masks.append(None)
            else:
                m = np.ones(sp.layout.n_units, bool)
                m[f] = False
                masks.append(m)
    fits = fit_many(pb, groups, fixed=fixed, masks=masks, layout=sp.layout) if groups else []
    per = 1 + len(sp.folds)
    total_rows = max(sum(len(r) for r in sp.rows_flat), 1)
    before = base.held
    # null: each candidate added to the accepted ones, fitted (linearised at its full-data
    # optimum) to white noise at the residual scale of each joint under the step's base model
    # (the noise estimated from this dataset: the floor times any misfit the base leaves, never
    # below the floor), with this dataset's split; the same draws for every candidate, so the
    # family-wise quantile is that of the largest null gain over the step's candidates
    scale = np.tile(np.maximum(np.sqrt(np.mean(base.resid**2, axis=0)), 1.0), n)[:, None]
    noise = sp.noise * scale
    nulls = []
    for c, eff in enumerate(effs):
        fit = fits[c * per]
        own = set(fit.space.owner_columns(eff.name))
        base_cols = [p for p, i in enumerate(fit.free) if i not in own]
        nulls.append(
            (
                _held_sse(fit.jac[:, base_cols], noise, sp.rows_flat)
                - _held_sse(fit.jac, noise, sp.rows_flat)
            )
            / total_rows
        )
    q = g["null_quantile"]
    fw_thr = float(np.quantile(np.max(nulls, axis=0), q)) if nulls else 0.0
    out = []
    for c, eff in enumerate(effs):
        fit = fits[c * per]
        own = set(fit.space.owner_columns(eff.name))
        k = sum(1 for i in fit.free if i in own)
        r1 = fit.resid
        rss1 = (r1**2).sum(axis=0) * sig**2
        dbic = float(
            np.sum(n * np.log(np.maximum(rss1, 1e-300) / np.maximum(rss0, 1e-300)))
            + k * np.log(n * nj)
        )
        after = np.concatenate([fits[c * per + 1 + i].resid[t] for i, t in enumerate(sp.test_rows)])
        gain = _ms(before) - _ms(after)
        null_thr = float(np.quantile(nulls[c], q))
        thr = max(fw_thr if g.get("family_wise", 1.0) else null_thr, 0.0)
        delta = base.resid - r1  # whitened change of the prediction, [N, J]
        size = 0.0
        for tr in range(pb.data.num_traj):
            sel = pb.data.traj == tr
            size = max(size, float(np.sqrt(np.mean(delta[sel] ** 2, axis=0)).max()))
        reasons = []
        if not dbic <= g["delta_bic_max"]:
            reasons.append(f"dBIC {dbic:.1f} > {g['delta_bic_max']:g}")
        if not gain > thr:
            reasons.append(
                f"held-out gain {gain:.3g} sigma^2 not above the null {q:.0%} quantile {thr:.3g}"
            )
        if not size >= g["effect_size_min"]:
            reasons.append(f"effect size {size:.2f} sigma < {g['effect_size_min']:g}")
        drop = base.resid**2 - r1**2
        phase_gain = {}
        for p, name in enumerate(ARM_PHASES):
            sel = sp.phases == p
            if sel.any():
                phase_gain[name] = float(drop[sel].mean())
        phases = [p for p, v in sorted(phase_gain.items(), key=lambda kv: -kv[1]) if v > 0][:2]
        row = {
            "name": eff.name,
            "family": eff.family,
            "reported": False,
            "step": None,
            "given": list(base.names),
            "delta_bic": dbic,
            "residual": eff.residual,
            "heldout_rms_before": _phys_rms(pb, before),
            "heldout_rms_after": _phys_rms(pb, after),
            "heldout_unit": "mm" if isinstance(pb, KinProblem) else "N m",
            "heldout_gain_sigma2": gain,
            "null_gain_p95_sigma2": null_thr,
            "null_gain_fw_sigma2": fw_thr,
            "gate_heldout_sigma2": thr,
            "null_draws": int(sp.noise.shape[1]),
            "effect_size_sigma": size,
            "params": _params(fit, eff),
            "phases": phases,
            "rivals": [],
            "separate_by": eff.separate_by,
            "description": eff.description,
            "converged": fit.converged,
            "reasons": reasons,
        }
        out.append(_Scored(row, fit, after, delta.ravel()))
    return out


def diagnose_torques(
    pb: ArmProblem,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    candidates: Sequence[str] | None = None,
    gate: dict[str, float] | None = None,
    null_draws: int = 40,
    seed: int = 0,
    max_effects: int | None = None,
    holdout: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Select the effects missing from the torque model by forward selection (module docstring).

    Args:
        pb: prepared data; fixed: effects held at physics.json values.
        candidates: effect names (default: every registered arm effect); effects judged on
            the end-effector poses are listed under ``skipped``.
        gate: thresholds overriding :data:`DEFAULT_GATE`.
        null_draws: white-noise draws for the held-out null distribution.
        seed: random seed of the null draws.
        max_effects: stop after accepting this many effects (default: no limit); the rows
            not accepted then show the last step they were judged at (``given``).

    Returns:
        JSON-ready dict with ``effects`` (ranked rows: name, family, residual, reported, step,
        given, delta_bic, heldout_rms_before, heldout_rms_after [N m], effect_size_sigma,
        params {value, low, high, unit}, phases, rivals, separate_by, reasons), ``selected``
        (the accepted effects in order), ``steps`` (per step: the effect added and its
        figures), ``skipped``, ``noise_floor_nm``, ``split`` and ``gate``.
    """
    groups, skipped = split_candidates(candidates, pb.data.has)
    skipped += [
        {"name": e.name, "reason": "judged on the end-effector poses (diagnose_kinematic)"}
        for e in groups["kinematic"]
    ]
    out = _select(pb, fixed, groups["torque"], gate, null_draws, seed, max_effects, holdout)
    sig = pb.sigma.cpu().numpy()
    names = pb.data.joint_names
    return {
        "model": "arm",
        "residual": "torque",
        "n_samples": pb.n,
        "n_trajectories": pb.data.num_traj,
        "noise_floor_nm": {j: float(s) for j, s in zip(names, sig, strict=True)},
        "baseline_rms_nm": {j: float(v) for j, v in zip(names, out.pop("baseline"), strict=True)},
        **out,
        "skipped": skipped,
    }


def diagnose_kinematic(
    kp: KinProblem,
    fixed: dict[str, dict[str, float]] | None = None,
    *,
    candidates: Sequence[str] | None = None,
    gate: dict[str, float] | None = None,
    null_draws: int = 40,
    seed: int = 0,
    max_effects: int | None = None,
    holdout: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Select the effects missing from the kinematic model (end-effector poses) by forward
    selection, with the same gate as :func:`diagnose_torques`.

    Returns:
        as :func:`diagnose_torques`, with ``noise_floor`` and ``baseline_rms`` per pose
        channel (units in ``units``: mm, deg), ``link``, ``orientation`` (whether the
        orientation is in the residual) and ``heldout_rms_*`` in mm (RMS length of the
        position error); torque effects are listed under ``skipped``.
    """
    groups, skipped = split_candidates(candidates, {"ee_poses", "efforts"})
    skipped += [
        {"name": e.name, "reason": "judged on the joint torques (diagnose_torques)"}
        for e in groups["torque"]
    ]
    out = _select(kp, fixed, groups["kinematic"], gate, null_draws, seed, max_effects, holdout)
    info = describe(kp)
    return {
        "model": "arm",
        "residual": "kinematic",
        "n_samples": kp.n,
        "n_trajectories": kp.data.num_traj,
        "link": info["link"],
        "orientation": kp.oriented,
        "units": info["units"],
        "noise_floor": info["noise_floor"],
        "baseline_rms": {
            c: float(v) for c, v in zip(kp.channels, out.pop("baseline"), strict=True)
        },
        **out,
        "skipped": skipped,
        "notes": list(kp.data.notes),
    }


def _select(
    pb: ArmProblem | KinProblem,
    fixed: dict[str, dict[str, float]] | None,
    effs: list[ArmEffect],
    gate: dict[str, float] | None,
    null_draws: int,
    seed: int,
    max_effects: int | None,
    holdout: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Forward selection of ``effs`` on the residual of ``pb`` (see the module docstring)."""
    g = {**DEFAULT_GATE, **(gate or {})}
    sig = pb.sigma.cpu().numpy()
    n, nj = pb.n, len(sig)
    if isinstance(pb, KinProblem):
        r0 = base_residual(pb, fixed) / sig  # [N, K] whitened
    else:
        r0 = ((pb.tau - base_prediction(pb, fixed)) / pb.sigma).cpu().numpy()  # [N, J]
    rss0 = (r0**2).sum(axis=0) * sig**2
    layout = unit_layout(pb)
    folds = holdout_folds(pb, layout, holdout) if holdout else unit_folds(layout)
    test_rows = [np.flatnonzero(np.isin(layout.unit, f)) for f in folds]
    rng = np.random.default_rng(seed)
    sp = _Split(
        layout,
        folds,
        test_rows,
        [(t[:, None] * nj + np.arange(nj)[None, :]).ravel() for t in test_rows],
        rng.standard_normal((n * nj, null_draws)),
        _sample_phases(pb),
    )
    base = _Base([], r0, np.concatenate([r0[t] for t in test_rows]), None)
    remaining = list(effs)
    latest: dict[str, dict[str, Any]] = {}
    alone: dict[str, _Scored] = {}
    accepted_rows: list[dict[str, Any]] = []
    steps: list[dict[str, Any]] = []
    limit = len(effs) if max_effects is None else max_effects
    while remaining:
        scored = _score(pb, fixed, base, remaining, sp, g)
        for s in scored:
            latest[s.row["name"]] = s.row
            alone.setdefault(s.row["name"], s)
        passing = [s for s in scored if not s.row["reasons"]]
        if not passing:
            break
        best = min(passing, key=lambda s: s.row["delta_bic"])
        best.row["reported"] = True
        best.row["step"] = len(accepted_rows) + 1
        accepted_rows.append(best.row)
        steps.append(
            {
                "step": best.row["step"],
                "added": best.row["name"],
                "residual": best.row["residual"],
                "given": list(base.names),
                "delta_bic": best.row["delta_bic"],
                "heldout_rms_before": best.row["heldout_rms_before"],
                "heldout_rms_after": best.row["heldout_rms_after"],
                "effect_size_sigma": best.row["effect_size_sigma"],
                "heldout_gain_sigma2": best.row["heldout_gain_sigma2"],
                "gate_heldout_sigma2": best.row["gate_heldout_sigma2"],
                "null_draws": best.row["null_draws"],
                "candidates_passing": [s.row["name"] for s in passing],
            }
        )
        base = _Base([*base.names, best.row["name"]], best.fit.resid, best.held, best.fit)
        remaining = [e for e in remaining if e.name != best.row["name"]]
        if len(accepted_rows) >= limit:
            break
    if base.fit is not None:  # accepted effects: the parameters of the final joint fit
        for row in accepted_rows:
            row["params"] = _params(base.fit, get_effect(row["name"]))
    others = [latest[e.name] for e in remaining if e.name in latest]
    for row in others:
        first = alone[row["name"]].row
        if base.names and row["given"] == base.names and not first["reasons"]:
            row["reasons"].insert(
                0, f"passes alone, explained by {' + '.join(base.names)} once they are added"
            )
    # rivals: look-alike corrections, each effect fitted alone to the base model
    for name, s in alone.items():
        a = s.delta
        na = np.linalg.norm(a)
        for other, o in alone.items():
            if other == name or na == 0:
                continue
            nb = np.linalg.norm(o.delta)
            if nb > 0 and float(a @ o.delta) / (na * nb) > 0.7:
                latest[name]["rivals"].append(other)
    others.sort(key=lambda r: r["delta_bic"])
    if others:  # why the loop stopped: the best candidate left and the gate it failed
        best_left = max(others, key=lambda r: r["heldout_gain_sigma2"])
        stop = {
            "given": list(base.names),
            "best_left": best_left["name"],
            "heldout_gain_sigma2": best_left["heldout_gain_sigma2"],
            "gate_heldout_sigma2": best_left["gate_heldout_sigma2"],
            "reasons": best_left["reasons"],
        }
    else:
        stop = {"given": list(base.names), "best_left": None, "reasons": ["no candidate left"]}
    return {
        "stop": stop,
        "baseline": np.sqrt(rss0 / n),
        "split": layout.how
        + (f", held out: {', '.join(holdout)}" if holdout else f", {len(folds)} held-out folds"),
        "gate": g,
        "selection": "forward: each step refits the candidates on top of the accepted effects",
        "selected": [r["name"] for r in accepted_rows],
        "steps": steps,
        "effects": accepted_rows + others,
    }

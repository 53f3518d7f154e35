"""Held-out machinery of the physics diagnosis: folds, the fold step, partial identification.

Used by :mod:`robogs.physics.diagnose` (ranking candidate effects) and :mod:`robogs.physics.api`
(``fit``'s held-out error), so that both measure held-out error the same way.

* A *fold* (:func:`trajectory_folds`) is a set of whole trajectories held out together:
  ``K = min(N_FOLDS, T)`` folds of the ``T`` trajectories, trajectory ``t`` in fold ``t mod K``.
  Trajectories are never split by sample, which would leak autocorrelated noise into training.
* A fold's parameters are *one bounded Gauss-Newton step* (:func:`gn_step`) from the full fit,
  using the training trajectories' residuals and Jacobians only: the step minimises their
  linearised chi^2 within the parameters' prior bounds (bounded-variable least squares), each
  trajectory keeping its nuisance parameters of the full fit. :func:`heldout_rollouts` rolls
  the model out at every fold's parameters and halves a step that raises the training chi^2.
* The *held-out chi^2* [sigma^2] of a fit is the sum of the whitened residuals (residual over
  the noise scale, dimensionless) squared of each trajectory at the parameters of the fold that
  held it out. The *held-out fall* of a candidate effect is the base model's held-out chi^2 minus
  the candidate's, in sigma^2; the gate (:mod:`robogs.physics.gate`) sums it over the
  trajectories the effect acts on.
* A *held-out choice* (``--holdout T1,T2``, :func:`holdout_folds`) replaces the K folds by one
  fold: the named trajectories are held out together, the others train. The held-out chi^2 is
  then that of the named trajectories only, and the gate's null (:mod:`robogs.physics.gate`)
  is simulated for that same fold (the folds reach ``gate.calibrate`` unchanged); held-out
  RMS values are taken over the held-out trajectories' samples only (:func:`held_mask`).
* Partial identification: a fit whose parameters are not all determined may still determine a
  combination of them; :func:`determined_direction` finds the best-determined direction with
  each parameter scaled by its prior range, and :func:`determined_combination` writes it as
  text for the reports.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robogs.format.errors import InputError
from robogs.physics.engine import Engine
from robogs.physics.fit import FitOutcome, on_bounds
from robogs.physics.space import ParamSpace

__all__ = [
    "N_FOLDS",
    "holdout_folds",
    "holdout_from_column",
    "HOLDOUT_COLUMNS",
    "held_mask",
    "split_label",
    "split_tag",
    "NULL_EIG",
    "trajectory_folds",
    "gn_step",
    "heldout_rollouts",
    "determined_direction",
    "determined_combination",
]

N_FOLDS = 5
"""Default number of held-out folds (fewer when there are fewer trajectories)."""
NULL_EIG = 1e-13
"""Eigenvalues of a covariance block under this fraction of its largest are the null space that
the pseudo-inverse of the information dropped (infinite variance, not zero)."""
_Z = 1.959963984540054  # two-sided 95 % normal quantile


def determined_direction(cov: np.ndarray, span: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The best-determined direction of a block of parameters, or None when none is determined.

    Each parameter is scaled by its prior range ``span`` [its unit], so that the bounds become
    a unit box; ``u`` is the eigenvector of the scaled covariance ``cov / (span span^T)`` with
    the smallest eigenvalue ``lam`` (the combination ``sum_i u_i theta_i / span_i`` with the
    least variance). It is determined when its 95 % half-width ``1.96 sqrt(lam)`` is under the
    box's extent along ``u``, ``sum_i |u_i|``: for one parameter, fit's rule that its interval
    be narrower than its bounds (:mod:`robogs.physics.fit`). Eigenvalues under ``NULL_EIG`` of
    the largest are the information's null space, which the pseudo-inverse dropped (variance
    infinite, not zero), and are never chosen.

    Args:
        cov: [k, k] covariance of the parameters (others marginalised).
        span: [k] upper minus lower bound of each.

    Returns:
        (u [k], ratio): the unit direction in scaled units (sign: largest component positive)
        and its half-width over the box's extent (< 1), or None.
    """
    cov = np.asarray(cov, dtype=float)
    span = np.asarray(span, dtype=float)
    if cov.size == 0 or not np.all(np.isfinite(cov)) or not np.all(span > 0):
        return None
    c = cov / np.outer(span, span)
    lam, vec = np.linalg.eigh(0.5 * (c + c.T))
    if lam[-1] <= 0:
        return None
    live = np.nonzero(lam > NULL_EIG * lam[-1])[0]
    if live.size == 0:
        return None
    i = int(live[0])
    u = vec[:, i] * np.sign(vec[np.argmax(np.abs(vec[:, i])), i])
    ratio = float(_Z * np.sqrt(lam[i]) / np.sum(np.abs(u)))
    return (u, ratio) if ratio < 1.0 else None


def determined_combination(
    space: ParamSpace, out: FitOutcome, free: list[int], jj: list[int]
) -> str | None:
    """The determined combination of an effect's parameters (indices ``jj`` into ``free``) as
    text, or None when no direction is determined (:func:`determined_direction`). Parameters
    the predictions do not change with are left out: their variance is not defined."""
    live = [j for j in jj if "do not change" not in out.why_param[j]]
    if not live or out.cov.shape[0] != len(free):
        return None
    cols = [free[j] for j in live]
    span = space.upper[cols] - space.lower[cols]
    got = determined_direction(out.cov[np.ix_(live, live)], span)
    if got is None:
        return None
    u, ratio = got
    names = [space.slots[c].param for c in cols]
    value = float(np.sum(u * out.theta[cols] / span))
    half = float(_Z * np.sqrt(u @ (out.cov[np.ix_(live, live)] / np.outer(span, span)) @ u))
    terms = " + ".join(
        f"{w:.3g} {p.name}/{s:.3g}{(' ' + p.unit) if p.unit not in ('', '-') else ''}"
        for w, p, s in zip(u, names, span, strict=True)
    )
    return (
        f"determined: {terms} = {value:.3g} +- {half:.2g} (95 %; each parameter over its prior "
        f"range, the half-width {100 * ratio:.0f} % of the bounds' extent along it)"
    )


def trajectory_folds(n_traj: int) -> list[np.ndarray]:
    """The K = min(N_FOLDS, n_traj) held-out folds: boolean masks [n_traj], fold ``f`` holding
    out the trajectories ``t`` with ``t mod K == f`` (whole trajectories, never samples)."""
    k = min(N_FOLDS, n_traj)
    return [np.arange(n_traj) % k == f for f in range(k)]


def holdout_folds(names: Sequence[str], holdout: Sequence[str] | None) -> list[np.ndarray]:
    """The held-out folds of trajectories ``names``: the default :func:`trajectory_folds`
    when ``holdout`` is None or empty, else one fold holding out the named ones.

    A name is a trajectory's name, or an episode's id that the split cut into trajectories
    ``<episode>#<k>`` (:mod:`robogs.physics.split`): then all of them are held out.

    Raises:
        InputError: a name that is no trajectory (the message lists the valid ones), a
            recording of one trajectory, or a choice that holds out every trajectory (nothing
            is left to fit the fold on).
    """
    names = [str(n) for n in names]
    if holdout is None or len(holdout) == 0:
        return trajectory_folds(len(names))
    asked = [str(h).strip() for h in holdout if str(h).strip()]
    if not asked:
        raise InputError(
            "--holdout names no trajectory",
            hint="name one or more trajectories (TRAJ[,TRAJ...]), or leave --holdout out for "
            "the default folds",
        )
    valid = ", ".join(names[:40]) + (f", ... ({len(names)} in all)" if len(names) > 40 else "")
    if len(names) < 2:
        raise InputError(
            f"--holdout needs at least two trajectories; the data hold {len(names)}",
            hint="record more trajectories, or leave --holdout out",
        )
    mask = np.zeros(len(names), dtype=bool)
    bad = []
    for h in asked:
        hit = [i for i, n in enumerate(names) if n == h or n.startswith(h + "#")]
        if not hit:
            bad.append(h)
        mask[hit] = True
    if bad:
        raise InputError(
            f"--holdout: no trajectory named {', '.join(repr(b) for b in bad)}",
            hint=f"valid trajectory names: {valid}",
        )
    if mask.all():
        raise InputError(
            f"--holdout holds out all {len(names)} trajectories: none is left to fit on",
            hint=f"name fewer trajectories (valid names: {valid})",
        )
    return [mask]


HOLDOUT_COLUMNS = ("segment",)
"""Per-trajectory columns ``--holdout-column`` reads: ``segment``, each episode's segment in the
manifest, which the tabular log import fills from the log's ``segment``, ``episode`` or
``trajectory`` column (one episode, or several cut at time gaps, per value) and other
converters with the source's name (a file, a bag's session)."""


def holdout_from_column(episodes: Sequence[tuple[str, str]], spec: str) -> tuple[list[str], str]:
    """The episodes ``--holdout-column`` selects, and what it selected (for people).

    ``spec`` is ``COLUMN=V1,V2,...`` (every episode whose column value is one of the values) or
    ``COLUMN`` alone (every episode with the value of the last episode in the manifest's order:
    a log's last segment, so the model is tested on the data recorded last). ``COLUMN`` is one
    of :data:`HOLDOUT_COLUMNS`.

    Args:
        episodes: (episode id, segment) in the manifest's order.

    Raises:
        InputError: an unknown column, a value no episode has (the valid values are listed),
            or no episode at all.
    """
    col, eq, raw = str(spec).partition("=")
    col = col.strip()
    if col not in HOLDOUT_COLUMNS:
        raise InputError(
            f"no per-trajectory column {col!r}",
            where="--holdout-column",
            hint="use segment=V1,V2 (each episode's segment: the tabular import stores the log's "
            "segment, episode or trajectory column there), or --holdout TRAJ[,TRAJ...]",
        )
    if not episodes:
        raise InputError("the dataset has no episode", where="--holdout-column")
    values = list(dict.fromkeys(seg for _, seg in episodes))
    shown = ", ".join(values[:40]) + (f", ... ({len(values)} in all)" if len(values) > 40 else "")
    if eq:
        asked = [v.strip() for v in raw.split(",") if v.strip()]
        if not asked:
            raise InputError(
                f"--holdout-column {spec!r} names no value",
                where="--holdout-column",
                hint=f"{col}=V1,V2,...; values: {shown}",
            )
        bad = [v for v in asked if v not in values]
        if bad:
            raise InputError(
                f"no episode has {col} {', '.join(repr(b) for b in bad)}",
                where="--holdout-column",
                hint=f"values of {col}: {shown}",
            )
    else:
        asked = [episodes[-1][1]]
    ids = [eid for eid, seg in episodes if seg in asked]
    return ids, f"{col} in {{{', '.join(asked)}}}: episodes {', '.join(ids)}"


def held_mask(folds: list[np.ndarray], n_traj: int) -> np.ndarray:
    """[T] trajectories held out by some fold (all of them for the default folds)."""
    out = np.zeros(n_traj, dtype=bool)
    for f in folds:
        out |= np.asarray(f, dtype=bool)
    return out


def split_label(names: Sequence[str], folds: list[np.ndarray]) -> str:
    """How the trajectories were held out, for people: ``"5 folds of whole trajectories"`` or
    ``"held out: a, b (2 of 9 trajectories)"``."""
    if len(folds) == 1 and not folds[0].all():
        held = [n for n, m in zip(names, folds[0], strict=True) if m]
        return f"held out: {', '.join(held)} ({len(held)} of {len(names)} trajectories)"
    return f"{len(folds)} folds of whole trajectories"


def split_tag(folds: list[np.ndarray]) -> str:
    """The split for cache keys: ``""`` for the default folds, else the held-out mask (so a
    calibration simulated for one split is never read back for another)."""
    n = len(folds[0]) if folds else 0
    default = trajectory_folds(n)
    if len(folds) == len(default) and all(
        np.array_equal(a, b) for a, b in zip(folds, default, strict=True)
    ):
        return ""
    return "|holdout:" + ";".join("".join("1" if x else "0" for x in f) for f in folds)


def gn_step(
    out: FitOutcome, space: ParamSpace, free: list[int], train: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """One bounded Gauss-Newton step of the global parameters using training trajectories only.

    The step minimises the training trajectories' linearised chi^2 within the parameter bounds
    (bounded-variable least squares, Stark & Parker 1995, Comput. Stat. 10; ``scipy``'s
    ``lsq_linear``), not the unbounded step clipped afterwards: clipping one parameter at its
    bound would leave the others with their compensation for it (a Stribeck fit whose ``dmu``
    was clipped to 0 kept a friction 12 % low and put held-out chi^2 up by 1600 sigma^2).
    Returns the parameters and, per column of ``free``, ``"lower"``/``"upper"``/``""`` where
    the step stopped on a bound.
    """
    from scipy.optimize import lsq_linear

    th = out.theta.copy()
    if not free:
        return th, []
    j = out.jac[train].reshape(-1, len(free))
    r = out.resid[train].reshape(-1)
    lo = space.lower[free] - th[free]
    hi = space.upper[free] - th[free]
    norm = np.linalg.norm(j, axis=0)
    live = (norm > 0) & (hi > lo)  # a column the data do not move takes no step
    step = np.zeros(len(free))
    if live.any():
        sc = norm[live]
        sol = lsq_linear(j[:, live] / sc, -r, bounds=(lo[live] * sc, hi[live] * sc), method="bvls")
        step[live] = sol.x / sc
    th[free] = np.clip(th[free] + step, space.lower[free], space.upper[free])
    return th, on_bounds(space, th, free)


def heldout_rollouts(
    eng: Engine,
    space: ParamSpace,
    outs: list[FitOutcome],
    frees: list[list[int]],
    folds: list[np.ndarray],
    halvings: int = 3,
) -> tuple[np.ndarray, list[list[list[str]]], list[int]]:
    """Residuals [P*K, T, N] at each fit's fold parameters, rolled out in batches.

    A fold's parameters are the bounded Gauss-Newton step of :func:`gn_step`. Where the step
    raises the training trajectories' chi^2 above the full fit's (the linearisation does not
    hold that far: a poorly determined Stribeck pair), it is halved, up to ``halvings`` times
    (backtracking, Nocedal & Wright 2006, ch. 3), and the point with the lowest training chi^2
    is kept; the held-out trajectories never take part in the choice. Returns the residuals,
    the bound hits per fit and fold, and per fit the number of folds whose step was halved.
    """
    k_f = len(folds)
    full, steps, locs, trains, hits = [], [], [], [], []
    for out, free in zip(outs, frees, strict=True):
        hit = []
        for fmask in folds:
            th, h = gn_step(out, space, free, ~fmask)
            full.append(out.theta)
            steps.append(th)
            locs.append(out.local)
            trains.append(~fmask)
            hit.append(h)
        hits.append(hit)
    full_a, step_a, loc_a = np.stack(full), np.stack(steps), np.stack(locs)
    held = eng.evaluate(space, step_a, loc_a)  # [P*K, T, N*4]
    ref = np.array(
        [np.sum(outs[i // k_f].resid[trains[i]] ** 2) for i in range(len(steps))], dtype=float
    )

    def train_cost(r: np.ndarray, i: int) -> float:
        return float(np.sum(r[trains[i]] ** 2))

    cost = np.array([train_cost(held[i], i) for i in range(len(steps))])
    best = cost.copy()
    halved = np.zeros(len(steps), dtype=bool)
    for h in range(1, halvings + 1):
        bad = np.nonzero(cost > ref)[0]
        if bad.size == 0:
            break
        halved[bad] = True
        frac = 0.5**h
        trial = full_a[bad] + frac * (step_a[bad] - full_a[bad])
        res = eng.evaluate(space, trial, loc_a[bad])
        for j, i in enumerate(bad):
            cost[i] = train_cost(res[j], i)
            if cost[i] < best[i]:
                best[i] = cost[i]
                held[i] = res[j]
    per_fit = [int(halved[p * k_f : (p + 1) * k_f].sum()) for p in range(len(outs))]
    return held, hits, per_fit

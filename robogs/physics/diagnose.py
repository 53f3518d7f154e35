"""Rank candidate effects: which missing physics explains the residual?

For every candidate effect whose needs the data meets, the base model plus that effect is
refitted (all candidates in one batched fit, :mod:`robogs.physics.fit`). Each row
reports, against the refitted base model:

* ``delta_bic`` = ``n ln(chi2_e / chi2_b) + (k_e - k_b) ln n`` (Schwarz 1978; the noise scale
  is left free so a mis-estimated sigma cannot inflate it);
* held-out error by trajectory: K folds of whole trajectories; the parameters of each fold come
  from one Gauss-Newton step from the full fit using only the training trajectories, the error
  is measured on the held-out ones (never split by sample, which would leak autocorrelation).
  The gate's held-out gain is the fall of held-out chi^2 on the trajectories the effect acts
  on (``z_t >= AFFECTED_Z``), so that an effect seen only in a few drops is not diluted by
  many pushes it does not touch;
* effect size in noise units: per trajectory ``z_t = ||(pred_e - pred_b) / sigma||`` over the
  whole trajectory, the maximum over trajectories (a short slide moving every sample by less
  than sigma can still be decisive);
* share of the above-noise residual explained, fitted parameters with 95 % intervals, the
  phases where the residual falls, rivals (nearly collinear predicted changes) and the
  experiment that separates them, and a verdict.

The reporting gate (all required): ``delta_bic <= -10``, held-out chi^2 falls by more than
``HELDOUT_MIN_GAIN`` on the trajectories the effect acts on, effect size
``>= EFFECT_SIZE_MIN``, and an identifiable fit. Null data must report nothing: on 10 null
scenarios of the full design (seeds 100-109, nominal noise; bench/diagnose.py) no candidate
exceeded a held-out gain of 0.094 or an effect size of 5.2 sigma, although ΔBIC reached -73;
the thresholds (0.12, 6 sigma) sit above those maxima.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from robogs.physics.effects import Effect, available_effects, get_effect
from robogs.physics.engine import Engine, rms_mm
from robogs.physics.fit import FitOutcome, Problem
from robogs.physics.phases import PHASES
from robogs.physics.space import ParamSpace

__all__ = [
    "ParamEstimate",
    "EffectRow",
    "DiagnoseResult",
    "diagnose_recording",
    "start_points",
    "DBIC_MAX",
    "HELDOUT_MIN_GAIN",
    "EFFECT_SIZE_MIN",
    "RIVAL_COSINE",
    "RIGID_RIVAL_COSINE",
]

DBIC_MAX = -10.0
HELDOUT_MIN_GAIN = 0.12
EFFECT_SIZE_MIN = 6.0
AFFECTED_Z = 3.0
RIVAL_COSINE = 0.9
"""Cosine above which camera-intrinsics parts are rivals (:mod:`robogs.physics.intrinsics`)."""
RIGID_RIVAL_COSINE = 0.7
"""Cosine of the predicted changes above which two rigid-model effects are rivals (the arm
model uses the same 0.7): a table tilt and anisotropic friction reach 0.78 on six pushes in
three directions (no opposite pair), a tilt and viscous damping stay under 0.3."""
_N_FOLDS = 5


@dataclass
class ParamEstimate:
    """A fitted parameter with its 95 % interval (low/high = +-inf if unidentifiable)."""

    name: str
    value: float
    low: float
    high: float
    unit: str


@dataclass
class EffectRow:
    """One candidate effect, fitted and judged."""

    name: str
    family: str
    reported: bool
    verdict: str
    delta_bic: float
    heldout_rms_before: float
    heldout_rms_after: float
    heldout_gain: float
    heldout_dchi2: float
    effect_size: float
    effect_size_total: float
    explained: float
    rms_after: float
    params: list[ParamEstimate]
    phases: list[str] = field(default_factory=list)
    rivals: list[str] = field(default_factory=list)
    similarity: dict[str, float] = field(default_factory=dict)
    separate_by: str = ""
    note: str = ""
    unit: str = "mm"  # of the RMS fields (``px`` for effects seen in mask boundaries)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the documented keys first)."""
        d = asdict(self)
        d["params"] = [asdict(p) for p in self.params]
        for k in (
            "delta_bic",
            "heldout_rms_before",
            "heldout_rms_after",
            "heldout_gain",
            "heldout_dchi2",
            "effect_size",
            "effect_size_total",
            "explained",
            "rms_after",
        ):
            d[k] = _finite(d[k])
        for p in d["params"]:
            for k in ("value", "low", "high"):
                p[k] = _finite(p[k])
        return d


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


@dataclass
class DiagnoseResult:
    """Ranked effects (reported first, then by delta BIC), skipped ones with the reason."""

    rows: list[EffectRow]
    skipped: list[tuple[str, str]]
    base_params: list[ParamEstimate]
    rms_base: float
    noise_floor: float
    noise: dict[str, float]
    n_residuals: int
    gate: dict[str, float]

    @property
    def reported(self) -> list[EffectRow]:
        return [r for r in self.rows if r.reported]

    def to_dict(self) -> dict[str, Any]:
        return {
            "effects": [r.to_dict() for r in self.rows],
            "skipped": [{"name": n, "reason": why} for n, why in self.skipped],
            "base_params": [asdict(p) for p in self.base_params],
            "rms_base_mm": self.rms_base,
            "noise_floor_mm": self.noise_floor,
            "noise": self.noise,
            "n_residuals": self.n_residuals,
            "gate": self.gate,
        }


def _estimates(
    space: ParamSpace, out: FitOutcome, cols: list[int], free: list[int]
) -> list[ParamEstimate]:
    res = []
    for c in cols:
        j = free.index(c)
        s = space.slots[c]
        v = float(out.theta[c])
        sd = float(out.std[j]) if len(out.std) else float("inf")
        name = s.param.name if s.owner != "base" else s.param.name
        res.append(ParamEstimate(name, v, v - 1.96 * sd, v + 1.96 * sd, s.param.unit))
    return res


def start_points(space: ParamSpace, effect: Effect, theta0: np.ndarray) -> list[np.ndarray]:
    """Start vectors of one candidate: ``theta0`` (the effect off) and one per ``effect.starts``."""
    out = [theta0]
    for start in effect.starts:
        th = theta0.copy()
        for k, v in start.items():
            th[space.index(effect.name, k)] = v
        out.append(th)
    return out


def _folds(n_traj: int) -> list[np.ndarray]:
    k = min(_N_FOLDS, n_traj)
    return [np.arange(n_traj) % k == f for f in range(k)]


def _gn_step(out: FitOutcome, space: ParamSpace, free: list[int], train: np.ndarray) -> np.ndarray:
    """One Gauss-Newton step of the global parameters using training trajectories only."""
    th = out.theta.copy()
    if not free:
        return th
    j = out.jac[train].reshape(-1, len(free))
    r = out.resid[train].reshape(-1)
    a = j.T @ j
    d = np.diag(a).copy()
    d = np.where(d > 0, d, 1.0)
    step = -np.linalg.solve(a + 1e-9 * np.diag(d), j.T @ r)
    th[free] = np.clip(th[free] + step, space.lower[free], space.upper[free])
    return th


def _paired_better(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether held-out chi^2 per trajectory ``a`` [T] is clearly below ``b`` [T]: the mean
    paired difference over trajectories exceeds twice its standard error (and T >= 3)."""
    d = b - a
    if d.size < 3:
        return False
    se = float(np.std(d, ddof=1) / np.sqrt(d.size))
    return float(d.mean()) > 2.0 * se and float(d.mean()) > 0


def _rivals(rows: list[EffectRow], deltas: list[np.ndarray], held_t: list[np.ndarray]) -> None:
    """Rivals from the data: the cosine of the whitened predicted changes (each effect fitted
    with the base model, against the base fit) over this dataset's trajectories, measured for
    every pair that moves the predictions (effect size >= 2 sigma) and stored in
    ``similarity``; pairs with cosine >= ``RIGID_RIVAL_COSINE`` are rivals. Two reported rivals are
    reported together: the one with clearly better held-out evidence (paired over trajectories,
    :func:`_paired_better`) stays, the other is withdrawn (verdict ``rival``); otherwise both
    stay as an unresolved pair (verdict ``unresolved``). The separating experiment is named as
    missing from the data, since the data did not separate them (that is what the cosine says).
    """
    flat = [d.reshape(-1) for d in deltas]
    norms = [float(np.linalg.norm(f)) for f in flat]
    for i, ri in enumerate(rows):
        if ri.effect_size < 2.0 or norms[i] == 0:
            continue
        for j, rj in enumerate(rows):
            if i == j or rj.effect_size < 2.0 or norms[j] == 0:
                continue
            cos = float(flat[i] @ flat[j]) / (norms[i] * norms[j])
            ri.similarity[rj.name] = cos
            if cos >= RIGID_RIVAL_COSINE:
                ri.rivals.append(rj.name)
        if ri.rivals:
            cs = ", ".join(f"{n} (cos {ri.similarity[n]:.2f})" for n in ri.rivals)
            ri.note = (ri.note + "; " if ri.note else "") + (
                f"predicted changes nearly collinear with {cs} on this data; the experiment that "
                f"separates them is missing from it: {ri.separate_by}"
            )
    for i, ri in enumerate(rows):
        for j, rj in enumerate(rows):
            if j <= i or rj.name not in ri.rivals or not (ri.reported and rj.reported):
                continue
            if _paired_better(held_t[i + 1], held_t[j + 1]):
                win, lose = ri, rj
            elif _paired_better(held_t[j + 1], held_t[i + 1]):
                win, lose = rj, ri
            else:
                for a, b in ((ri, rj), (rj, ri)):
                    a.verdict = "unresolved"
                    a.note += f"; unresolved pair with {b.name}: neither has clearly better held-out evidence"
                continue
            lose.reported = False
            lose.verdict = "rival"
            lose.note += (
                f"; withdrawn: {win.name} has clearly better held-out error on the same "
                "trajectories (paired over trajectories)"
            )


def diagnose_recording(
    recording: object,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
    engine: Engine | None = None,
) -> DiagnoseResult:
    """Fit and rank candidate effects on a recording (see the module docstring).

    Args:
        recording: a Recording or recording-like object.
        effects: candidate names (default: every registered rigid-model effect).
        progress: called with (iteration, unfinished fits).
        dt: simulation step [s].
        engine: reuse a prepared engine.
    """
    eng = engine or Engine(recording, dt=dt)
    prep = eng.prep
    names = list(effects) if effects is not None else available_effects(model="rigid")
    present = {e.name for e, _ in eng.present}
    cands: list[Effect] = []
    skipped: list[tuple[str, str]] = []
    for n in names:
        e = get_effect(n)
        if e.model != "rigid":
            skipped.append((n, f"belongs to the {e.model!r} model"))
            continue
        if n in present:
            skipped.append((n, "already in physics.json (refitted with the base model)"))
            continue
        miss = eng.needs_missing(e)
        if miss:
            skipped.append((n, f"needs {', '.join(miss)} (not in the data)"))
            continue
        cands.append(e)
    space = eng.space(cands)
    base_cols = eng.base_columns(space)
    theta0 = eng.start(space)
    problems = [Problem(free=list(base_cols), theta0=theta0)]
    frees = [list(base_cols)]
    owner: list[int] = [0]
    for i, e in enumerate(cands, start=1):
        f = list(base_cols) + space.owner_columns(e.name)
        frees.append(f)
        for th in start_points(space, e, theta0):
            problems.append(Problem(free=f, theta0=th))
            owner.append(i)
    fitted = eng.fit(space, problems, progress=progress)
    # multi-start: keep the best start of every candidate
    outs = [
        min((o for o, k in zip(fitted, owner, strict=True) if k == i), key=lambda o: o.cost)
        for i in range(len(cands) + 1)
    ]
    base = outs[0]
    n = base.n
    mask = eng.mask
    # held-out by trajectory: one Gauss-Newton step per fold, exact rollout of all folds at once
    folds = _folds(prep.n_traj)
    thetas, locs = [], []
    for out, free in zip(outs, frees, strict=True):
        for fmask in folds:
            thetas.append(_gn_step(out, space, free, ~fmask))
            locs.append(out.local)
    held = eng.evaluate(space, np.stack(thetas), np.stack(locs))  # [P*K, T, N*4]
    k_f = len(folds)
    held_chi2, held_raw, held_t = [], [], []
    for p in range(len(outs)):
        r = np.zeros_like(outs[0].resid)
        for f, fmask in enumerate(folds):
            r[fmask] = held[p * k_f + f][fmask]
        held_t.append(np.sum(r**2, axis=-1))  # per trajectory [T]
        held_chi2.append(float(np.sum(r**2)))
        held_raw.append(eng.raw(r))
    floor = float(np.sqrt(np.mean(np.sum(prep.sig_pos.numpy()[mask] ** 2, axis=-1))) * 1000.0)
    base_raw = eng.raw(base.resid)
    rms_base = rms_mm(base_raw, mask)
    held_base = rms_mm(held_raw[0], mask)
    deltas = [(base.resid - o.resid) for o in outs[1:]]
    phase = prep.phase
    rows: list[EffectRow] = []
    for i, e in enumerate(cands, start=1):
        out, free = outs[i], frees[i]
        k_extra = len(free) - len(base_cols)
        dbic = float(n * np.log(out.cost / base.cost) + k_extra * np.log(n))
        delta = deltas[i - 1]
        z_t = np.sqrt(np.sum(delta**2, axis=-1))
        size = float(z_t.max())
        size_total = float(np.sqrt(np.sum(z_t**2)))
        # held-out gain on the trajectories the effect acts on (so that an effect seen only in
        # the drops is not diluted by the pushes); all trajectories if it moves none of them
        acts = z_t >= AFFECTED_Z
        if not acts.any():
            acts = np.ones_like(acts)
        gain = 1.0 - held_t[i][acts].sum() / max(held_t[0][acts].sum(), 1e-300)
        excess = base.cost - (n - len(base_cols))
        explained = float(np.clip((base.cost - out.cost) / excess, 0.0, 1.0)) if excess > 0 else 0.0
        red = (base.resid**2 - out.resid**2).reshape(prep.n_traj, -1, 4).sum(-1)
        red = red[:, : phase.shape[1]]  # pose samples (the force block follows them)
        total = red[mask].sum()
        phases = []
        if total > 0:
            for ph_i, ph in enumerate(PHASES):
                share = red[(phase == ph_i) & mask].sum() / total
                if share >= 0.15:
                    phases.append((share, ph))
        params = _estimates(space, out, space.owner_columns(e.name), free)
        jj = [free.index(c) for c in space.owner_columns(e.name)]
        ident = bool(out.ok[jj].all()) if len(out.ok) else True
        why = "; ".join(dict.fromkeys(out.why_param[j] for j in jj if out.why_param[j]))
        gate = dbic <= DBIC_MAX and gain > HELDOUT_MIN_GAIN and size >= EFFECT_SIZE_MIN and ident
        if not ident:
            verdict = "unidentifiable"
        elif gate:
            verdict = "add"
        elif dbic <= -6 and size >= 2.0:
            verdict = "likely"
        else:
            verdict = "not supported"
        rows.append(
            EffectRow(
                name=e.name,
                family=e.family,
                reported=bool(gate),
                verdict=verdict,
                delta_bic=dbic,
                heldout_rms_before=held_base,
                heldout_rms_after=rms_mm(held_raw[i], mask),
                heldout_gain=float(gain),
                heldout_dchi2=float(held_chi2[0] - held_chi2[i]),
                effect_size=size,
                effect_size_total=size_total,
                explained=explained,
                rms_after=rms_mm(eng.raw(out.resid), mask),
                params=params,
                phases=[p for _, p in sorted(phases, reverse=True)],
                separate_by=e.separate_by,
                note="" if ident else f"unidentifiable: {why}; to identify it: {e.separate_by}",
            )
        )
    _rivals(rows, deltas, held_t)
    rows.sort(key=lambda r: (not r.reported, r.delta_bic))
    bcols = space.owner_columns("base")
    return DiagnoseResult(
        rows=rows,
        skipped=skipped,
        base_params=_estimates(space, base, bcols, frees[0]),
        rms_base=rms_base,
        noise_floor=floor,
        noise={
            "sigma_pos_mm": prep.noise.sigma_pos * 1000,
            "sigma_z_mm": prep.noise.sigma_z * 1000,
            "sigma_yaw_deg": float(np.degrees(prep.noise.sigma_yaw)),
            "sigma_t_ms": prep.noise.sigma_t * 1000,
            "source": prep.noise.source,
        },
        n_residuals=n,
        gate={
            "delta_bic_max": DBIC_MAX,
            "heldout_min_gain": HELDOUT_MIN_GAIN,
            "effect_size_min": EFFECT_SIZE_MIN,
        },
    )

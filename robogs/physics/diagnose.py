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

The reporting gate (:mod:`robogs.physics.gate`): the held-out chi^2 fall on the trajectories
the effect acts on (``heldout_gain_sigma2``) must exceed the candidate's family-wise null
quantile, simulated on this dataset (its design, per-trajectory noise, drops, jitter and
split; the model linearised at each candidate's fit, min-P over the candidates so that on null
data any candidate passes 5 % of the time), Schwarz's criterion must prefer the effect as well
(``delta_bic < 0``; under 8 trajectories ``delta_bic <= DBIC_MAX``, below), and at least one
direction of the effect's parameters must be determined. Each row carries the quantile it was
judged against (``null_threshold_sigma2``), its own 95 % quantile and its null p-value;
``DiagnoseResult.gate`` the calibration's cost (draws, seconds, cached). The effect size is
reported, not gated.

Why ΔBIC < 0 too: the held-out null is linearised (and, at 9 trajectories, a sign-flip null with
256 patterns), and its size on design B was above its nominal 5 %: 3 of 21 null seeds passed
the held-out test alone (8.2 against 7.9, 48.1 against 47.9, 11.5 against 6.9 sigma^2), with
in-sample ΔBIC +12.8, -9.2 and +1.2 (bench/RESULTS.md, issue 17). Asking Schwarz's criterion
(Schwarz 1978, Ann. Statist. 6) to prefer the effect as well is parameter-free: an effect whose
in-sample fall of chi^2 does not pay its ``k ln n`` is not reported, whatever its held-out fall.
A row the rule blocked says so in its note. Under 8 trajectories strong in-sample evidence is
asked instead (``DBIC_MAX``): the parametric null (the default, :func:`gate_method`) leaves the
residual's other shared errors to too few trajectories, and the wild null (``both``) is white
noise only there (``gate.calibrate``).

Partial identification: a fit whose parameters are not all determined
(:mod:`robogs.physics.fit`: a 95 % interval wider than the bounds, or near-collinear parameters)
may still determine a combination of them, e.g. Stribeck's ``dmu`` and ``v_s`` on short slides,
where only about ``v_s^2 ln(1 + dmu)`` is seen.
:func:`~robogs.physics.heldout.determined_direction` takes the best-determined eigen-direction
of the effect's block of the covariance, with each parameter scaled by its prior range. When one
is determined and the gate passes, the effect is reported with verdict
``"add (partly identified)"``: the undetermined parameters are named in ``undetermined``, their
intervals are unbounded, and the note gives the determined combination and the experiment that
would separate the rest (``separate_by``). With no determined direction the verdict stays
``"unidentifiable"``. A partly identified effect must also show strong in-sample evidence,
``delta_bic <= DBIC_MAX`` (as under 8 trajectories, where the held-out null is not trusted
alone): its held-out folds step along a ridge the data do not determine, and the step is then no
longer the linear one the null simulates (on design B null seed 9 a Stribeck fit, ``dmu`` on its
lower bound in 4 of 5 folds and every fold's step halved, passed the held-out gate with 38.7
against 17.0 sigma^2 at ΔBIC -6.4; hidden Stribeck on the same design: ΔBIC -40 to -193). It
does not remove every such case (null seed 19: a partly identified Stribeck at ΔBIC -13.2, 32.9
against 15.6 sigma^2); ``diagnose_recording(partial=False)`` withholds them all. A parameter
that ends on a bound of its prior range, at the full fit or in a fold's held-out step, is named
in ``on_bound`` and in the note, as are fold steps that had to be halved.

A halved held-out step (the linearised step raised the training chi^2, so
:func:`~robogs.physics.heldout.heldout_rollouts` halved it) is outside what the null simulates
for any candidate, identified or not: such a candidate is asked ``delta_bic <= DBIC_MAX`` as
well. On design A under the parametric null, 2 of 50 null seeds reported an effect, both with a
halved step (seed 20 restitution, 17.5 against 6.5 sigma^2 at ΔBIC -8.4; seed 48 camera
extrinsics, 26.2 against 18.5 at -1.3); of 211 hidden-effect and null cases of both designs
(bench/RESULTS.md, issue 17, the lead's count after h114) the rule withdraws no true report (the
closest: design B restitution seed 16 at ΔBIC -12.3) and both of those.

Quasi-static data (:func:`quasi_static`): when no object slides more than ``QS_SAMPLES``
samples after losing contact, the dynamics-level effects (viscous, quadratic drag, Stribeck,
and restitution without drops) are not ranked: they are listed as unobservable with the reason
and the experiment that would reveal them.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from robogs.physics import gate as gate_mod
from robogs.physics import roughness as rough_mod
from robogs.physics.effects import Effect, available_effects, get_effect
from robogs.physics.engine import Engine, rms_mm
from robogs.physics.fit import FitOutcome, Problem, fit_nested, on_bounds
from robogs.physics.heldout import (
    determined_combination,
    held_mask,
    heldout_rollouts,
    holdout_folds,
    split_label,
    split_tag,
)
from robogs.physics.phases import PHASES
from robogs.physics.space import ParamSpace

__all__ = [
    "ParamEstimate",
    "EffectRow",
    "DiagnoseResult",
    "AutoStep",
    "AutoPath",
    "diagnose_recording",
    "auto_loop",
    "plot_path",
    "quasi_static",
    "rival_cutoff",
    "sign_flip_floor",
    "unjudged_on_holdout",
    "start_points",
    "judge",
    "PARTLY",
    "DBIC_MAX",
    "RIVAL_COSINE",
    "QS_SAMPLES",
    "DYNAMIC_EFFECTS",
]

DBIC_MAX = -10.0
"""ΔBIC gate of the camera-intrinsics effects (:mod:`robogs.physics.intrinsics`); the rigid
model's gate is simulated per dataset (:mod:`robogs.physics.gate`)."""
RIVAL_COSINE = 0.9
"""Cosine above which camera-intrinsics parts are rivals (:mod:`robogs.physics.intrinsics`)."""
QS_SAMPLES = 3
"""Quasi-static: no trajectory slides more than this many pose samples after losing contact."""
DYNAMIC_EFFECTS = ("viscous_damping", "quadratic_drag", "stribeck", "restitution")
"""Effects seen only in how a free object decelerates or bounces (not ranked on quasi-static
data)."""
PARTLY = "add (partly identified)"
"""Verdict of a reported effect of which only some direction of the parameters is determined."""
_REVEAL = "a push that releases the object at speed (or a release-and-slide), so it slides freely"
CARRY_Z = 0.1
"""A trajectory counts toward :func:`sign_flip_floor` when the effect moves it by more than
0.1 sigma (``z_t``); flipping one it moves less hardly changes its null statistic."""


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
    heldout_gain_sigma2: float = float("nan")
    null_threshold_sigma2: float = float("nan")
    null_q95_sigma2: float = float("nan")
    null_p: float = float("nan")
    rival_cutoff: dict[str, float] = field(default_factory=dict)
    on_bound: dict[str, str] = field(default_factory=dict)
    undetermined: list[str] = field(default_factory=list)
    """Parameters the data do not determine (interval unbounded); with a determined direction
    of them the effect may still be reported (verdict :data:`PARTLY`)."""
    blocked_by_bic: bool = False
    """The held-out gate passed but Schwarz's criterion did not prefer the effect."""
    null_factor: float = 1.0
    """The factor its null was scaled by (the gate's linearisation check on null draws,
    :func:`robogs.physics.gate.null_draw_factor`; 1 where not checked)."""
    conditional: dict[str, Any] = field(default_factory=dict)
    """Its gate given the stronger reported effects (:func:`_conditional`): ``given``, held-out
    fall and threshold (sigma^2), ``reported``; empty where not judged so."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the documented keys first)."""
        d = asdict(self)
        d["params"] = [_finite_param(p) for p in self.params]
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
            "heldout_gain_sigma2",
            "null_threshold_sigma2",
            "null_q95_sigma2",
            "null_p",
        ):
            d[k] = _finite(d[k])
        return d


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _finite_param(p: ParamEstimate) -> dict[str, Any]:
    """JSON-ready estimate: an unbounded interval end is None (JSON has no infinity)."""
    d = asdict(p)
    for k in ("value", "low", "high"):
        d[k] = _finite(d[k])
    return d


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
    gate: dict[str, Any]
    design: dict[str, Any] = field(default_factory=dict)
    present_params: dict[str, list[ParamEstimate]] = field(default_factory=dict)
    """The effects already in physics.json at their values refitted jointly with the base model on
    every trajectory (the base fit's, the same fit every candidate was scored against)."""

    @property
    def reported(self) -> list[EffectRow]:
        return [r for r in self.rows if r.reported]

    def to_dict(self) -> dict[str, Any]:
        return {
            "effects": [r.to_dict() for r in self.rows],
            "skipped": [{"name": n, "reason": why} for n, why in self.skipped],
            "base_params": [_finite_param(p) for p in self.base_params],
            "rms_base_mm": self.rms_base,
            "noise_floor_mm": self.noise_floor,
            "noise": self.noise,
            "n_residuals": self.n_residuals,
            "gate": self.gate,
            "design": self.design,
            "present_params": {
                n: [_finite_param(p) for p in ps] for n, ps in self.present_params.items()
            },
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


def judge(
    stat: float,
    threshold: float,
    q95: float,
    dbic: float,
    few: bool,
    identified: bool,
    partly: bool = False,
    halved: int = 0,
) -> tuple[str, bool, bool]:
    """A candidate's verdict from its evidence (see the module docstring).

    Args:
        stat: held-out fall on the trajectories it acts on [sigma^2].
        threshold: its family-wise null quantile [sigma^2]; ``q95`` its own 95 % one.
        dbic: in-sample ΔBIC against the base model.
        few: under 8 trajectories (white-noise null only): ``dbic <= DBIC_MAX`` is asked
            instead of ``dbic < 0``.
        identified: every parameter determined; ``partly``: at least one direction of them
            (:func:`~robogs.physics.heldout.determined_direction`); a partly identified effect
            is asked ``dbic <= DBIC_MAX`` too.
        halved: held-out folds whose step was halved
            (:func:`~robogs.physics.heldout.heldout_rollouts`); where any was,
            ``dbic <= DBIC_MAX`` is asked too: the null simulates the linear step, not the
            halved one.

    Returns:
        (verdict, reported, blocked): ``blocked`` when the held-out gate passed but ΔBIC did
        not (the verdict is then ``"likely"``).
    """
    bic_ok = dbic <= DBIC_MAX if (few or not identified or halved > 0) else dbic < 0.0
    determined = identified or partly
    held = stat > threshold
    if not determined:
        return "unidentifiable", False, False
    if held and bic_ok:
        return ("add" if identified else PARTLY), True, False
    if held:
        return "likely", False, True  # Schwarz's criterion prefers the base model
    if stat > q95:
        return "likely", False, False  # above its own 95 % null quantile, not the family-wise
    return "not supported", False, False


def start_points(space: ParamSpace, effect: Effect, theta0: np.ndarray) -> list[np.ndarray]:
    """Start vectors of one candidate: ``theta0`` (the effect off) and one per ``effect.starts``."""
    out = [theta0]
    for start in effect.starts:
        th = theta0.copy()
        for k, v in start.items():
            th[space.index(effect.name, k)] = v
        out.append(th)
    return out


def _bound_report(
    space: ParamSpace, out: FitOutcome, free: list[int], cols: list[int], folds: list[list[str]]
) -> dict[str, str]:
    """Which of the effect's parameters (indices ``cols`` into ``free``) sit on a bound of their
    prior range, at the full fit and in the held-out folds' steps (``folds``: per fold, per
    column of ``free``): name -> e.g. ``"lower (full fit); lower in 4 of 5 folds"``."""
    full = on_bounds(space, out.theta, free)
    rep: dict[str, str] = {}
    for j in cols:
        name = space.slots[free[j]].param.name
        parts = [f"{full[j]} (full fit)"] if full[j] else []
        for side in ("lower", "upper"):
            n = sum(f[j] == side for f in folds if f)
            if n:
                parts.append(f"{side} in {n} of {len(folds)} folds")
        if parts:
            rep[name] = "; ".join(parts)
    return rep


def _paired_better(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether held-out chi^2 per trajectory ``a`` [T] is clearly below ``b`` [T]: the mean
    paired difference over trajectories exceeds twice its standard error (and T >= 3)."""
    d = b - a
    if d.size < 3:
        return False
    se = float(np.std(d, ddof=1) / np.sqrt(d.size))
    return float(d.mean()) > 2.0 * se and float(d.mean()) > 0


def rival_cutoff(norm_a: float, threshold_b: float) -> float:
    """Cosine above which effect ``b`` passes the gate on the signal of effect ``a`` alone.

    Fitted to a's predicted change (whitened norm ``norm_a``, sigma units), b explains
    ``cos^2 norm_a^2`` of chi^2; it passes its gate when that exceeds its null threshold
    ``threshold_b`` [sigma^2]. So ``cos* = sqrt(threshold_b) / norm_a`` (1 when b could never
    pass on a's signal): the collinearity at which a's evidence becomes b's.
    """
    if norm_a <= 0 or not np.isfinite(threshold_b):
        return 1.0
    return float(min(1.0, np.sqrt(max(threshold_b, 1.0)) / norm_a))


def design_features(rec: Any, sigma_pos: float) -> dict[str, Any]:
    """What separating experiments the trajectories hold, measured on the object poses.

    ``opposite_directions``: two trajectories whose net object displacements (> 5 noise sigma,
    at least 5 mm) point more than 150 deg apart; ``speed_range``: the fastest and the slowest
    moving trajectories' peak speeds (over >= 60 ms windows) differ by 2x or more.
    """
    heads, speeds = [], []
    for tr in rec.trajectories:
        p = np.asarray(tr.object_pos, dtype=float)[:, :2]
        t = (np.asarray(tr.t_ns) - tr.t_ns[0]) * 1e-9
        if len(p) < 3:
            continue
        d = p[-1] - p[0]
        if np.hypot(*d) > max(5 * sigma_pos, 0.005):
            heads.append(float(np.arctan2(d[1], d[0])))
            w = max(1, int(np.searchsorted(t, t[0] + 0.06)))
            if w < len(t):
                v = np.hypot(*(p[w:] - p[:-w]).T) / np.maximum(t[w:] - t[:-w], 1e-9)
                speeds.append(float(v.max()))
    opp = [
        (i, j)
        for i in range(len(heads))
        for j in range(i + 1, len(heads))
        if abs(np.angle(np.exp(1j * (heads[i] - heads[j])))) > np.radians(150)
    ]
    spread = max(speeds) / max(min(speeds), 1e-9) if speeds else 0.0
    return {
        "opposite_directions": bool(opp),
        "speed_range": bool(spread >= 2.0),
        "peak_speed_ratio": float(spread),
        "n_moving": len(heads),
    }


def _experiment_present(separate_by: str, feats: dict[str, Any]) -> bool | None:
    """Whether the data hold the separating experiment (None: not one this module can check)."""
    text = separate_by.lower()
    if "opposite directions" in text:
        return bool(feats.get("opposite_directions"))
    if "speeds" in text:
        return bool(feats.get("speed_range"))
    return None


def _rivals(
    rows: list[EffectRow],
    deltas: list[np.ndarray],
    feats: dict[str, Any],
) -> None:
    """Rivals from the data.

    The cosine of the whitened predicted changes (each effect fitted with the base model,
    against the base fit) is measured over this dataset's trajectories for every pair and stored
    in ``similarity``. Two effects that both show evidence (held-out gain above their own 95 %
    null quantile) are rivals when either would pass its gate on the other's signal alone
    (:func:`rival_cutoff`, stored in ``rival_cutoff``).

    Two reported rivals are resolved by leakage: fitted to the signal of ``a``, ``b`` gains
    about ``cos^2 S_a`` (``S`` the held-out gain, sigma^2). When ``S_b`` is within that plus
    its null threshold and ``S_a`` is not within the converse, the data separated them: ``b``
    is withdrawn (verdict ``rival``) and both notes say by how much. When each is within the
    other's leakage the pair is unresolved (both stay, verdict ``unresolved``). The separating
    experiment is named as missing only when the data lack it (:func:`design_features`); when
    present, the note says so. A reported effect whose rival has the larger held-out gain but
    missed its own gate is not reported alone when its gain is within that rival's leakage:
    both are reported as an unresolved pair (a camera offset on five trajectories passed as a
    tilt alone: tilt 633 sigma^2 against its 511, the offset 1134 against its 1371).
    """
    flat = [d.reshape(-1) for d in deltas]
    norms = [float(np.linalg.norm(f)) for f in flat]
    shows = [r.heldout_gain_sigma2 > r.null_q95_sigma2 for r in rows]
    for i, ri in enumerate(rows):
        if norms[i] == 0:
            continue
        for j, rj in enumerate(rows):
            if i == j or norms[j] == 0:
                continue
            cos = float(flat[i] @ flat[j]) / (norms[i] * norms[j])
            ri.similarity[rj.name] = cos
            cut = min(
                rival_cutoff(norms[i], rj.null_threshold_sigma2),
                rival_cutoff(norms[j], ri.null_threshold_sigma2),
            )
            ri.rival_cutoff[rj.name] = cut
            if shows[i] and shows[j] and cos >= cut and cut < 1.0:
                ri.rivals.append(rj.name)
        if ri.rivals:
            cs = ", ".join(
                f"{n} (cos {ri.similarity[n]:.2f} >= {ri.rival_cutoff[n]:.2f})" for n in ri.rivals
            )
            has = _experiment_present(ri.separate_by, feats)
            if has is False:
                exp = f"the experiment that separates them is missing from it: {ri.separate_by}"
            elif has:
                exp = f"the data hold the experiment that separates them ({ri.separate_by})"
            else:
                exp = f"the experiment that separates them: {ri.separate_by}"
            ri.note = (ri.note + "; " if ri.note else "") + (
                f"predicted changes look alike with {cs} on this data; {exp}"
            )
    pairs = [
        (i, j)
        for i in range(len(rows))
        for j in range(len(rows))
        if rows[j].name in rows[i].rivals
        and rows[i].heldout_gain_sigma2 >= rows[j].heldout_gain_sigma2
        and i != j
    ]
    pairs.sort(key=lambda ij: -rows[ij[0]].heldout_gain_sigma2)
    for i, j in pairs:
        a, b = rows[i], rows[j]
        c2 = a.similarity[b.name] ** 2
        leak_b = c2 * a.heldout_gain_sigma2 + b.null_threshold_sigma2
        leak_a = c2 * b.heldout_gain_sigma2 + a.null_threshold_sigma2
        if b.reported and not a.reported and b.heldout_gain_sigma2 <= leak_b:
            # b passes its gate on what may be a's signal, a (the stronger evidence) not its
            # own: never b alone, the pair is reported together (a pair needs b to pass, so
            # the family-wise rate on null data is unchanged)
            a.reported = True
            for x, y in ((a, b), (b, a)):
                x.verdict = "unresolved"
                x.note += (
                    f"; unresolved pair with {y.name}: {b.name} passes its gate, but its "
                    f"held-out gain {b.heldout_gain_sigma2:.1f} sigma^2 is no more than "
                    f"{a.name}'s stronger signal ({a.heldout_gain_sigma2:.1f}) gives it "
                    f"({leak_b:.1f}), so both are reported"
                )
            continue
        if not (a.reported and b.reported):
            continue
        if b.heldout_gain_sigma2 <= leak_b and a.heldout_gain_sigma2 > leak_a:
            what = (
                f"separated by this data: {b.name}'s held-out gain {b.heldout_gain_sigma2:.1f} "
                f"sigma^2 is no more than {a.name}'s signal gives it ({leak_b:.1f}), while "
                f"{a.name}'s {a.heldout_gain_sigma2:.1f} exceeds what {b.name} explains "
                f"({leak_a:.1f})"
            )
            b.reported, b.verdict = False, "rival"
            b.note += f"; withdrawn: {a.name} has clearly better held-out evidence ({what})"
            a.note += f"; {what}"
        elif b.heldout_gain_sigma2 <= leak_b:
            for x, y in ((a, b), (b, a)):
                x.verdict = "unresolved"
                x.note += (
                    f"; unresolved pair with {y.name}: each one's held-out evidence is what the "
                    "other's signal would give it"
                )


def _conditional(
    rows: list[EffectRow],
    recording: Any,
    eng: Engine,
    *,
    partial: bool,
    holdout: Sequence[str] | None,
) -> None:
    """Second and later reports judged given the stronger ones (parametric null only).

    Each candidate's gate is marginal: base + effect against base. A strong effect's signal
    then leaks into a weaker, partly similar one, whose small parametric threshold (tens of
    sigma^2) it passes although the data hold nothing of it beyond the strong effect: a
    hidden table tilt (design A, seeds 3-9) reported Stribeck friction in 6 of 7 cases at
    15-80x its threshold. They are rivals there (seed 3: cosine 0.54 against a cutoff of
    0.10), but the projected leakage ``cos^2 S_tilt`` undercounts what a Stribeck fit takes
    from the tilt's signal (1117 sigma^2 against its 1417), so :func:`_rivals` kept it; given
    the tilt, its held-out fall is 12.3 sigma^2 against a threshold of 18.7 (Delta BIC +16).
    Here the reported rows, strongest first (lowest Delta BIC, as the
    report orders them), are judged as forward selection would (Efroymson 1960;
    :func:`auto_loop`): the stronger accepted effects go into the base at their fitted values
    (refitted with it), the candidate is diagnosed alone on that base with a fresh null for
    that base, and it stays reported only where it passes that conditional gate. The one
    reported first is never touched, so the family-wise rate on null data can only fall.
    Cost: one extra :func:`diagnose_recording` (one candidate, its own calibration) per report
    beyond the first; none where fewer than two are reported. A row that :func:`_rivals` left
    ``unresolved`` with a stronger kept one is not withdrawn (its conditional numbers are still
    recorded): there the data cannot tell which of the two it is, and withdrawing the weaker by
    Delta BIC would pick one (design B viscous s2, truth viscous: drag first by 1.7, viscous
    given drag -4.9 against 1.8 sigma^2; withdrawn, the report named drag alone).
    """
    import copy

    rep = sorted((r for r in rows if r.reported), key=lambda r: r.delta_bic)
    given: list[EffectRow] = rep[:1]
    for r in rep[1:]:
        doc = copy.deepcopy(recording.physics)
        doc.setdefault("effects", []).extend(
            {"name": g.name, "params": {p.name: p.value for p in g.params}} for g in given
        )
        rec = copy.copy(recording)
        rec.physics = doc
        sub = Engine(rec, dt=eng.prep.scene.dt, backend=eng.backend)
        res = diagnose_recording(
            rec, effects=[r.name], engine=sub, partial=partial, holdout=holdout
        )
        c = next((x for x in res.rows if x.name == r.name), None)
        names = [g.name for g in given]
        r.conditional = {
            "given": names,
            "heldout_gain_sigma2": _finite(c.heldout_gain_sigma2) if c else None,
            "null_threshold_sigma2": _finite(c.null_threshold_sigma2) if c else None,
            "delta_bic": _finite(c.delta_bic) if c else None,
            "reported": bool(c and c.reported),
        }
        what = (
            f"given {', '.join(names)}: held-out fall {c.heldout_gain_sigma2:.1f} sigma^2 "
            f"against its threshold {c.null_threshold_sigma2:.1f}"
            if c
            else f"given {', '.join(names)}: not fitted"
        )
        if c is not None and c.reported:
            given.append(r)
            r.note = (r.note + "; " if r.note else "") + f"passes its gate {what}"
            continue
        pair = [n for n in r.rivals if n in names] if r.verdict == "unresolved" else []
        if pair:  # h101: design B viscous s2 (truth viscous) had drag first by 1.7 in Delta BIC
            r.note = (r.note + "; " if r.note else "") + (
                f"not withdrawn although it fails its gate {what}: it and {', '.join(pair)} are "
                "an unresolved pair (the data cannot tell which), so both stay reported"
            )
            continue
        r.reported, r.verdict = False, "conditional"
        r.note = (r.note + "; " if r.note else "") + (
            f"withdrawn: its evidence is the stronger effects' signal ({what})"
        )


def quasi_static(prep: Any) -> tuple[bool, int]:
    """Whether the objects stop within ``QS_SAMPLES`` samples of losing contact.

    Returns (quasi-static, longest run of ``sliding`` or ``free`` samples that follows a
    ``contact`` or ``grasp`` sample, over all trajectories).
    """
    slide = (PHASES.index("sliding"), PHASES.index("free"))
    touch = (PHASES.index("contact"), PHASES.index("grasp"))
    best = 0
    for lab in np.asarray(prep.phase):
        run, after = 0, False
        for v in lab:
            if v in touch:
                run, after = 0, True
            elif v in slide and after:
                run += 1
                best = max(best, run)
            else:
                run, after = 0, False
    return best <= QS_SAMPLES, best


def diagnose_recording(
    recording: object,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
    engine: Engine | None = None,
    partial: bool = True,
    holdout: Sequence[str] | None = None,
) -> DiagnoseResult:
    """Fit and rank candidate effects on a recording (see the module docstring).

    Args:
        recording: a Recording or recording-like object.
        effects: candidate names (default: every registered rigid-model effect).
        progress: called with (iteration, unfinished fits).
        dt: simulation step [s].
        engine: reuse a prepared engine.
        partial: report partly identified effects (False: only fully identified ones pass).
        holdout: trajectories (or split episodes) held out as one fold instead of the default
            folds (:func:`~robogs.physics.heldout.holdout_folds`); the held-out errors, the
            gate's statistic and its simulated null all use that fold, and
            ``DiagnoseResult.design["split"]`` says which.

    Raises:
        InputError: a bad ``holdout`` (:func:`~robogs.physics.heldout.holdout_folds`), or one
            too small for the gate (:func:`unjudged_on_holdout`).
    """
    eng = engine or Engine(recording, dt=dt)
    prep = eng.prep
    names = list(effects) if effects is not None else available_effects(model="rigid")
    traj_names = [t.name for t in prep.rec.trajectories]
    folds = holdout_folds(traj_names, holdout)  # checked before any fit
    present = {e.name for e, _ in eng.present}
    qs, slide_run = quasi_static(prep)
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
        if (
            qs
            and n in DYNAMIC_EFFECTS
            and (n != "restitution" or "impact" not in eng.prep.excitation)
        ):
            skipped.append(
                (
                    n,
                    f"unobservable: quasi-static data (objects stop within {slide_run} sample(s) "
                    f"of losing contact, so how they decelerate or bounce is never seen); "
                    f"the experiment that would reveal it: {_REVEAL}",
                )
            )
            continue
        miss = eng.needs_missing(e)
        if miss:
            skipped.append((n, f"needs {', '.join(miss)} (not in the data)"))
            continue
        cands.append(e)
    space = eng.space(cands)
    base_cols = eng.base_columns(space)
    theta0 = eng.start(space)
    frees = [list(base_cols)] + [list(base_cols) + space.owner_columns(e.name) for e in cands]
    # each candidate fitted from the base optimum, multi-start; the base refitted when a
    # candidate switched back to it beats it (fit.fit_nested): a gain is never the optimiser's.
    # The base fit is the shared "before" (baseline, memoised; its space is this one's prefix)
    from robogs.physics.baseline import baseline

    known = baseline(prep.rec, dt=prep.drive.dt, engine=eng).outcome
    th_known = theta0.copy()
    th_known[: len(known.theta)] = known.theta
    base_out, cand_outs = fit_nested(
        lambda probs: eng.fit(space, probs, progress=progress),
        lambda th, lo: eng.evaluate(space, th, lo),
        space,
        Problem(free=list(base_cols), theta0=theta0),
        [(space.owner_columns(e.name), start_points(space, e, theta0)) for e in cands],
        base_fit=replace(known, theta=th_known),
    )
    outs = [base_out, *cand_outs]
    base = outs[0]
    n = base.n
    mask = eng.mask
    # held-out by trajectory: one bounded Gauss-Newton step per fold (halved where it fails on
    # the training trajectories), exact rollouts of all folds at once
    held, fold_bounds, halved = heldout_rollouts(eng, space, outs, frees, folds)
    held_m = mask & held_mask(folds, prep.n_traj)[:, None]  # RMS over held-out samples only
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
    held_base = rms_mm(held_raw[0], held_m)
    deltas = [(base.resid - o.resid) for o in outs[1:]]
    stats = [
        float(gate_mod.heldout_statistic(held_t[0], held_t[i], deltas[i - 1]))
        for i in range(1, len(outs))
    ]
    dbics = [
        float(n * np.log(o.cost / base.cost) + (len(f) - len(base_cols)) * np.log(n))
        for o, f in zip(outs[1:], frees[1:], strict=True)
    ]
    if holdout:  # refused before the null is simulated
        _check_holdout(space, cands, outs[1:], frees[1:], deltas, held_mask(folds, prep.n_traj))
    nuis_rec: dict[str, Any] = {}  # h48: the gate's start-pose columns (roughness module)
    cal = _calibrate(
        eng, space, cands, outs, folds, base_cols, theta0, stats, dbics, record=nuis_rec
    )
    phase = prep.phase
    rows: list[EffectRow] = []
    for i, e in enumerate(cands, start=1):
        out, free = outs[i], frees[i]
        dbic = dbics[i - 1]
        delta = deltas[i - 1]
        z_t = np.sqrt(np.sum(delta**2, axis=-1))
        size = float(z_t.max())
        size_total = float(np.sqrt(np.sum(z_t**2)))
        # held-out gain on the trajectories the effect acts on (so that an effect seen only in
        # the drops is not diluted by the pushes); all trajectories if it moves none of them
        acts = z_t >= gate_mod.AFFECTED_Z
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
        bound = _bound_report(space, out, free, jj, fold_bounds[i])
        ident = bool(out.ok[jj].all()) if len(out.ok) else True
        why = "; ".join(dict.fromkeys(out.why_param[j] for j in jj if out.why_param[j]))
        undetermined = [space.slots[free[j]].param.name for j in jj if not ident and not out.ok[j]]
        part = None if ident else determined_combination(space, out, free, jj)
        stat = stats[i - 1]
        # thresholds in sigma^2 on this data (under 8 trajectories those of the studentised
        # held-out fall times its standard error, gate.Calibration.judge)
        thr, q95, p_own = cal.judge(e.name, held_t[0], held_t[i], delta)
        # under 8 trajectories the wild null ("both") is white noise only (gate.calibrate):
        # strong in-sample evidence is required as well; so it is under the parametric null
        # (the default), whose drive model leaves the residual's other shared errors to so
        # few trajectories (a 4-push null reported Stribeck at dBIC -2.3 without it, test_split)
        few = "white-noise null only" in cal.method or (
            "parametric" in cal.method and gate_mod.few_trajectories(prep.n_traj)
        )
        verdict, gate, blocked = judge(
            stat, thr, q95, dbic, few, ident, partial and part is not None, int(halved[i])
        )
        in_only = ""  # h94, opt-in: passes on the in-sample statistic alone, where the folds
        # cannot test it (z_t >= AFFECTED_Z on under 2 trajectories: a fold that holds its one
        # carrier out hardly determines it); an extra condition, so the min-P level still holds
        n_carry = int(np.sum(z_t >= gate_mod.AFFECTED_Z))
        if not gate and n_carry < 2 and e.name in cal.insample and e.name in cal.insample_data:
            s_in = cal.insample_data[e.name]
            t_in, q_in, _ = cal.judge_insample(e.name, s_in)
            v_in, g_in, _ = judge(
                s_in, t_in, q_in, dbic, few, ident, partial and part is not None, int(halved[i])
            )
            if g_in:
                verdict, gate, blocked = v_in, True, False
                carriers = [traj_names[t] for t in np.flatnonzero(z_t >= gate_mod.AFFECTED_Z)]
                who = (
                    f"carried by trajectory {carriers[0]} alone"
                    if carriers
                    else f"it moves no trajectory by {gate_mod.AFFECTED_Z:g} sigma"
                )
                in_only = (
                    f"in-sample evidence only: its in-sample fall {s_in:.1f} sigma^2 passes its "
                    f"family-wise threshold {t_in:.1f}, its held-out fall {stat:.1f} does not "
                    f"({thr:.1f}); {who}; held-out confirmation needs another trajectory that "
                    f"excites it: {e.separate_by}"
                )
        if ident:
            note = ""
        elif part is None or not partial:
            note = f"unidentifiable: {why}; to identify it: {e.separate_by}"
        else:
            note = (
                f"partly identified: {', '.join(undetermined)} not determined ({why}); "
                f"{part}; to determine {', '.join(undetermined)}: {e.separate_by}"
            )
        if in_only:
            note = (note + "; " if note else "") + in_only
        if blocked:
            bar = f"ΔBIC <= {DBIC_MAX:g}" if (few or not ident or halved[i]) else "ΔBIC < 0"
            if halved[i] and not (few or not ident):
                bar += (
                    f" (its held-out step was halved in {halved[i]} of {len(folds)} folds, and "
                    "the null simulates the linear step)"
                )
            note = (note + "; " if note else "") + (
                f"not reported: its held-out fall {stat:.1f} sigma^2 passes its family-wise "
                f"threshold {thr:.1f}, but ΔBIC is {dbic:+.1f}, and the gate asks {bar} as well "
                "(Schwarz's criterion must prefer the effect)"
            )
        rows.append(
            EffectRow(
                name=e.name,
                family=e.family,
                reported=bool(gate),
                verdict=verdict,
                delta_bic=dbic,
                heldout_rms_before=held_base,
                heldout_rms_after=rms_mm(held_raw[i], held_m),
                heldout_gain=float(gain),
                heldout_dchi2=float(held_chi2[0] - held_chi2[i]),
                effect_size=size,
                effect_size_total=size_total,
                explained=explained,
                rms_after=rms_mm(eng.raw(out.resid), mask),
                params=params,
                phases=[p for _, p in sorted(phases, reverse=True)],
                separate_by=e.separate_by,
                note=note,
                heldout_gain_sigma2=stat,
                null_threshold_sigma2=thr,
                null_q95_sigma2=q95,
                null_p=p_own,
                on_bound=bound,
                undetermined=undetermined,
                blocked_by_bic=blocked,
                null_factor=cal.inflation.get(e.name, 1.0),
            )
        )
        chk = cal.checks.get(e.name) if e.name in cal.inflation else None
        if chk is not None and chk.factor > 1.0:
            rows[-1].note = (rows[-1].note + "; " if rows[-1].note else "") + (
                f"null threshold scaled x{chk.factor:.2f} ({thr / chk.factor:.1f} -> {thr:.1f} "
                f"sigma^2): on {len(chk.ratios)} draws (its fitted change scaled "
                f"x{chk.scale:.2f} to the threshold's size, on the data's own residual) its "
                "fit gained more than its linear model by up to that ratio (on the data: "
                f"{chk.data_ratio:.2f}; the gate's linearisation check)"
            )
        if bound:
            rows[-1].note = (
                (rows[-1].note + "; " if rows[-1].note else "")
                + "on a bound: "
                + (", ".join(f"{k} {v}" for k, v in bound.items()))
            )
        if halved[i]:
            rows[-1].note = (rows[-1].note + "; " if rows[-1].note else "") + (
                f"held-out step halved in {halved[i]} of {len(folds)} folds (the linearised step "
                "raised the training chi^2)"
            )
        carrying = int(np.sum(z_t > CARRY_Z))
        p_floor = sign_flip_floor(cal.method, carrying)
        # said where it explains a miss: evidence above its own 95 % quantile, not the gate's
        if verdict == "likely" and p_floor is not None and p_floor > cal.alpha_adj:
            rows[-1].note = (rows[-1].note + "; " if rows[-1].note else "") + (
                f"it moves only {carrying} of {prep.n_traj} trajectories: flipping the sign of "
                "one it does not move leaves its null statistic (nearly) unchanged, so its "
                f"linearised null p-value cannot fall much below {p_floor:.4f}, above the "
                f"family-wise level {cal.alpha_adj:.4f}; it passes only where its real held-out "
                "fall exceeds its linearisation. More trajectories of the kinds it acts on "
                "would let it pass"
            )
    feats = design_features(prep.rec, float(prep.noise.sigma_pos))
    _rivals(rows, deltas, feats)
    if "parametric" in cal.method and sum(r.reported for r in rows) >= 2:
        _conditional(rows, recording, eng, partial=partial, holdout=holdout)
    rows.sort(key=lambda r: (not r.reported, r.delta_bic))
    bcols = space.owner_columns("base")
    return DiagnoseResult(
        rows=rows,
        skipped=skipped,
        base_params=_estimates(space, base, bcols, frees[0]),
        present_params={
            e.name: _estimates(space, base, space.owner_columns(e.name), frees[0])
            for e, _ in eng.present
        },
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
        gate={**cal.to_dict(), **({"nuisance_columns": nuis_rec} if nuis_rec else {})},
        design={
            **feats,
            "quasi_static": qs,
            "longest_free_slide_samples": slide_run,
            "n_trajectories": prep.n_traj,
            "split": split_label(traj_names, folds),
            "holdout": [n for n, m in zip(traj_names, folds[0], strict=True) if m]
            if holdout
            else None,
        },
    )


def unjudged_on_holdout(z_t: np.ndarray, held: np.ndarray) -> tuple[int, float] | None:
    """Whether a held-out choice leaves a candidate's gate unable to pass: (how many
    trajectories it acts on, its largest ``z_t``) when it acts on some (``z_t >=
    gate.AFFECTED_Z``, the gate's rule) and on none of the ``held`` [T] ones, else None.

    The gate's statistic sums the held-out chi^2 fall over the trajectories an effect acts on
    (:func:`robogs.physics.gate.heldout_statistic`), and a trajectory no fold holds out adds 0:
    such an effect's statistic is exactly 0 on the data, whatever its size, while its null is
    simulated as usual, so it is never reported (a gate that looks calibrated and cannot pass).
    The default folds hold out every trajectory once, so this never happens there.
    """
    acts = np.asarray(z_t) >= gate_mod.AFFECTED_Z
    if not acts.any() or (acts & np.asarray(held, dtype=bool)).any():
        return None
    return int(acts.sum()), float(np.max(z_t))


def _check_holdout(
    space: ParamSpace,
    cands: list[Effect],
    outs: list[FitOutcome],
    frees: list[list[int]],
    deltas: list[np.ndarray],
    held: np.ndarray,
) -> None:
    """Refuse a held-out choice on which a candidate the data determine (every parameter, or
    a direction of them) cannot pass the gate (:func:`unjudged_on_holdout`)."""
    from robogs.format.errors import InputError

    bad = []
    for e, out, free, delta in zip(cands, outs, frees, deltas, strict=True):
        miss = unjudged_on_holdout(np.sqrt(np.sum(delta**2, axis=-1)), held)
        if miss is None:
            continue
        jj = [free.index(c) for c in space.owner_columns(e.name)]
        ident = bool(out.ok[jj].all()) if len(out.ok) else True
        if not ident and determined_combination(space, out, free, jj) is None:
            continue  # nothing of it determined: never reported, whatever the split
        bad.append(
            f"{e.name} moves {miss[0]} trajectories by >= {gate_mod.AFFECTED_Z:g} sigma (up to "
            f"{miss[1]:.1f}), none of them held out"
        )
    if bad:
        raise InputError(
            "the held-out set is too small for the gate: "
            + "; ".join(bad)
            + ". The gate's statistic is the held-out fall on the held-out trajectories an effect "
            "acts on: with none of them held out it is 0 by construction, and the effect could "
            "never pass",
            where="--holdout",
            hint="hold out trajectories these effects act on (e.g. a drop for restitution), "
            "leave them out with --effects, or use the default folds",
        )


def sign_flip_floor(method: str, carrying: int) -> float | None:
    """Smallest null p-value a sign-per-trajectory (Rademacher) wild null can give an effect
    that ``carrying`` trajectories carry: ``2^-(carrying-1)``, since flipping a trajectory it
    does not act on leaves its statistic unchanged and ``w``, ``-w`` give the same one (an exact
    randomisation test's resolution). None when the calibration's ``method`` is not that null
    (white noise only, or Webb's six-point weights)."""
    if not method.startswith(("both", "wild")) or "Webb" in method or "white-noise" in method:
        return None
    return 2.0 ** -(max(carrying, 1) - 1)


GATE_METHOD_ENV = "ROBOGS_GATE_METHOD"
"""Environment variable that picks the gate's null (:data:`robogs.physics.gate.METHODS`;
unset: ``"parametric"``, h76, the default since 2026-11-28), which simulates the drive's own
measurement error (:func:`robogs.physics.drive_noise.drive_inputs`). ``both`` is the earlier
default: the base residual sign-flipped per trajectory and white noise, the larger of the two
(it cannot pass an effect that few trajectories carry: :func:`sign_flip_floor`)."""


PARAMETRIC_DRAWS = 1000
"""Draws of the parametric null (a continuous null: its 1 - 0.0075 quantile is then the 8th
largest draw, where 400 give the 3rd)."""


def gate_method() -> str:
    """The gate's null construction: ``$ROBOGS_GATE_METHOD`` or ``"parametric"``.

    Raises:
        InputError: an unknown method (names the variable and the choices)."""
    from robogs.format.errors import InputError

    m = os.environ.get(GATE_METHOD_ENV, "").strip() or "parametric"
    if m not in gate_mod.METHODS:
        raise InputError(
            f"unknown gate method {m!r}",
            where=f"${GATE_METHOD_ENV}",
            hint=f"use one of {', '.join(gate_mod.METHODS)}, or unset it for the default",
        )
    return m


GATE_INSAMPLE_ENV = "ROBOGS_GATE_INSAMPLE"
"""Environment variable (``1``: on; opt-in, h94) that adds the in-sample statistic to the
parametric null's min-P (:func:`robogs.physics.gate.calibrate`'s ``insample``): a candidate
the held-out folds cannot test (``z_t >= AFFECTED_Z`` on under 2 trajectories) may pass on its
in-sample fall (ΔBIC < 0 still asked), and its note says so. The carrier rule is applied to
the data only, on top of a min-P over every candidate's two statistics: it can only withdraw
passes, so the family-wise level stays at most ``alpha`` (design-B null seed 14 without it: a
viscous damping that two trajectories carry passed in-sample, 53.3 against 50.7 sigma^2, at a
held-out fall of -86.7)."""


def gate_insample(method: str) -> bool:
    """Whether ``$ROBOGS_GATE_INSAMPLE`` asks for the in-sample statistic (``1``, ``true``,
    ``yes``; unset, empty, ``0``: no).

    Raises:
        InputError: set with a gate ``method`` other than ``"parametric"``, or an unknown
            value."""
    from robogs.format.errors import InputError

    v = os.environ.get(GATE_INSAMPLE_ENV, "").strip().lower()
    if v in ("", "0", "false", "no"):
        return False
    if v not in ("1", "true", "yes"):
        raise InputError(
            f"unknown value {v!r}", where=f"${GATE_INSAMPLE_ENV}", hint="use 1 or 0 (or unset it)"
        )
    if method != "parametric":
        raise InputError(
            f"the in-sample statistic needs the parametric null, not {method!r}",
            where=f"${GATE_INSAMPLE_ENV}",
            hint=f"set ${GATE_METHOD_ENV}=parametric as well, or unset ${GATE_INSAMPLE_ENV}",
        )
    return True


def _calibrate(
    eng: Engine,
    space: ParamSpace,
    cands: list[Effect],
    outs: list[FitOutcome],
    folds: list[np.ndarray],
    base_cols: list[int],
    theta0: np.ndarray,
    stats: list[float],
    dbics: list[float],
    record: dict[str, Any] | None = None,
) -> gate_mod.Calibration:
    """The gate's null for these candidates on this data (cached per revision; see gate), with
    the linearisation check on null draws of the candidates where it can change a verdict
    (``stats``: their held-out falls [sigma^2]; :func:`gate.needs_check`).

    With :data:`roughness.SMOOTH_NUISANCE`, and always under the parametric null
    (:func:`roughness.smooth_for`, h99), every linearised candidate (the base, the null
    draws' fits) takes its start-pose columns from :func:`roughness.smooth_nuisance` (one
    rollout each) instead of the fitter's 0.1 mm forward differences, and ``record`` (when
    given) gets the stencils chosen and the fitter's roughness per candidate."""
    import time

    import torch

    from robogs.physics.baseline import _fingerprint, model_key

    rec = eng.prep.rec
    fp = "|".join(
        [_fingerprint(rec), model_key(rec.physics), f"{eng.prep.scene.dt:g}", eng.backend]
    )  # the backend, not the class: planar and MuJoCo are both an Engine
    fp += split_tag(folds)  # a --holdout split's null is its own (never the default folds')
    base = outs[0]
    n_base = len(base_cols)
    valid = (base.resid != 0) | np.any(base.jac != 0, axis=-1)
    fn = eng.residual_fn(space)
    method = gate_method()
    smooth = rough_mod.smooth_for(method)
    data_key = fp  # the drive-error draws model the data, not how the gate makes its columns
    fp += "|smooth-nuisance" if smooth else ""

    def nuisance(o: FitOutcome, resid: np.ndarray, name: str = "", f=fn) -> np.ndarray:
        """The start-pose columns the gate profiles out for fit ``o`` (h48)."""
        if not smooth:
            return o.jac_local
        cols, rc = rough_mod.smooth_nuisance(f, o.theta, o.local, o.jac_local, resid, valid)
        if name and record is not None:
            record[name] = rc.to_dict()
        return cols

    lin = [
        gate_mod.LinearCandidate(e.name, o.jac, nuisance(o, base.resid, e.name), n_base)
        for e, o in zip(cands, outs[1:], strict=True)
    ]
    insample = gate_insample(method)  # h94, opt-in (False unless $ROBOGS_GATE_INSAMPLE is set)
    if method == "both":  # the wild null, called exactly as before it stopped being the default
        cal = gate_mod.calibrate(lin, base.resid, valid, folds, fingerprint=fp)
    else:
        inputs = None
        if method == "parametric":
            from robogs.physics.drive_noise import drive_inputs

            inputs = drive_inputs(eng, space, base, valid, data_key)
        draws = PARAMETRIC_DRAWS if method == "parametric" else gate_mod.N_DRAWS
        cal = gate_mod.calibrate(
            lin,
            base.resid,
            valid,
            folds,
            fingerprint=fp,
            method=method,
            inputs=inputs,
            draws=draws,
            **({"insample": True} if insample else {}),
        )
        if insample:  # the data's in-sample statistics, judged in diagnose_recording
            for e, lc, out in zip(cands, lin, outs[1:], strict=True):
                g = base.cost - out.cost
                cal.insample_data[e.name] = gate_mod.insample_statistic(lc, base.resid, valid, g)
                cal.insample_parts[e.name] = (g, gate_mod.linear_gain(lc, base.resid, valid))
    if cal.statistic != "fall":
        return cal
    signs = gate_mod.check_signs(eng.prep.n_traj, fp)

    made = False
    for e, lc, out, stat, dbic in zip(cands, lin, outs[1:], stats, dbics, strict=True):
        k = len(space.owner_columns(e.name))
        ratio = gate_mod.linear_ratio(
            base.cost - out.cost, gate_mod.linear_gain(lc, base.resid, valid), k
        )
        if not gate_mod.needs_check(stat, cal.thresholds[e.name], ratio, dbic):
            continue
        chk = cal.checks.get(e.name)
        if chk is None:
            count = [0]

            def fit_draw(
                offset: np.ndarray,
                e: Effect = e,
                count: list[int] = count,
            ):
                off = torch.as_tensor(offset)
                starts = start_points(space, e, theta0)

                def fn_d(th: torch.Tensor, lo: torch.Tensor) -> torch.Tensor:
                    count[0] += 1
                    return fn(th, lo) + off

                def evaluate(th: np.ndarray, lo: np.ndarray) -> np.ndarray:
                    with torch.no_grad():
                        return fn_d(torch.as_tensor(th), torch.as_tensor(lo)).numpy()

                b, (c,) = fit_nested(
                    lambda probs: eng.fit(space, probs, residual=fn_d),
                    evaluate,
                    space,
                    Problem(free=list(base_cols), theta0=base.theta, local0=base.local),
                    [(space.owner_columns(e.name), starts)],
                )
                lc_d = gate_mod.LinearCandidate(e.name, c.jac, nuisance(c, b.resid, f=fn_d), n_base)
                return b.cost, c.cost, lc_d, b.resid

            t0 = time.perf_counter()
            lam = gate_mod.draw_scale(base.cost - out.cost, cal.thresholds[e.name])
            chk = gate_mod.null_draw_factor(
                base.resid, out.resid, valid, fit_draw, signs, lam, ratio
            )
            chk.rollouts, chk.seconds = count[0], time.perf_counter() - t0
            made = True
        cal.apply_check(e.name, chk)
    if made:
        gate_mod.store_checks(cal)
    return cal


@dataclass
class AutoStep:
    """One step of the selection loop: the effect accepted (None: the loop stopped here)."""

    step: int
    effect: str | None
    given: list[str]
    heldout_rms_before: float
    heldout_rms_after: float
    delta_bic: float
    heldout_gain_sigma2: float
    null_threshold_sigma2: float
    verdict: str
    params: list[ParamEstimate] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in (
            "heldout_rms_before",
            "heldout_rms_after",
            "delta_bic",
            "heldout_gain_sigma2",
            "null_threshold_sigma2",
        ):
            d[k] = _finite(d[k])
        d["params"] = [_finite_param(p) for p in self.params]
        return d


@dataclass
class AutoPath:
    """The selection loop's path and its last diagnosis (judged given every accepted effect)."""

    steps: list[AutoStep]
    last: DiagnoseResult
    physics: dict[str, Any]
    stopped: str
    calibration_seconds: float

    @property
    def accepted(self) -> list[str]:
        return [
            s.effect for s in self.steps if s.effect is not None and s.verdict.startswith("added")
        ]

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": [s.to_dict() for s in self.steps],
            "accepted": self.accepted,
            "stopped": self.stopped,
            "calibration_seconds": self.calibration_seconds,
            "model": {
                n: [_finite_param(p) for p in ps] for n, ps in self.last.present_params.items()
            },
            "last": self.last.to_dict(),
        }


def auto_loop(
    recording: Any,
    *,
    effects: Sequence[str] | None = None,
    max_steps: int = 5,
    dt: float = 1e-3,
    progress: Callable[[int, int], None] | None = None,
    holdout: Sequence[str] | None = None,
    engine: str = "planar",
) -> AutoPath:
    """Forward selection to its end (Efroymson 1960): diagnose, accept the reported effect with
    the lowest ΔBIC into the base model (stored at its fitted values, refitted jointly with the
    base at the next step), repeat until no candidate passes the gate or ``max_steps``. An
    effect that a stronger unmodelled one masks is judged again once that one is in the base
    (a table tilt beside viscous damping: bench/RESULTS.md, issue 17).

    Each step's gate is calibrated afresh on its own base model (the accepted effects included),
    for the split ``holdout`` gives (:func:`diagnose_recording`), with rollouts on the
    ``engine`` backend (``planar``, ``mujoco`` or ``auto``; :class:`robogs.physics.engine.Engine`).
    Nothing is written: ``AutoPath.physics`` is the document with the accepted effects at their
    values of the last step's joint refit (``AutoPath.last.present_params``), not at the values
    each had when it was accepted.
    """
    import copy

    rec = copy.copy(recording)
    doc = copy.deepcopy(rec.physics)
    rec.physics = doc
    steps: list[AutoStep] = []
    cal_s = 0.0
    given: list[str] = [str(e.get("name")) for e in doc.get("effects", []) or []]
    while True:
        eng = Engine(rec, dt=dt, backend=engine)  # afresh: the document changes each step
        res = diagnose_recording(
            rec, effects=effects, dt=dt, progress=progress, holdout=holdout, engine=eng
        )
        for entry in doc.get("effects", []) or []:  # the joint refit replaces each step's value
            joint = res.present_params.get(str(entry.get("name")))
            if joint:
                entry["params"] = {p.name: p.value for p in joint}
        cal_s += float(res.gate.get("seconds", 0.0))
        cal_s += float((res.gate.get("linearisation_check") or {}).get("seconds", 0.0))
        top = next((r for r in res.rows if r.reported), None)
        if top is None or len(steps) >= max_steps:
            best = max(
                res.rows,
                key=lambda r: r.heldout_gain_sigma2 - r.null_threshold_sigma2,
                default=None,
            )
            why = (
                "no candidate passes the gate on held-out trajectories"
                if top is None
                else f"step limit {max_steps} reached"
            )
            steps.append(
                AutoStep(
                    step=len(steps) + 1,
                    effect=None if best is None else best.name,
                    given=list(given),
                    heldout_rms_before=best.heldout_rms_before if best else res.rms_base,
                    heldout_rms_after=best.heldout_rms_after if best else res.rms_base,
                    delta_bic=best.delta_bic if best else float("nan"),
                    heldout_gain_sigma2=best.heldout_gain_sigma2 if best else float("nan"),
                    null_threshold_sigma2=best.null_threshold_sigma2 if best else float("nan"),
                    verdict="stop: " + why,
                )
            )
            return AutoPath(steps, res, doc, why, cal_s)
        unresolved = [r.name for r in res.rows if r.verdict == "unresolved" and r is not top]
        steps.append(
            AutoStep(
                step=len(steps) + 1,
                effect=top.name,
                given=list(given),
                heldout_rms_before=top.heldout_rms_before,
                heldout_rms_after=top.heldout_rms_after,
                delta_bic=top.delta_bic,
                heldout_gain_sigma2=top.heldout_gain_sigma2,
                null_threshold_sigma2=top.null_threshold_sigma2,
                verdict="added"
                + (
                    f" (partly identified: {', '.join(top.undetermined)} not determined)"
                    if top.undetermined
                    else ""
                )
                + (f" (unresolved with {', '.join(unresolved)})" if unresolved else ""),
                params=top.params,
            )
        )
        entry = {"name": top.name, "params": {p.name: p.value for p in top.params}}
        doc.setdefault("effects", []).append(entry)
        given.append(top.name)


def path_rms(path: AutoPath) -> list[float]:
    """Held-out position RMS [mm] of the model at the start and after each step: an accepted
    effect's "after", and the model unchanged where the loop stopped."""
    st = path.steps
    rms = [st[0].heldout_rms_before if st else float("nan")]
    for s in st:
        rms.append(s.heldout_rms_after if s.verdict.startswith("added") else rms[-1])
    return rms


def plot_path(path: AutoPath, out: Any) -> Any:
    """Write the selection path as a PNG (atomic): held-out RMS after each step [mm], and each
    step's held-out evidence against the null quantile it was judged against [sigma^2]."""
    import os
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    st = path.steps
    labels = ["base"] + [
        (s.effect or "—") + ("" if s.verdict.startswith("added") else " (stop)") for s in st
    ]
    rms = path_rms(path)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.8))
    a1.plot(range(len(rms)), rms, "o-")
    a1.set_xticks(range(len(rms)), labels, rotation=30, ha="right", fontsize=8)
    a1.set_ylabel("held-out position RMS [mm]")
    a1.set_title("held-out error along the path")
    x = np.arange(len(st))
    a2.bar(x - 0.2, [max(s.heldout_gain_sigma2, 0.0) for s in st], 0.4, label="held-out gain")
    a2.bar(x + 0.2, [s.null_threshold_sigma2 for s in st], 0.4, label="null quantile (family-wise)")
    a2.set_xticks(x, labels[1:], rotation=30, ha="right", fontsize=8)
    a2.set_yscale("symlog", linthresh=1.0)
    a2.set_ylabel("sigma^2")
    a2.set_title("evidence vs the dataset's null")
    a2.legend(fontsize=8)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    os.replace(tmp, out)
    return out

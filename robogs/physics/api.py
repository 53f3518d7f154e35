"""Dataset-level entry points of the physics loop: compare, diagnose, fit, report, revert.

Every function takes a robogs dataset (a ``Dataset`` or its folder) or an in-memory
recording (anything :func:`~robogs.physics.recording.as_recording` accepts). Only
:func:`fit` and :func:`revert` write, and only to datasets: physics.json gets a new revision
through the dataset writer, which keeps the previous one in ``physics/history/``.

Datasets with cameras, panoptic masks and a Gaussian binding also get the mask-boundary stream
in :func:`compare` (:mod:`robogs.physics.masks`) and the ``camera_intrinsics`` sensor
effect in :func:`diagnose` and :func:`fit` (:mod:`robogs.physics.intrinsics`); a fit
of it writes the corrected ``cameras/<cam>.json`` together with a physics revision whose
``sensors.<cam>.intrinsics`` records the old and new values, so :func:`revert` restores both.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import InputError
from robogs.physics.baseline import Baseline, baseline
from robogs.physics.compare import CompareResult
from robogs.physics.diagnose import (
    AutoPath,
    DiagnoseResult,
    ParamEstimate,
    auto_loop,
    diagnose_recording,
    start_points,
)
from robogs.physics.effects import get_effect
from robogs.physics.engine import Engine, recording_backend, rms_mm
from robogs.physics.fit import FitOutcome, Problem, fit_nested
from robogs.physics.heldout import (
    determined_combination,
    determined_direction,
    held_mask,
    heldout_rollouts,
    holdout_folds,
    split_label,
)
from robogs.physics.masks import MAX_FRAMES
from robogs.physics.recording import Recording, as_recording, load_recording
from robogs.physics.report import render_report
from robogs.physics.residuals import tracked_rms

__all__ = [
    "compare",
    "heldout_error",
    "diagnose",
    "diagnose_auto",
    "fit",
    "FitResult",
    "report",
    "report_baselines",
    "revert",
    "UNDETERMINED",
]


def _open(dataset: Any) -> tuple[Recording, Any]:
    from robogs.format.dataset import Dataset

    if isinstance(dataset, Dataset):
        return load_recording(dataset), dataset
    if isinstance(dataset, (str, Path)):
        ds = Dataset.open(Path(dataset))
        return load_recording(ds), ds
    return as_recording(dataset), None


def _camera_effects() -> set[str]:
    """Effects fitted from camera masks, outside the rigid-object model (``model="camera"``)."""
    from robogs.physics.effects import available_effects

    return set(available_effects(model="camera"))


def _attach_masks(res: CompareResult, ds: Any, mask_frames: int, mask_poses: str) -> None:
    """Add the mask-boundary stream to ``res`` (objects at ``mask_poses``: model or recorded)."""
    from robogs.physics.masks import safe_mask_boundary

    if mask_poses not in ("model", "recorded"):
        raise InputError(f"mask_poses must be 'model' or 'recorded', got {mask_poses!r}")
    if mask_frames <= 0:
        res.masks, res.masks_absent = None, "not requested (mask frames 0)"
        return
    poses = None
    if mask_poses == "model" and res.predicted:
        obj = res.streams[0].stream.split("/", 1)[1]  # "object_poses/<free object>"
        poses = {p["trajectory"]: {obj: (p["t_ns"], p["pos"], p["quat"])} for p in res.predicted}
    res.masks, res.masks_absent = safe_mask_boundary(ds, max_frames=mask_frames, object_poses=poses)
    if res.masks is not None and poses is not None:
        res.masks.object_poses = f"model ({obj}: predicted; other objects: recorded)"


def compare(
    dataset: Any,
    *,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
    mask_poses: str = "model",
    progress: Callable[[int, int], None] | None = None,
    engine: str = "planar",
) -> CompareResult:
    """Residuals of the current physics revision, refitted, against the measured streams.

    The model is the one every command calls "before" (:func:`robogs.physics.baseline.
    baseline`): base parameters, present effects and each trajectory's initial pose refitted
    from the stored values; nothing is written. With camera masks and a binding the result carries the mask-boundary stream: links by
    forward kinematics of the measured joints, the free object at the model's predicted poses
    (``mask_poses="model"``) or at its recorded poses (``"recorded"``), ``mask_frames`` frames
    per camera stream (0: none). ``progress(iteration, unfinished fits)`` follows the refit.
    ``engine``: ``planar``, ``mujoco`` or ``auto`` (:func:`robogs.physics.engine.recording_backend`).
    """
    rec, ds = _open(dataset)
    res = copy.copy(
        baseline(rec, dt=dt, progress=progress, backend=recording_backend(rec, engine)[0]).result
    )  # the memoised table stays without masks
    _attach_masks(res, ds, mask_frames, mask_poses)
    return res


def heldout_error(
    dataset: Any,
    holdout: Sequence[str] | None = None,
    *,
    dt: float = 1e-3,
    engine: str = "planar",
) -> dict[str, Any]:
    """Held-out error of the current revision's baseline (the model ``compare`` shows), by
    diagnose's procedure (:func:`_heldout_resid`) on the default folds or on the trajectories
    ``holdout`` names: ``heldout_rms_mm`` [mm] over the held-out samples, ``heldout_chi2``
    [sigma^2], ``split`` (how they were held out) and ``holdout`` (the trajectories held out)."""
    rec, _ = _open(dataset)
    names = [t.name for t in rec.trajectories]
    folds = holdout_folds(names, holdout)  # a bad choice fails before fitting
    eng = Engine(rec, dt=dt, backend=engine)
    bl = baseline(rec, dt=dt, engine=eng)
    (r,), split, hm = _heldout_resid(eng, bl.space, [bl.outcome], [bl.free], holdout)
    return {
        "heldout_rms_mm": rms_mm(eng.raw(r), hm),
        "heldout_chi2": float(np.sum(r**2)),
        "split": split,
        "holdout": [n for n, m in zip(names, held_mask(folds, len(names)), strict=True) if m],
    }


def diagnose(
    dataset: Any,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
    engine: str = "planar",
    holdout: Sequence[str] | None = None,
) -> DiagnoseResult:
    """Rank candidate effects (see :mod:`robogs.physics.diagnose`).

    ``camera_intrinsics`` is judged from the camera masks (:mod:`robogs.physics.
    intrinsics`), skipped with the reason when the dataset has none. ``holdout``: trajectories
    (or episodes cut into ``<episode>#<k>``) held out as one fold instead of the default folds;
    the held-out errors, the gate's statistic and its simulated null use it
    (:func:`robogs.physics.diagnose.diagnose_recording`).
    """
    rec, ds = _open(dataset)
    names = None if effects is None else list(effects)
    camera = _camera_effects()
    rigid = None if names is None else [n for n in names if n not in camera]
    eng = Engine(rec, dt=dt, backend=engine)
    res = diagnose_recording(
        rec, effects=rigid, progress=progress, dt=dt, engine=eng, holdout=holdout
    )
    bl = baseline(rec, dt=dt, engine=eng)
    res.rms_base = bl.rms_mm  # the shared "before"
    res.design["wrench_note"] = bl.result.wrench_note
    if names is None or any(n in camera for n in names):
        from robogs.physics.intrinsics import NAME, diagnose_intrinsics

        fits, why = diagnose_intrinsics(ds, max_frames=mask_frames)
        if why is not None:
            res.skipped.append((NAME, why))
        res.rows.extend(f.row for f in fits)
        res.rows.sort(key=lambda r: (not r.reported, r.delta_bic))
    return res


def diagnose_auto(
    dataset: Any,
    *,
    effects: Sequence[str] | None = None,
    dt: float = 1e-3,
    max_steps: int = 5,
    progress: Callable[[int, int], None] | None = None,
    holdout: Sequence[str] | None = None,
    engine: str = "planar",
) -> AutoPath:
    """The object model's selection loop to its end (:func:`robogs.physics.diagnose.auto_loop`);
    camera-mask effects are left out (they are not part of the rigid-object model).
    ``holdout`` and ``engine``: as :func:`diagnose`, for every step."""
    rec, _ = _open(dataset)
    camera = _camera_effects()
    rigid = None if effects is None else [n for n in effects if n not in camera]
    return auto_loop(
        rec,
        effects=rigid,
        dt=dt,
        max_steps=max_steps,
        progress=progress,
        holdout=holdout,
        engine=engine,
    )


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    Attributes:
        params: fitted base and effect parameters with 95 % intervals (``owner.name``;
            unbounded where the parameter is not determined).
        rms_before / rms_after: position RMS [mm] of the baseline (:func:`robogs.physics.
            baseline.baseline`) of the revision fitted from and of the document written.
        noise_floor: data-estimated noise floor [mm].
        unidentifiable: parameters not written: base parameters the data do not determine
            (they keep their stored values) and the parameters of an effect of which no
            direction is determined.
        physics: the new physics.json document.
        revision: the revision written (None when nothing was written).
        from_revision: the revision fitted from (None for an unwritten document).
        heldout_rms_before / heldout_rms_after: held-out position RMS [mm] of the base fit and
            of the joint fit, by diagnose's procedure
            (:func:`robogs.physics.heldout.heldout_rollouts`: K folds of whole trajectories,
            one bounded Gauss-Newton step from the full fit on the training ones); with no
            ``add`` both are the base's.
        heldout_chi2_before / heldout_chi2_after: the same as whitened chi^2 [sigma^2].
        heldout_split: how the trajectories were held out.
        undetermined: per added effect written partly identified, its parameters the data do
            not determine (written at the estimate; the determined combination is in ``notes``).
        not_written: per added effect not written, the reason (no direction determined).
        notes: per added effect, what the fit says of it (partly identified, not written).
        objects: per object of the recording by dataset name (the free one first, then each
            tracked one): ``rms_before_mm`` / ``rms_after_mm`` (``compare``'s position RMS of
            that object), ``noise_floor_mm`` and ``heldout_rms_before_mm`` /
            ``heldout_rms_after_mm`` (:func:`_object_rms`); empty for a camera-only fit.
        shape_notes: what the engine simulated instead of what the dataset says
            (:meth:`~robogs.physics.engine.Engine.notes`): the objects simulated as their mesh's
            convex hull instead of a box, the hull substitutions
            (:class:`robogs.format.shapes.Shapes`), effects MuJoCo plays another way (a soft
            bounce for restitution on a free joint); appended to the revision note.
    """

    params: list[ParamEstimate]
    rms_before: float
    rms_after: float
    noise_floor: float
    unidentifiable: list[str]
    physics: dict[str, Any]
    revision: int | None = None
    compare_before: CompareResult | None = field(default=None, repr=False)
    compare_after: CompareResult | None = field(default=None, repr=False)
    cameras: list[dict[str, Any]] = field(default_factory=list)
    from_revision: int | None = None
    heldout_rms_before: float = float("nan")
    heldout_rms_after: float = float("nan")
    heldout_chi2_before: float = float("nan")
    heldout_chi2_after: float = float("nan")
    heldout_split: str = ""
    undetermined: dict[str, list[str]] = field(default_factory=dict)
    not_written: dict[str, str] = field(default_factory=dict)
    notes: dict[str, str] = field(default_factory=dict)
    objects: dict[str, dict[str, float]] = field(default_factory=dict)
    shape_notes: list[str] = field(default_factory=list)

    def refusal(self, path: Any = None) -> InputError | None:
        """The error to raise when an added effect could not be written (no direction of its
        parameters is determined), None when every added effect was written."""
        if not self.not_written:
            return None
        name, why = next(iter(self.not_written.items()))
        why, _, how = why.partition("; to identify it: ")
        return InputError(
            f"{name} is not written: {why}; nothing written",
            path=path,
            where=f"fit --add {name}",
            hint=f"to identify it: {how}" if how else None,
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "params": [
                {
                    "name": p.name,
                    "value": p.value,
                    "low": _fin(p.low),
                    "high": _fin(p.high),
                    "unit": p.unit,
                }
                for p in self.params
            ],
            "rms_before_mm": _fin(self.rms_before),
            "rms_after_mm": _fin(self.rms_after),
            "noise_floor_mm": _fin(self.noise_floor),
            "heldout_rms_before_mm": _fin(self.heldout_rms_before),
            "heldout_rms_after_mm": _fin(self.heldout_rms_after),
            "heldout_chi2_before": _fin(self.heldout_chi2_before),
            "heldout_chi2_after": _fin(self.heldout_chi2_after),
            "heldout_split": self.heldout_split,
            "unidentifiable": self.unidentifiable,
            "undetermined": self.undetermined,
            "not_written": self.not_written,
            "notes": self.notes,
            "objects": {k: {n: _fin(x) for n, x in v.items()} for k, v in self.objects.items()},
            "shape_notes": self.shape_notes,
            "revision": self.revision,
            "from_revision": self.from_revision,
            "cameras": self.cameras,
            "force_before": None if self.compare_before is None else self.compare_before.force,
            "force_after": None if self.compare_after is None else self.compare_after.force,
            "wrench_note": "" if self.compare_after is None else self.compare_after.wrench_note,
        }


def _fin(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


UNDETERMINED = "not determined by this data (interval unbounded); to determine it: "
"""How :func:`fit` flags an undetermined parameter of an effect it writes partly identified
(in the revision note and the output), followed by the effect's ``separate_by``."""


def _joint_fit(
    eng: Engine, space: Any, cands: list[Any], before: Baseline, progress: Any
) -> tuple[FitOutcome, FitOutcome, list[int], list[int]]:
    """The base model plus ``cands`` fitted jointly as diagnose fits a candidate
    (:func:`robogs.physics.fit.fit_nested` from the baseline's optimum, each effect's start
    points, the base refitted when the candidate switched off beats it); one candidate problem
    with every added effect's columns. Returns (base fit, joint fit, base columns, free)."""
    base_cols = eng.base_columns(space)
    extra: list[int] = []
    for e in cands:
        extra += [c for c in space.owner_columns(e.name) if c not in base_cols + extra]
    th0 = eng.start(space)
    starts = [th0]
    for e in cands:  # multi-start: each effect's extra start points, the others at zero
        starts += start_points(space, e, th0)[1:]
    known = before.outcome
    th_known = th0.copy()
    th_known[: len(known.theta)] = known.theta
    base_out, (out,) = fit_nested(
        lambda probs: eng.fit(space, probs, progress=progress),
        lambda th, lo: eng.evaluate(space, th, lo),
        space,
        Problem(free=list(base_cols), theta0=th0),
        [(extra, starts)],
        base_fit=replace(known, theta=th_known),
    )
    return base_out, out, list(base_cols), list(base_cols) + extra


def _heldout_resid(
    eng: Engine,
    space: Any,
    outs: list[FitOutcome],
    frees: list[list[int]],
    holdout: Sequence[str] | None = None,
) -> tuple[list[np.ndarray], str, np.ndarray]:
    """Held-out weighted residuals [T, C] of each fit (every held-out trajectory from the fit
    of the fold that held it out; zero for a trajectory no fold holds out), by diagnose's
    procedure; how they were held out; and the [T, N] pose samples held out (valid samples of
    held-out trajectories), over which held-out RMS values are taken. ``holdout``: the
    trajectories held out as one fold (:func:`robogs.physics.heldout.holdout_folds`; None: the
    default folds)."""
    names = [t.name for t in eng.prep.rec.trajectories]
    folds = holdout_folds(names, holdout)
    held, _, _ = heldout_rollouts(eng, space, outs, frees, folds)
    k = len(folds)
    rs = []
    for p in range(len(outs)):
        r = np.zeros_like(outs[0].resid)
        for f, fmask in enumerate(folds):
            r[fmask] = held[p * k + f][fmask]
        rs.append(r)
    hm = eng.mask & held_mask(folds, eng.prep.n_traj)[:, None]
    return rs, split_label(names, folds), hm


def _object_rms(
    eng: Engine,
    before: CompareResult,
    after: CompareResult,
    held: list[np.ndarray],
    hm: np.ndarray | None = None,
) -> dict[str, dict[str, float]]:
    """Per object of the recording (the free one first, then each tracked one, by dataset name):
    position RMS [mm] before -> after as ``compare`` gives them (the free object's overall RMS;
    a tracked object's ``object_poses/<name>`` rows pooled over trajectories by their sample
    counts), its noise floor [mm], and the held-out RMS [mm] of the weighted residuals ``held``
    (before, after; :func:`_heldout_resid`) over the held-out samples ``hm`` [T, N] (default:
    every valid sample)."""
    prep = eng.prep
    obj = prep.rec.object_name
    hm = eng.mask if hm is None else hm
    held_t = hm.any(axis=1)  # trajectories held out
    out = {
        obj: {
            "rms_before_mm": before.rms_mm,
            "rms_after_mm": after.rms_mm,
            "noise_floor_mm": after.noise_floor_mm,
            "heldout_rms_before_mm": rms_mm(eng.raw(held[0]), hm),
            "heldout_rms_after_mm": rms_mm(eng.raw(held[-1]), hm),
        }
    }
    names = [t.name for t in prep.rec.trajectories]
    hb, ha = tracked_rms(prep, held[0]), tracked_rms(prep, held[-1])
    for o in prep.tracked:
        n = o.mask.numpy().sum(1).astype(float)  # samples per trajectory

        def pooled(res: CompareResult, name: str = o.name, n: np.ndarray = n) -> float:
            rows = {s.trajectory: s.rms_mm for s in res.streams if s.stream.endswith(f"/{name}")}
            r = np.array([rows[t] for t in names])
            return float(np.sqrt(np.sum(n * r**2) / max(n.sum(), 1.0)))

        def held_rms(h: dict[str, Any], n: np.ndarray = n) -> float:
            """Per-trajectory RMS pooled over the held-out trajectories by sample count."""
            r = np.asarray(h["per_trajectory_mm"], dtype=float)[held_t]
            w = n[held_t]
            return float(np.sqrt(np.sum(w * r**2) / max(w.sum(), 1.0)))

        out[o.name] = {
            "rms_before_mm": pooled(before),
            "rms_after_mm": pooled(after),
            "noise_floor_mm": ha[o.name]["noise_floor_mm"],
            "heldout_rms_before_mm": held_rms(hb[o.name]),
            "heldout_rms_after_mm": held_rms(ha[o.name]),
        }
    return out


def _identification(
    space: Any, out: FitOutcome, free: list[int], added: set[str]
) -> tuple[dict[str, list[str]], dict[str, str], list[str], dict[str, str]]:
    """What a fit determines of each effect of ``space`` (diagnose's rule: every parameter,
    or a direction of them, :func:`robogs.physics.heldout.determined_combination`).

    Returns ``(undetermined, not_written, kept, notes)``: per partly identified effect its
    undetermined parameters; per effect of ``added`` of which nothing is determined, the
    reason; the effects already stored of which nothing is determined (their stored values are
    kept); and per effect not fully determined, the note printed and written.
    """
    undetermined: dict[str, list[str]] = {}
    not_written: dict[str, str] = {}
    notes: dict[str, str] = {}
    kept: list[str] = []
    for e in space.effects:
        jj = [free.index(c) for c in space.owner_columns(e.name) if c in free]
        if not jj or bool(out.ok[jj].all()):
            continue
        why = "; ".join(dict.fromkeys(out.why_param[j] for j in jj if out.why_param[j]))
        part = determined_combination(space, out, free, jj)
        if part is None:
            notes[e.name] = f"unidentifiable: {why}; to identify it: {e.separate_by}"
            if e.name in added:
                not_written[e.name] = notes[e.name]
            else:
                kept.append(e.name)
                notes[e.name] += " (its stored values are kept)"
            continue
        names = [space.slots[free[j]].param.name for j in jj if not out.ok[j]]
        undetermined[e.name] = names
        notes[e.name] = (
            f"partly identified: {', '.join(f'{e.name}.{n}' for n in names)} "
            f"{UNDETERMINED}{e.separate_by} ({why}; {part})"
        )
    return undetermined, not_written, kept, notes


def _fit_engine(
    eng: Engine,
    add: Sequence[str],
    progress: Callable[[int, int], None] | None = None,
    holdout: Sequence[str] | None = None,
) -> FitResult:
    """Refit the engine's revision plus ``add``; before and after are baselines (:func:`baseline`).

    The added effects are fitted jointly with the base model and the effects present, as
    diagnose fits a candidate (:func:`_joint_fit`). An added effect is written when all its
    parameters are determined, or when a direction of them is (diagnose's rule,
    :func:`robogs.physics.heldout.determined_direction`): then every parameter is written at
    the estimate and the undetermined ones are flagged (:data:`UNDETERMINED`); with no direction
    determined it is not written (``not_written``). A base parameter the data do not determine
    keeps its stored value, except where the near-singularity is that of a partly identified
    effect and the parameter's own interval is narrower than its bounds. "Before" is the
    baseline of the engine's revision, "after" the baseline of the document this fit writes, so
    ``compare`` and ``report`` of the written revision print the same "after". With nothing to
    add the fit is the baseline fit itself. ``holdout``: the trajectories the held-out error is
    measured on (one fold, :func:`robogs.physics.heldout.holdout_folds`; None: the default folds).
    """
    rec = eng.prep.rec
    holdout_folds([t.name for t in rec.trajectories], holdout)  # a bad choice fails before fitting
    cands = eng.check_effects(add)
    before = baseline(rec, dt=eng.prep.drive.dt, engine=eng, progress=progress)
    if cands:
        space = eng.space(cands)
        base_out, out, base_cols, free = _joint_fit(eng, space, cands, before, progress)
        held, split, hm = _heldout_resid(eng, space, [base_out, out], [base_cols, free], holdout)
    else:
        space, free, out = before.space, before.free, before.outcome
        held, split, hm = _heldout_resid(eng, space, [out], [free], holdout)
    h_b, h_a = (rms_mm(eng.raw(r), hm) for r in (held[0], held[-1]))
    c_b, c_a = (float(np.sum(r**2)) for r in (held[0], held[-1]))
    undetermined, not_written, kept, notes = _identification(
        space, out, free, {e.name for e in cands}
    )
    params, unident = [], []
    written = np.zeros(len(free), dtype=bool)
    for j, c in enumerate(free):
        s = space.slots[c]
        sd = float(out.std[j])
        params.append(
            ParamEstimate(
                s.key,
                float(out.theta[c]),
                out.theta[c] - 1.96 * sd,
                out.theta[c] + 1.96 * sd,
                s.param.unit,
            )
        )
        if s.owner == "base":
            written[j] = np.isfinite(sd)
            if not written[j] and undetermined and "do not change" not in out.why_param[j]:
                # near-singular with a partly identified effect: its own interval decides
                span = space.upper[[c]] - space.lower[[c]]
                one = out.cov[j : j + 1, j : j + 1]
                if determined_direction(one, span) is not None:
                    written[j] = True
                    half = 1.96 * float(np.sqrt(one[0, 0]))
                    params[-1] = replace(
                        params[-1], low=params[-1].value - half, high=params[-1].value + half
                    )
        else:
            written[j] = s.owner not in not_written and s.owner not in kept
        if not written[j]:
            unident.append(s.key)
    doc = copy.deepcopy(rec.physics)
    for k in ("revision", "parent_revision", "note"):  # the writer sets them
        doc.pop(k, None)
    obj = rec.object_name
    ob = doc.setdefault("objects", {}).setdefault(obj, {"equation": "rigid"})
    for c in space.owner_columns("base"):
        if written[free.index(c)]:  # an undetermined value keeps the stored one
            key = space.slots[c].param.name
            entry = ob
            if key.startswith("objects."):  # another object's, e.g. objects.box_b.friction_dynamic
                _, other, key = key.split(".", 2)
                entry = doc["objects"][other]
            entry[key] = float(out.theta[c])
            if key == "friction_dynamic" and float(entry.get("friction_static", 0.0)) < entry[key]:
                entry["friction_static"] = entry[key]  # the model's max(static, dynamic) (P002)
    effects = [
        e
        for e in doc.get("effects", [])
        if e.get("name") not in {x.name for x in space.effects} or e.get("name") in kept
    ]
    for e in space.effects:
        if e.name in not_written or e.name in kept:
            continue  # nothing of it determined: an added one is not written
        effects.append(
            {
                "name": e.name,
                "target": obj,
                "params": {p.name: float(out.theta[space.index(e.name, p.name)]) for p in e.params},
            }
        )
    doc["effects"] = effects
    rev = rec.physics.get("revision")
    doc["fit"] = {"from_revision": rev if isinstance(rev, int) else None, "added": list(add)}
    after = baseline(rec, doc, dt=eng.prep.drive.dt, progress=progress, backend=eng.backend)
    return FitResult(
        params=params,
        rms_before=before.rms_mm,
        rms_after=after.rms_mm,
        noise_floor=after.result.noise_floor_mm,
        unidentifiable=unident,
        physics=doc,
        compare_before=before.result,
        compare_after=after.result,
        from_revision=before.revision,
        heldout_rms_before=h_b,
        heldout_rms_after=h_a,
        heldout_chi2_before=c_b,
        heldout_chi2_after=c_a,
        heldout_split=split,
        undetermined=undetermined,
        not_written=not_written,
        notes=notes,
        objects=_object_rms(eng, before.result, after.result, held, hm),
    )


def fit(
    dataset: Any,
    add: Sequence[str] = (),
    *,
    write: bool = True,
    note: str | None = None,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
    progress: Callable[[int, int], None] | None = None,
    engine: str = "planar",
    holdout: Sequence[str] | None = None,
) -> FitResult:
    """Refit the base model (and the effects already present) plus ``add``.

    With a dataset and ``write=True`` the fitted values become a new physics.json revision
    (the previous one is kept in ``physics/history/``; see :func:`revert`). An added effect of
    which only some direction of the parameters is determined (diagnose's verdict "add (partly
    identified)") is written at the estimate, its undetermined parameters flagged in
    ``undetermined``, ``notes`` and the revision note (:data:`UNDETERMINED`). An added effect of
    which nothing is determined is not written: with a dataset and ``write=True`` nothing is
    written and :class:`InputError` says why (the CLI prints one line and exits 2); otherwise it
    is listed in ``not_written``. Base parameters found unidentifiable are listed in
    ``unidentifiable`` and keep their stored values. Objects simulated as their mesh's convex
    hull (:mod:`robogs.format.shapes`) are said so in ``shape_notes`` and in the revision note.

    ``camera_intrinsics`` is fitted from the camera masks instead (``mask_frames`` frames per
    camera stream): the corrected ``cameras/<cam>.json`` is written in the same edit as the
    physics revision, whose ``sensors.<cam>.intrinsics`` keeps the previous values. Asked
    alone, it leaves the rigid-model parameters as they are.

    "Before" and "after" are baselines (:mod:`robogs.physics.baseline`) of the revision
    fitted from and of the document written; with no ``add`` the base model is refitted.
    The held-out error is diagnose's (:func:`_heldout_resid`): on the default folds, or on the
    trajectories ``holdout`` names, held out as one fold (the others train it; ``heldout_split``
    says which). ``progress(iteration, unfinished fits)`` follows each fit.
    """
    camera = _camera_effects()
    cam_add = [a for a in add if a in camera]
    rigid_add = [a for a in add if a not in camera]
    if cam_add and not rigid_add:
        ds = _dataset(dataset, cam_add[0])
        res = FitResult(
            [], float("nan"), float("nan"), float("nan"), [], copy.deepcopy(ds.physics())
        )
    else:
        rec, ds = _open(dataset)
        eng = Engine(rec, dt=dt, backend=engine)
        res = _fit_engine(eng, rigid_add, progress, holdout)
        res.shape_notes = eng.notes(rigid_add)
    if ds is not None and write and (err := res.refusal(ds.root)) is not None:
        raise err
    new_cams = []
    if cam_add:
        new_cams = _fit_cameras(
            _dataset(ds if ds is not None else dataset, cam_add[0]), res, mask_frames
        )
    if ds is not None and write:
        text = note or (f"fit: added {', '.join(add)}" if add else "fit: refitted the base model")
        for name, params in res.undetermined.items():
            text += f"; {', '.join(f'{name}.{n}' for n in params)} {UNDETERMINED}"
            text += get_effect(name).separate_by
        if res.shape_notes:  # what the engine simulated instead of what the dataset says
            text += "; " + "; ".join(res.shape_notes)
        with ds.edit() as w:
            for cam in new_cams:
                w.set_camera(cam)
            res.revision = w.set_physics(res.physics, note=text)
            w.commit()
    return res


def _as_dataset(dataset: Any) -> Any:
    """The ``Dataset`` of a dataset or folder; None for an in-memory recording."""
    from robogs.format.dataset import Dataset

    if isinstance(dataset, (str, Path)):
        return Dataset.open(Path(dataset))
    return dataset if isinstance(dataset, Dataset) else None


def _dataset(dataset: Any, effect: str) -> Any:
    from robogs.format.dataset import Dataset

    if isinstance(dataset, Dataset):
        return dataset
    if isinstance(dataset, (str, Path)):
        return Dataset.open(Path(dataset))
    raise InputError(
        f"{effect} is fitted from camera masks; an in-memory recording has none",
        hint="pass a dataset folder with cameras, panoptic labels and bound splats",
    )


def _fit_cameras(ds: Any, res: FitResult, mask_frames: int) -> list[Any]:
    """Fit every camera's intrinsics; record them in ``res``; return the corrected cameras."""
    from robogs.physics.intrinsics import NAME, corrected_camera, fit_intrinsics

    out = []
    for f in fit_intrinsics(ds, max_frames=mask_frames):
        cam, new = f.camera, corrected_camera(f)
        for p, ok in zip(f.row.params, f.identifiable, strict=True):
            res.params.append(replace(p, name=f"{NAME}.{p.name}"))
            if not ok:
                res.unidentifiable.append(f"{NAME}.{p.name}")
        keys = ("fx", "fy", "cx", "cy")
        before = {k: float(getattr(cam, k)) for k in keys}
        after = {k: float(getattr(new, k)) for k in keys}
        res.physics.setdefault("sensors", {}).setdefault(cam.name, {})["intrinsics"] = {
            **after,
            "previous": before,
            "boundary_px_before": f.boundary_px_before,
            "boundary_px_after": f.boundary_px_after,
        }
        res.cameras.append(
            {
                "camera": cam.name,
                "before": before,
                "after": after,
                "boundary_px_before": f.boundary_px_before,
                "boundary_px_after": f.boundary_px_after,
                "noise_px": f.sigma_px,
                "reported": f.row.reported,
                "verdict": f.row.verdict,
            }
        )
        if f.identifiable.any():
            out.append(new)
    return out


@dataclass
class ReportPair:
    """The "before" and "after" a physics report shows, with what each one is.

    Attributes:
        before / after: residual tables of the two baselines.
        before_label / after_label: which revision each is (for people).
        params: the "after" model's fitted parameters with 95 % intervals.
        added: the effects the "after" model adds.
        before_revision / after_revision: revision numbers (None: not written).
        heldout_rms_before / heldout_rms_after: held-out position RMS [mm] by diagnose's
            procedure (:func:`_heldout_resid`) of the two models.
        heldout_split: how the trajectories were held out (``"5 folds of whole
            trajectories"`` or ``"held out: a, b (2 of 6 trajectories)"``).
        holdout: the trajectories a held-out choice held out (empty: the default folds).
        notes: per effect of the "after" model not fully determined, what is (partly
            identified: the undetermined parameters, the determined combination, the experiment
            that would determine the rest; :func:`_identification`).
    """

    before: CompareResult
    after: CompareResult
    before_label: str
    after_label: str
    params: list[ParamEstimate]
    added: list[str]
    before_revision: int | None = None
    after_revision: int | None = None
    heldout_rms_before: float = float("nan")
    heldout_rms_after: float = float("nan")
    notes: dict[str, str] = field(default_factory=dict)
    heldout_split: str = ""
    holdout: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "before": {"label": self.before_label, "revision": self.before_revision},
            "after": {"label": self.after_label, "revision": self.after_revision},
            "rms_before_mm": self.before.rms_mm,
            "rms_after_mm": self.after.rms_mm,
            "heldout_rms_before_mm": _fin(self.heldout_rms_before),
            "heldout_rms_after_mm": _fin(self.heldout_rms_after),
            "heldout_split": self.heldout_split,
            "holdout": self.holdout,
            "added": self.added,
            "notes": self.notes,
        }


def _fitted_from(rec: Recording, ds: Any) -> dict[str, Any] | None:
    """The physics document the current revision was fitted from (None if not a fit's)."""
    import json

    rev = (rec.physics.get("fit") or {}).get("from_revision")
    if ds is None or not isinstance(rev, int) or rev not in ds.physics_history():
        return None
    return json.loads(ds.resolve(f"physics/history/rev-{rev:04d}.json").read_text())


def _label(bl: Baseline) -> str:
    rev = "unwritten revision" if bl.revision is None else f"revision {bl.revision}"
    return f"{rev}, refitted"


def report_baselines(
    dataset: Any,
    *,
    add: Sequence[str] = (),
    dt: float = 1e-3,
    engine: str = "planar",
    holdout: Sequence[str] | None = None,
) -> ReportPair:
    """What :func:`report` compares; every value comes from :func:`baseline`.

    * ``add`` given: before = the current revision, after = the document ``fit --add`` would
      write (a dry run);
    * else, when the current revision was written by :func:`fit`: before = the revision it was
      fitted from (``physics/history``), after = the current revision;
    * else before = after = the current revision.

    ``holdout``: the trajectories the held-out error is measured on, held out as one fold
    (:func:`robogs.physics.heldout.holdout_folds`; None: the default folds), as ``compare``,
    ``diagnose`` and ``fit`` take it; a bad choice raises before anything is fitted.
    """
    rec, ds = _open(dataset)
    return _report_pair(rec, ds, add, dt, engine, holdout)


def _report_pair(
    rec: Recording,
    ds: Any,
    add: Sequence[str],
    dt: float,
    engine: str = "planar",
    holdout: Sequence[str] | None = None,
) -> ReportPair:
    names = [t.name for t in rec.trajectories]
    folds = holdout_folds(names, holdout)  # a bad choice fails before fitting
    split = split_label(names, folds)
    held_names = (
        [n for n, m in zip(names, held_mask(folds, len(names)), strict=True) if m]
        if holdout
        else []
    )
    rigid = [a for a in add if a not in _camera_effects()]
    backend = recording_backend(rec, engine)[0]
    if rigid:
        res = _fit_engine(Engine(rec, dt=dt, backend=backend), rigid, None, holdout)
        if res.compare_before is None or res.compare_after is None:  # pragma: no cover
            raise RuntimeError("comparison missing")
        rev = "unwritten revision" if res.from_revision is None else f"revision {res.from_revision}"
        return ReportPair(
            res.compare_before,
            res.compare_after,
            f"{rev}, refitted",
            f"{rev} + {', '.join(rigid)}, refitted (not written)",
            res.params,
            rigid,
            res.from_revision,
            None,
            res.heldout_rms_before,
            res.heldout_rms_after,
            res.notes,
            res.heldout_split,
            held_names,
        )
    after = baseline(rec, dt=dt, backend=backend)
    parent = _fitted_from(rec, ds)
    before = after if parent is None else baseline(rec, parent, dt=dt, backend=backend)
    added = list((rec.physics.get("fit") or {}).get("added") or []) if parent is not None else []
    held = [_baseline_heldout(rec, after, dt, backend, holdout)]
    held = (
        held * 2
        if parent is None
        else [_baseline_heldout(rec, before, dt, backend, holdout), *held]
    )
    return ReportPair(
        before.result,
        after.result,
        _label(before),
        _label(after) if parent is None else f"{_label(after)} (fitted from {before.revision})",
        after.params(),
        added,
        before.revision,
        after.revision,
        held[0],
        held[1],
        _identification(after.space, after.outcome, after.free, set())[3],
        split,
        held_names,
    )


def _baseline_heldout(
    rec: Recording,
    bl: Baseline,
    dt: float,
    backend: str,
    holdout: Sequence[str] | None = None,
) -> float:
    """Held-out position RMS [mm] of a baseline (:func:`_heldout_resid`, on its own document;
    ``holdout``: the held-out fold, None for the default folds)."""
    eng = Engine(replace(rec, physics=bl.physics), dt=dt, backend=backend)
    (r,), _, hm = _heldout_resid(eng, bl.space, [bl.outcome], [bl.free], holdout)
    return rms_mm(eng.raw(r), hm)


def report(
    dataset: Any,
    out_html: str | Path,
    *,
    add: Sequence[str] = (),
    dt: float = 1e-3,
    pair: ReportPair | None = None,
    engine: str = "planar",
    holdout: Sequence[str] | None = None,
    diagnosis: DiagnoseResult | None = None,
) -> Path:
    """Write an HTML report of residuals before and after (see :func:`report_baselines`;
    ``pair``: one it already returned for this dataset, instead of ``add``, ``dt`` and
    ``holdout``). The report states the held-out split (the trajectories ``holdout`` held out,
    or the default folds). ``diagnosis``: the diagnosis the "after" effect was chosen from (on
    the same split), shown as a table of held-out errors, gains and the gate's null quantiles.

    Plots are inline SVG (matplotlib is not required).
    """
    if pair is None:
        rec, ds = _open(dataset)
        pair = _report_pair(rec, ds, add, dt, engine, holdout)
    else:
        ds = _as_dataset(dataset)
    before = copy.copy(pair.before)  # the memoised table stays without masks
    _attach_masks(before, ds, MAX_FRAMES, "model")
    rows = [(p.name, p.value, p.low, p.high, p.unit) for p in pair.params]
    return render_report(
        before,
        pair.after,
        out_html,
        title="robogs physics report",
        added=pair.added,
        params=rows,
        labels=(pair.before_label, pair.after_label),
        heldout=(pair.heldout_rms_before, pair.heldout_rms_after),
        notes=[f"{k}: {v}" for k, v in pair.notes.items()],
        split=pair.heldout_split,
        holdout=pair.holdout,
        diagnosis=[
            (
                r.name,
                r.heldout_rms_before,
                r.heldout_rms_after,
                r.unit,
                r.heldout_gain_sigma2,
                r.null_threshold_sigma2,
                r.verdict or ("missing" if r.reported else "not supported"),
            )
            for r in (diagnosis.rows if diagnosis is not None else [])
        ],
    )


def revert(dataset: Any, revision: int) -> int:
    """Make an earlier physics.json revision current again (as a new revision); returns it."""
    import json

    from robogs.format.dataset import Dataset

    ds = dataset if isinstance(dataset, Dataset) else Dataset.open(Path(dataset))
    if revision not in ds.physics_history():
        raise InputError(
            f"no physics revision {revision}",
            path=ds.resolve("physics.json"),
            where="physics/history",
            hint=f"kept revisions: {ds.physics_history()}",
        )
    old = json.loads(ds.resolve(f"physics/history/rev-{revision:04d}.json").read_text())
    keys = ("fx", "fy", "cx", "cy")

    def record(doc: dict[str, Any], cam: str) -> dict[str, Any] | None:
        rec = (((doc.get("sensors") or {}).get(cam) or {}).get("intrinsics")) or None
        return rec if isinstance(rec, dict) else None

    # camera intrinsics in force at ``revision``: its own record of the last intrinsics fit
    # (later revisions carry records over), else the "previous" values of the first later fit
    restore: dict[str, dict[str, float]] = {}
    for cam in ds.camera_names:
        rec = record(old, cam)
        if rec is not None and all(k in rec for k in keys):
            restore[cam] = {k: rec[k] for k in keys}
    docs = [
        json.loads(ds.resolve(f"physics/history/rev-{r:04d}.json").read_text())
        for r in ds.physics_history()
        if r > revision
    ] + [ds.physics()]
    for doc in sorted(docs, key=lambda d: int(d.get("revision", 0))):
        for cam in ds.camera_names:
            prev = (record(doc, cam) or {}).get("previous")
            if isinstance(prev, dict) and cam not in restore:
                restore[cam] = prev
    with ds.edit() as w:
        for cam, vals in restore.items():
            w.set_camera(replace(ds.camera(cam), **{k: float(vals[k]) for k in keys}))
        rev = w.set_physics(old, note=f"revert to revision {revision}")
        w.commit()
    return rev

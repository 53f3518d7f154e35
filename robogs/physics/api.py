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
from robogs.physics.engine import Engine, resolve_backend
from robogs.physics.fit import Problem
from robogs.physics.masks import MAX_FRAMES
from robogs.physics.recording import Recording, as_recording, load_recording
from robogs.physics.report import render_report

__all__ = [
    "compare",
    "diagnose",
    "diagnose_auto",
    "fit",
    "FitResult",
    "report",
    "report_baselines",
    "revert",
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
    ``engine``: ``planar``, ``mujoco`` or ``auto`` (:func:`robogs.physics.engine.resolve_backend`).
    """
    rec, ds = _open(dataset)
    res = copy.copy(
        baseline(
            rec, dt=dt, progress=progress, backend=resolve_backend(rec.physics, engine)[0]
        ).result
    )  # the memoised table stays without masks
    _attach_masks(res, ds, mask_frames, mask_poses)
    return res


def diagnose(
    dataset: Any,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
    engine: str = "planar",
) -> DiagnoseResult:
    """Rank candidate effects (see :mod:`robogs.physics.diagnose`).

    ``camera_intrinsics`` is judged from the camera masks (:mod:`robogs.physics.
    intrinsics`), skipped with the reason when the dataset has none.
    """
    rec, ds = _open(dataset)
    names = None if effects is None else list(effects)
    camera = _camera_effects()
    rigid = None if names is None else [n for n in names if n not in camera]
    eng = Engine(rec, dt=dt, backend=engine)
    res = diagnose_recording(rec, effects=rigid, progress=progress, dt=dt, engine=eng)
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
) -> AutoPath:
    """The object model's selection loop to its end (:func:`robogs.physics.diagnose.auto_loop`);
    camera-mask effects are left out (they are not part of the rigid-object model)."""
    rec, _ = _open(dataset)
    camera = _camera_effects()
    rigid = None if effects is None else [n for n in effects if n not in camera]
    return auto_loop(rec, effects=rigid, dt=dt, max_steps=max_steps, progress=progress)


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    Attributes:
        params: fitted base and effect parameters with 95 % intervals (``owner.name``).
        rms_before / rms_after: position RMS [mm] of the baseline (:func:`robogs.physics.
            baseline.baseline`) of the revision fitted from and of the document written.
        noise_floor: data-estimated noise floor [mm].
        unidentifiable: parameters the data do not identify (insensitive, near-collinear or
            with an interval wider than their bounds); they are not written.
        physics: the new physics.json document.
        revision: the revision written (None when nothing was written).
        from_revision: the revision fitted from (None for an unwritten document).
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
            "unidentifiable": self.unidentifiable,
            "revision": self.revision,
            "from_revision": self.from_revision,
            "cameras": self.cameras,
            "force_before": None if self.compare_before is None else self.compare_before.force,
            "force_after": None if self.compare_after is None else self.compare_after.force,
            "wrench_note": "" if self.compare_after is None else self.compare_after.wrench_note,
        }


def _fin(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _fit_engine(
    eng: Engine, add: Sequence[str], progress: Callable[[int, int], None] | None = None
) -> FitResult:
    """Refit the engine's revision plus ``add``; before and after are baselines (:func:`baseline`).

    "Before" is the baseline of the engine's revision, "after" the baseline of the document
    this fit writes (effects with an unidentifiable parameter left out, unidentifiable base
    values kept at their stored ones), so ``compare`` and ``report`` of the written revision
    print the same "after". With nothing to add the fit is the baseline fit itself.
    """
    rec = eng.prep.rec
    cands = eng.check_effects(add)
    before = baseline(rec, dt=eng.prep.drive.dt, engine=eng, progress=progress)
    if cands:
        space = eng.space(cands)
        free = eng.base_columns(space)
        for e in cands:
            free += [c for c in space.owner_columns(e.name) if c not in free]
        th0 = eng.start(space)
        starts = [th0]
        for e in cands:  # multi-start: each effect's extra start points, the others at zero
            starts += start_points(space, e, th0)[1:]
        outs = eng.fit(space, [Problem(free=free, theta0=th) for th in starts], progress=progress)
        out = min(outs, key=lambda o: o.cost)
    else:
        space, free, out = before.space, before.free, before.outcome
    params, unident = [], []
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
        if not np.isfinite(sd):
            unident.append(s.key)
    doc = copy.deepcopy(rec.physics)
    for k in ("revision", "parent_revision", "note"):  # the writer sets them
        doc.pop(k, None)
    obj = rec.object_name
    ob = doc.setdefault("objects", {}).setdefault(obj, {"equation": "rigid"})
    for c in space.owner_columns("base"):
        if np.isfinite(out.std[free.index(c)]):  # an unidentifiable value keeps the stored one
            key = space.slots[c].param.name
            entry = ob
            if key.startswith("objects."):  # another object's, e.g. objects.box_b.friction_dynamic
                _, other, key = key.split(".", 2)
                entry = doc["objects"][other]
            entry[key] = float(out.theta[c])
            if key == "friction_dynamic" and float(entry.get("friction_static", 0.0)) < entry[key]:
                entry["friction_static"] = entry[key]  # the model's max(static, dynamic) (P002)
    bad = set(unident)
    effects = [
        e for e in doc.get("effects", []) if e.get("name") not in {x.name for x in space.effects}
    ]
    for e in space.effects:
        if any(f"{e.name}.{p.name}" in bad for p in e.params):
            continue  # an effect with an unidentifiable parameter is not written
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
) -> FitResult:
    """Refit the base model (and the effects already present) plus ``add``.

    With a dataset and ``write=True`` the fitted values become a new physics.json revision
    (the previous one is kept in ``physics/history/``; see :func:`revert`). Parameters found
    unidentifiable are reported in ``unidentifiable`` and are not written.

    ``camera_intrinsics`` is fitted from the camera masks instead (``mask_frames`` frames per
    camera stream): the corrected ``cameras/<cam>.json`` is written in the same edit as the
    physics revision, whose ``sensors.<cam>.intrinsics`` keeps the previous values. Asked
    alone, it leaves the rigid-model parameters as they are.

    "Before" and "after" are baselines (:mod:`robogs.physics.baseline`) of the revision
    fitted from and of the document written; with no ``add`` the base model is refitted.
    ``progress(iteration, unfinished fits)`` follows each fit.
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
        res = _fit_engine(Engine(rec, dt=dt, backend=engine), rigid_add, progress)
    new_cams = []
    if cam_add:
        new_cams = _fit_cameras(
            _dataset(ds if ds is not None else dataset, cam_add[0]), res, mask_frames
        )
    if ds is not None and write:
        with ds.edit() as w:
            for cam in new_cams:
                w.set_camera(cam)
            res.revision = w.set_physics(
                res.physics,
                note=note
                or (f"fit: added {', '.join(add)}" if add else "fit: refitted the base model"),
            )
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
    """

    before: CompareResult
    after: CompareResult
    before_label: str
    after_label: str
    params: list[ParamEstimate]
    added: list[str]
    before_revision: int | None = None
    after_revision: int | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "before": {"label": self.before_label, "revision": self.before_revision},
            "after": {"label": self.after_label, "revision": self.after_revision},
            "rms_before_mm": self.before.rms_mm,
            "rms_after_mm": self.after.rms_mm,
            "added": self.added,
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
    dataset: Any, *, add: Sequence[str] = (), dt: float = 1e-3, engine: str = "planar"
) -> ReportPair:
    """What :func:`report` compares; every value comes from :func:`baseline`.

    * ``add`` given: before = the current revision, after = the document ``fit --add`` would
      write (a dry run);
    * else, when the current revision was written by :func:`fit`: before = the revision it was
      fitted from (``physics/history``), after = the current revision;
    * else before = after = the current revision.
    """
    rec, ds = _open(dataset)
    return _report_pair(rec, ds, add, dt, engine)


def _report_pair(
    rec: Recording, ds: Any, add: Sequence[str], dt: float, engine: str = "planar"
) -> ReportPair:
    rigid = [a for a in add if a not in _camera_effects()]
    backend = resolve_backend(rec.physics, engine)[0]
    if rigid:
        res = _fit_engine(Engine(rec, dt=dt, backend=backend), rigid)
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
        )
    after = baseline(rec, dt=dt, backend=backend)
    parent = _fitted_from(rec, ds)
    before = after if parent is None else baseline(rec, parent, dt=dt, backend=backend)
    added = list((rec.physics.get("fit") or {}).get("added") or []) if parent is not None else []
    return ReportPair(
        before.result,
        after.result,
        _label(before),
        _label(after) if parent is None else f"{_label(after)} (fitted from {before.revision})",
        after.params(),
        added,
        before.revision,
        after.revision,
    )


def report(
    dataset: Any,
    out_html: str | Path,
    *,
    add: Sequence[str] = (),
    dt: float = 1e-3,
    pair: ReportPair | None = None,
    engine: str = "planar",
) -> Path:
    """Write an HTML report of residuals before and after (see :func:`report_baselines`;
    ``pair``: one it already returned for this dataset, instead of ``add`` and ``dt``).

    Plots are inline SVG (matplotlib is not required).
    """
    if pair is None:
        rec, ds = _open(dataset)
        pair = _report_pair(rec, ds, add, dt, engine)
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

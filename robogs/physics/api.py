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
from robogs.physics.compare import CompareResult, compare_recording, residual_table
from robogs.physics.diagnose import (
    DiagnoseResult,
    ParamEstimate,
    diagnose_recording,
    start_points,
)
from robogs.physics.engine import Engine
from robogs.physics.fit import Problem
from robogs.physics.masks import MAX_FRAMES
from robogs.physics.recording import Recording, as_recording, load_recording
from robogs.physics.report import render_report

__all__ = ["compare", "diagnose", "fit", "FitResult", "report", "revert"]


def _open(dataset: Any) -> tuple[Recording, Any]:
    from robogs.format.dataset import Dataset

    if isinstance(dataset, Dataset):
        return load_recording(dataset), dataset
    if isinstance(dataset, (str, Path)):
        ds = Dataset.open(Path(dataset))
        return load_recording(ds), ds
    return as_recording(dataset), None


#: effects fitted from camera masks, outside the rigid-object model
CAMERA_EFFECTS = ("camera_intrinsics",)


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
    dataset: Any, *, dt: float = 1e-3, mask_frames: int = MAX_FRAMES, mask_poses: str = "model"
) -> CompareResult:
    """Residuals of the stored model against the measured streams (nothing is refitted).

    With camera masks and a binding the result carries the mask-boundary stream: links by
    forward kinematics of the measured joints, the free object at the model's predicted poses
    (``mask_poses="model"``) or at its recorded poses (``"recorded"``), ``mask_frames`` frames
    per camera stream (0: none).
    """
    rec, ds = _open(dataset)
    res = compare_recording(rec, dt=dt)
    _attach_masks(res, ds, mask_frames, mask_poses)
    return res


def diagnose(
    dataset: Any,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
) -> DiagnoseResult:
    """Rank candidate effects (see :mod:`robogs.physics.diagnose`).

    ``camera_intrinsics`` is judged from the camera masks (:mod:`robogs.physics.
    intrinsics`), skipped with the reason when the dataset has none.
    """
    rec, ds = _open(dataset)
    names = None if effects is None else list(effects)
    rigid = None if names is None else [n for n in names if n not in CAMERA_EFFECTS]
    res = diagnose_recording(rec, effects=rigid, progress=progress, dt=dt)
    if names is None or any(n in CAMERA_EFFECTS for n in names):
        from robogs.physics.intrinsics import NAME, diagnose_intrinsics

        fits, why = diagnose_intrinsics(ds, max_frames=mask_frames)
        if why is not None:
            res.skipped.append((NAME, why))
        res.rows.extend(f.row for f in fits)
        res.rows.sort(key=lambda r: (not r.reported, r.delta_bic))
    return res


@dataclass
class FitResult:
    """Outcome of :func:`fit`.

    Attributes:
        params: fitted base and effect parameters with 95 % intervals (``owner.name``).
        rms_before / rms_after: position RMS [mm] with stored and fitted parameters.
        noise_floor: data-estimated noise floor [mm].
        unidentifiable: parameters the data do not identify (insensitive, near-collinear or
            with an interval wider than their bounds); they are not written.
        physics: the new physics.json document.
        revision: the revision written (None when nothing was written).
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
            "cameras": self.cameras,
        }


def _fin(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _fit_engine(eng: Engine, add: Sequence[str]) -> FitResult:
    cands = eng.check_effects(add)
    space = eng.space(cands)
    free = eng.base_columns(space)
    for e in cands:
        free += [c for c in space.owner_columns(e.name) if c not in free]
    th0 = eng.start(space)
    starts = [th0]
    for e in cands:  # multi-start: each effect's extra start points, the others at zero
        starts += start_points(space, e, th0)[1:]
    outs = eng.fit(space, [Problem(free=free, theta0=th) for th in starts])
    out = min(outs, key=lambda o: o.cost)
    before = eng.evaluate(space, th0[None], np.zeros((1, eng.prep.n_traj, 3)))[0]
    cmp_before = residual_table(eng, eng.raw(before))
    cmp_after = residual_table(eng, eng.raw(out.resid))
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
    doc = copy.deepcopy(eng.prep.rec.physics)
    obj = eng.prep.rec.object_name
    ob = doc.setdefault("objects", {}).setdefault(obj, {"equation": "rigid"})
    for c in space.owner_columns("base"):
        if np.isfinite(out.std[free.index(c)]):  # an unidentifiable value keeps the stored one
            ob[space.slots[c].param.name] = float(out.theta[c])
    effects = [
        e for e in doc.get("effects", []) if e.get("name") not in {x.name for x in space.effects}
    ]
    for e in space.effects:
        effects.append(
            {
                "name": e.name,
                "target": obj,
                "params": {p.name: float(out.theta[space.index(e.name, p.name)]) for p in e.params},
            }
        )
    doc["effects"] = effects
    return FitResult(
        params=params,
        rms_before=cmp_before.rms_mm,
        rms_after=cmp_after.rms_mm,
        noise_floor=cmp_after.noise_floor_mm,
        unidentifiable=unident,
        physics=doc,
        compare_before=cmp_before,
        compare_after=cmp_after,
    )


def fit(
    dataset: Any,
    add: Sequence[str] = (),
    *,
    write: bool = True,
    note: str | None = None,
    dt: float = 1e-3,
    mask_frames: int = MAX_FRAMES,
) -> FitResult:
    """Refit the base model (and the effects already present) plus ``add``.

    With a dataset and ``write=True`` the fitted values become a new physics.json revision
    (the previous one is kept in ``physics/history/``; see :func:`revert`). Parameters found
    unidentifiable are reported in ``unidentifiable`` and are not written.

    ``camera_intrinsics`` is fitted from the camera masks instead (``mask_frames`` frames per
    camera stream): the corrected ``cameras/<cam>.json`` is written in the same edit as the
    physics revision, whose ``sensors.<cam>.intrinsics`` keeps the previous values. Asked
    alone, it leaves the rigid-model parameters as they are.
    """
    cam_add = [a for a in add if a in CAMERA_EFFECTS]
    rigid_add = [a for a in add if a not in CAMERA_EFFECTS]
    if cam_add and not rigid_add:
        ds = _dataset(dataset, cam_add[0])
        res = FitResult(
            [], float("nan"), float("nan"), float("nan"), [], copy.deepcopy(ds.physics())
        )
    else:
        rec, ds = _open(dataset)
        res = _fit_rigid(Engine(rec, dt=dt), rigid_add)
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
                res.physics, note=note or f"fit: added {', '.join(add) or 'nothing'}"
            )
            w.commit()
    return res


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


def _fit_rigid(eng: Engine, add: Sequence[str]) -> FitResult:
    res = _fit_engine(eng, add)
    if res.unidentifiable:
        bad = set(res.unidentifiable)
        res.physics["effects"] = [
            e
            for e in res.physics["effects"]
            if not any(f"{e['name']}.{k}" in bad for k in e["params"])
        ]
    return res


def report(
    dataset: Any, out_html: str | Path, *, add: Sequence[str] = (), dt: float = 1e-3
) -> Path:
    """Write an HTML report of residuals before (stored physics) and after refitting with ``add``.

    Plots are inline SVG (matplotlib is not required).
    """
    rec, ds = _open(dataset)
    eng = Engine(rec, dt=dt)
    res = _fit_engine(eng, [a for a in add if a not in CAMERA_EFFECTS])
    before, after = res.compare_before, res.compare_after
    if before is None or after is None:  # pragma: no cover - _fit_engine always fills them
        raise RuntimeError("comparison missing")
    _attach_masks(before, ds, MAX_FRAMES, "model")
    rows = [(p.name, p.value, p.low, p.high, p.unit) for p in res.params]
    return render_report(
        before, after, out_html, title="robogs physics report", added=list(add), params=rows
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

"""Dataset-level entry points of the physics loop: compare, diagnose, fit, report, revert.

Every function takes a robogs dataset (a ``Dataset`` or its folder) or an in-memory
recording (anything :func:`~reference_impl.physics.recording.as_recording` accepts). Only
:func:`fit` and :func:`revert` write, and only to datasets: physics.json gets a new revision
through the dataset writer, which keeps the previous one in ``physics/history/``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from reference_impl.physics.compare import CompareResult, compare_recording, residual_table
from reference_impl.physics.diagnose import (
    DiagnoseResult,
    ParamEstimate,
    diagnose_recording,
    start_points,
)
from reference_impl.physics.engine import Engine
from reference_impl.physics.fit import Problem
from reference_impl.physics.recording import Recording, as_recording, load_recording
from reference_impl.physics.report import render_report
from robogs_format.errors import InputError

__all__ = ["compare", "diagnose", "fit", "FitResult", "report", "revert"]


def _open(dataset: Any) -> tuple[Recording, Any]:
    from robogs_format.dataset import Dataset

    if isinstance(dataset, Dataset):
        return load_recording(dataset), dataset
    if isinstance(dataset, (str, Path)):
        ds = Dataset.open(Path(dataset))
        return load_recording(ds), ds
    return as_recording(dataset), None


def compare(dataset: Any, *, dt: float = 1e-3) -> CompareResult:
    """Residuals of the stored model against the measured streams (nothing is refitted)."""
    rec, _ = _open(dataset)
    return compare_recording(rec, dt=dt)


def diagnose(
    dataset: Any,
    *,
    effects: Sequence[str] | None = None,
    progress: Callable[[int, int], None] | None = None,
    dt: float = 1e-3,
) -> DiagnoseResult:
    """Rank candidate effects (see :mod:`reference_impl.physics.diagnose`)."""
    rec, _ = _open(dataset)
    return diagnose_recording(rec, effects=effects, progress=progress, dt=dt)


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
            "rms_before_mm": self.rms_before,
            "rms_after_mm": self.rms_after,
            "noise_floor_mm": self.noise_floor,
            "unidentifiable": self.unidentifiable,
            "revision": self.revision,
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
) -> FitResult:
    """Refit the base model (and the effects already present) plus ``add``.

    With a dataset and ``write=True`` the fitted values become a new physics.json revision
    (the previous one is kept in ``physics/history/``; see :func:`revert`). Parameters found
    unidentifiable are reported in ``unidentifiable`` and are not written.
    """
    rec, ds = _open(dataset)
    eng = Engine(rec, dt=dt)
    res = _fit_engine(eng, add)
    if res.unidentifiable:
        bad = set(res.unidentifiable)
        res.physics["effects"] = [
            e
            for e in res.physics["effects"]
            if not any(f"{e['name']}.{k}" in bad for k in e["params"])
        ]
    if ds is not None and write:
        with ds.edit() as w:
            res.revision = w.set_physics(
                res.physics, note=note or f"fit: added {', '.join(add) or 'nothing'}"
            )
            w.commit()
    return res


def report(
    dataset: Any, out_html: str | Path, *, add: Sequence[str] = (), dt: float = 1e-3
) -> Path:
    """Write an HTML report of residuals before (stored physics) and after refitting with ``add``.

    Plots are inline SVG (matplotlib is not required).
    """
    rec, _ = _open(dataset)
    eng = Engine(rec, dt=dt)
    res = _fit_engine(eng, add)
    before, after = res.compare_before, res.compare_after
    if before is None or after is None:  # pragma: no cover - _fit_engine always fills them
        raise RuntimeError("comparison missing")
    rows = [(p.name, p.value, p.low, p.high, p.unit) for p in res.params]
    return render_report(
        before, after, out_html, title="robogs physics report", added=list(add), params=rows
    )


def revert(dataset: Any, revision: int) -> int:
    """Make an earlier physics.json revision current again (as a new revision); returns it."""
    import json

    from robogs_format.dataset import Dataset

    ds = dataset if isinstance(dataset, Dataset) else Dataset.open(Path(dataset))
    if revision not in ds.physics_history():
        raise InputError(
            f"no physics revision {revision}",
            path=ds.resolve("physics.json"),
            where="physics/history",
            hint=f"kept revisions: {ds.physics_history()}",
        )
    old = json.loads(ds.resolve(f"physics/history/rev-{revision:04d}.json").read_text())
    with ds.edit() as w:
        rev = w.set_physics(old, note=f"revert to revision {revision}")
        w.commit()
    return rev

"""The one "before" and "after" of the physics loop: a physics revision, refitted.

``compare``, ``diagnose``, ``fit``, ``report``, the HTML report and ``robogs demo`` all measure
a model with :func:`baseline`: the base parameters and the effects already in a physics
revision are refitted together with every trajectory's nuisance parameters (its initial pose
correction dx, dy [m], dyaw [rad]), starting from the stored values. "Before" a fit is the
baseline of the revision fitted from; "after" is the baseline of the revision the fit writes
(or would write, on a dry run). Same function, same inputs, same numbers: a before or an after
printed by one command is the one every other command prints.

Why refit rather than evaluate the stored values: the nuisance parameters are never stored, and
evaluating them at zero charges the model for the noise of the first pose samples (on the demo
scenario that was 4.69 mm "before" against 1.81 mm for the same revision refitted), while the
stored base parameters may be priors. :func:`diagnose` scores candidates against the same
refitted base model.

Results are memoised per process on the recording's samples and the revision's model content
(``revision``, ``parent_revision``, ``note`` and ``fit`` do not change the model), so the demo's
compare, diagnose, fit and report fit each revision once.
"""

from __future__ import annotations

import hashlib
import json
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from robogs.physics.compare import CompareResult, residual_table
from robogs.physics.diagnose import ParamEstimate
from robogs.physics.engine import Engine
from robogs.physics.fit import FitOutcome, Problem
from robogs.physics.recording import Recording
from robogs.physics.space import ParamSpace

__all__ = ["Baseline", "baseline", "fit_baseline", "model_key", "NON_MODEL_KEYS"]

#: physics.json keys that record history, not the model
NON_MODEL_KEYS = ("revision", "parent_revision", "note", "fit")

_CACHE: OrderedDict[tuple[str, str, float], Baseline] = OrderedDict()
_CACHE_SIZE = 8


@dataclass
class Baseline:
    """A physics revision refitted to a recording.

    Attributes:
        revision: the revision's number (None for an unwritten document).
        physics: the physics.json document whose model this is.
        space: its parameter space (base parameters and present effects).
        free: the refitted columns of ``space``.
        outcome: the fit (``theta`` [Q], ``local`` [T, 3] nuisance parameters, intervals).
        result: residual table of the fitted model (mm, deg; phases, worst segments).
    """

    revision: int | None
    physics: dict[str, Any]
    space: ParamSpace
    free: list[int]
    outcome: FitOutcome
    result: CompareResult

    @property
    def rms_mm(self) -> float:
        """Object position RMS [mm] of the refitted model."""
        return self.result.rms_mm

    def params(self) -> list[ParamEstimate]:
        """Refitted parameters with 95 % intervals (infinite where unidentifiable)."""
        out = []
        for j, c in enumerate(self.free):
            s = self.space.slots[c]
            v, sd = float(self.outcome.theta[c]), float(self.outcome.std[j])
            out.append(ParamEstimate(s.key, v, v - 1.96 * sd, v + 1.96 * sd, s.param.unit))
        return out

    def to_dict(self) -> dict[str, Any]:
        """What identifies the baseline in JSON output."""
        return {
            "revision": self.revision,
            "refitted": "base parameters and present effects, with per-trajectory initial pose",
            "rms_mm": self.result.rms_mm,
            "effects": [e.get("name") for e in self.physics.get("effects", []) or []],
        }


def model_key(physics: dict[str, Any]) -> str:
    """Canonical JSON of the model content of a physics.json document."""
    doc = {k: v for k, v in physics.items() if k not in NON_MODEL_KEYS}
    return json.dumps(doc, sort_keys=True, default=float)


def _fingerprint(rec: Recording) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(rec.object_name.encode())
    for tr in rec.trajectories:
        h.update(tr.name.encode())
        for name in ("t_ns", "object_pos", "object_quat", "ee_t_ns", "ee_pos", "ee_quat", "grasp"):
            a = getattr(tr, name, None)
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def fit_baseline(
    eng: Engine, progress: Callable[[int, int], None] | None = None
) -> tuple[ParamSpace, list[int], FitOutcome, CompareResult]:
    """Refit the engine's revision: base columns and nuisance, from the stored values."""
    space = eng.space([])
    free = eng.base_columns(space)
    (out,) = eng.fit(space, [Problem(free=list(free), theta0=eng.start(space))], progress=progress)
    return space, free, out, residual_table(eng, eng.raw(out.resid))


def baseline(
    rec: Recording,
    physics: dict[str, Any] | None = None,
    *,
    dt: float = 1e-3,
    engine: Engine | None = None,
    progress: Callable[[int, int], None] | None = None,
    backend: str | None = None,
) -> Baseline:
    """The refitted model of ``physics`` (default: the recording's own) on ``rec``.

    Args:
        rec: the measured trajectories.
        physics: a physics.json document (an earlier revision, or one about to be written).
        dt: simulation step [s].
        engine: an engine already prepared for ``rec`` with this physics (saves the prepare).
        progress: called with (iteration, unfinished fits) while the fit runs.
        backend: rollout engine (``planar``, ``mujoco``, ``auto``; default: ``engine``'s, else
            planar).
    """
    doc = rec.physics if physics is None else physics
    if backend is None:
        backend = getattr(engine, "backend", "planar")
    key = (_fingerprint(rec), model_key(doc), float(dt), backend)
    rev = doc.get("revision")
    rev = int(rev) if isinstance(rev, int) else None
    hit = _CACHE.get(key)
    if hit is not None:
        _CACHE.move_to_end(key)
        return replace(hit, revision=rev, physics=doc)  # same model, this document's history
    if (
        engine is None
        or model_key(engine.prep.rec.physics) != key[1]
        or getattr(engine, "backend", "planar") != backend
    ):
        engine = Engine(
            rec if physics is None else replace(rec, physics=doc), dt=dt, backend=backend
        )
    space, free, out, res = fit_baseline(engine, progress)
    bl = Baseline(rev, doc, space, free, out, res)
    _CACHE[key] = bl
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return bl

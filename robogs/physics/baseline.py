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
compare, diagnose, fit and report fit each revision once; and on disk, so that separate
commands (``diagnose`` then ``fit`` then ``report``) fit it once too:
``$ROBOGS_CACHE_DIR/baseline/<key>.npz`` (default ``$XDG_CACHE_HOME/robogs`` or
``~/.cache/robogs``, as the gate's calibrations), the key also holding a hash of the physics
package's source, so a changed model never reads an old fit. Only arrays and JSON are stored
(``allow_pickle=False``); an unreadable entry is refitted and rewritten.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.physics.compare import CompareResult, residual_table
from robogs.physics.diagnose import ParamEstimate
from robogs.physics.engine import Engine
from robogs.physics.fit import FitOutcome, Problem
from robogs.physics.prepare import force_rms
from robogs.physics.recording import Recording
from robogs.physics.residuals import tracked_streams
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


_SAMPLES = (
    "t_ns",
    "object_pos",
    "object_quat",
    "ee_t_ns",
    "ee_pos",
    "ee_quat",
    "grasp",
    "wrench_t_ns",
    "wrench_force",
)
"""Trajectory arrays a baseline depends on (the wrench too: it enters the residuals in N)."""


def _fingerprint(rec: Recording) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(rec.object_name.encode())
    for tr in rec.trajectories:
        h.update(tr.name.encode())
        for name in _SAMPLES:
            a = getattr(tr, name, None)
            h.update(name.encode() + (b"-" if a is None else np.ascontiguousarray(a).tobytes()))
        for name, track in sorted((getattr(tr, "others", None) or {}).items()):
            h.update(name.encode() + b"".join(np.ascontiguousarray(a).tobytes() for a in track))
    for name, mesh in sorted((getattr(rec, "meshes", None) or {}).items()):  # shapes MuJoCo gets
        h.update(name.encode())
        for a in (mesh.vertices, mesh.faces):
            h.update(np.ascontiguousarray(a).tobytes())
    rp = getattr(rec, "robot_pusher", None)  # the robot's collision links (geometry "robot")
    if rp is not None:
        h.update(Path(rp.urdf).read_bytes() + rp.link.encode())
        for name, T in sorted(rp.frames.items()):
            h.update(name.encode() + np.ascontiguousarray(T).tobytes())
        # its servo DOFs (moving fingers, tilt) and their recorded values; nothing without them
        h.update(",".join(getattr(rp, "dofs", [])).encode())
        for tr in rec.trajectories:
            if getattr(tr, "pusher_dofs", None) is not None:
                h.update(np.ascontiguousarray(tr.pusher_dofs).tobytes())
    return h.hexdigest()


def _disk_path(key: tuple[str, str, float, str]) -> Path:
    from robogs.physics.gate import cache_dir, code_hash

    h = hashlib.blake2b(digest_size=20)
    h.update(json.dumps([*key, code_hash()]).encode())
    return cache_dir().parent / "baseline" / f"{h.hexdigest()}.npz"


_ARRAYS = ("theta", "local", "resid", "jac", "jac_local", "std", "cov", "ok")


def _load(path: Path) -> FitOutcome | None:
    """A cached fit outcome (None when absent or unreadable)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            arrays = {k: np.array(z[k]) for k in _ARRAYS}
        return FitOutcome(**arrays, **meta)
    except (OSError, KeyError, ValueError, TypeError):
        return None


def _save(path: Path, out: FitOutcome) -> None:
    """Write ``out`` atomically (a failure to write only costs a refit next time)."""
    meta = {f.name: getattr(out, f.name) for f in fields(out) if f.name not in _ARRAYS}
    meta = {k: (float(v) if isinstance(v, np.floating) else v) for k, v in meta.items()}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
        np.savez(tmp, meta=np.array(json.dumps(meta, default=float)),
                 **{k: getattr(out, k) for k in _ARRAYS})  # fmt: skip
        os.replace(tmp, path)
    except OSError:
        return


def fit_baseline(
    eng: Engine, progress: Callable[[int, int], None] | None = None
) -> tuple[ParamSpace, list[int], FitOutcome, CompareResult]:
    """Refit the engine's revision: base columns and nuisance, from the stored values."""
    space = eng.space([])
    free = eng.base_columns(space)
    (out,) = eng.fit(space, [Problem(free=list(free), theta0=eng.start(space))], progress=progress)
    return space, free, out, _table(eng, out)


def _table(eng: Engine, out: FitOutcome) -> CompareResult:
    """Residual table of a fit: poses (mm, deg) and, where a wrench is used, force (N)."""
    res = residual_table(eng, eng.raw(out.resid))
    res.streams += tracked_streams(eng.prep, out.resid)  # other tracked objects, per trajectory
    res.force = force_rms(eng.prep, out.resid)
    res.wrench_note = eng.prep.wrench_note
    if res.force is None and eng.prep.wrench is not None:
        res.wrench_note = f"wrench not used: the {eng.backend} engine predicts no pusher force"
    return res


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
    path = _disk_path(key)
    out = _load(path)
    if out is not None:
        space = engine.space([])
        free = engine.base_columns(space)
        res = _table(engine, out)
    else:
        space, free, out, res = fit_baseline(engine, progress)
        _save(path, out)
    bl = Baseline(rev, doc, space, free, out, res)
    _CACHE[key] = bl
    while len(_CACHE) > _CACHE_SIZE:
        _CACHE.popitem(last=False)
    return bl

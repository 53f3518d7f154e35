"""Reuse a diagnosis's candidate fits between tests that diagnose the same recording (h57).

``diagnose_recording`` spends most of its time in two deterministic steps that depend only on
the engine (backend, recording samples, model, time step) and their array inputs: the nested
candidate fits (:func:`robogs.physics.fit.fit_nested`, called with the memoised baseline as
``base_fit``) and the held-out rollouts (:func:`robogs.physics.heldout.heldout_rollouts`).
Tests that diagnose one recording under several gate settings (the gate's nuisance columns,
``partial``) recompute both for nothing. :func:`memoise_fits` wraps the two names in
``robogs.physics.diagnose`` so that a call whose key matches an earlier one gets a deep copy of
that call's result. The key is the engine (backend, the baseline's data fingerprint and model
key, time step) and a hash of every array and list the call receives, so a call with any
different input is computed afresh. Fits of the gate's null draws (``fit_nested`` without
``base_fit``: their residual carries an offset the key cannot see) are never memoised.
The gate's smooth start-pose columns (:func:`robogs.physics.roughness.stencil_columns`, h48/h99:
one batched rollout per fit, the same for every gate setting that uses them) are memoised the
same way, keyed by the residual function's engine and space and the point; a null draw's
residual function (an offset added) is never memoised.

Under pytest-xdist two tests of one module may run in different workers; each then computes
its own fits, as without the memo (the memo only saves, it never changes what is computed).
"""

from __future__ import annotations

import copy
import hashlib
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from robogs.physics import diagnose as D
from robogs.physics import roughness as R
from robogs.physics.baseline import _fingerprint, model_key

__all__ = ["memoise_fits"]


def _engine_key(eng: Any) -> tuple:
    prep = eng.prep
    return (eng.backend, _fingerprint(prep.rec), model_key(prep.rec.physics), prep.scene.dt)


def _digest(*parts: Any) -> str:
    """blake2b of arrays (dtype, shape, bytes), numbers, strings and nested sequences."""
    h = hashlib.blake2b(digest_size=20)

    def put(x: Any) -> None:
        if x is None:
            h.update(b"N")
        elif isinstance(x, np.ndarray):
            a = np.ascontiguousarray(x)
            h.update(f"A{a.dtype.str}{a.shape}".encode() + a.tobytes())
        elif isinstance(x, (list, tuple)):
            h.update(f"L{len(x)}".encode())
            for y in x:
                put(y)
        elif isinstance(x, (bool, int, float, str, np.generic)):
            h.update(f"S{type(x).__name__}:{x!r}".encode())
        else:
            raise TypeError(f"fit_memo cannot key a {type(x).__name__}")

    for p in parts:
        put(p)
    return h.hexdigest()


def _residual_key(fn: Any) -> list | None:
    """The key of a residual function ``Engine.residual_fn`` made (planar: the closure of
    :func:`robogs.physics.residuals.residual_fn`; MuJoCo: the engine's, holding ``sim``): its
    recording, model, time step, backend and parameter space. None for any other function,
    e.g. the gate's null-draw residual (``fn + offset``)."""
    names = set(inspect.getclosurevars(fn).nonlocals)
    if getattr(fn, "__qualname__", "") not in (
        "residual_fn.<locals>.fn",
        "Engine.residual_fn.<locals>.fn",
    ):
        return None
    if not {"prep", "space"} <= names or names - {"prep", "space", "sim"}:
        return None
    free = inspect.getclosurevars(fn).nonlocals
    prep, backend = free["prep"], type(free.get("sim")).__name__
    keys = [_fingerprint(prep.rec), model_key(prep.rec.physics), prep.scene.dt, backend]
    return [*keys, _space_key(free["space"])]


def _space_key(space: Any) -> list:
    return [(s.owner, s.param.name) for s in space.slots]


def _out_key(o: Any) -> list:
    return [o.theta, o.local, o.resid, float(o.cost)]


def memoise_fits(monkeypatch: pytest.MonkeyPatch, store: dict[str, Any]) -> dict[str, int]:
    """Route ``diagnose``'s candidate fits and held-out rollouts through ``store``.

    Returns a counter ``{"hits": n, "misses": m}`` that the caller may inspect."""
    count = {"hits": 0, "misses": 0}
    real_nested, real_held, real_stencil = D.fit_nested, D.heldout_rollouts, R.stencil_columns

    def cached(key: str, compute: Callable[[], Any]) -> Any:
        if key in store:
            count["hits"] += 1
        else:
            count["misses"] += 1
            store[key] = compute()
        return copy.deepcopy(store[key])

    def fit_nested(fit, evaluate, space, base, candidates, *, base_fit=None, **kw):
        eng = inspect.getclosurevars(fit).nonlocals.get("eng")
        if base_fit is None or eng is None:  # a null draw's fit, or a caller we do not know
            return real_nested(fit, evaluate, space, base, candidates, base_fit=base_fit, **kw)
        key = _digest(
            "fit_nested",
            list(_engine_key(eng)),
            _space_key(space),
            [list(base.free), base.traj, base.theta0, bool(base.fit_local), base.local0],
            [[list(cols), list(starts)] for cols, starts in candidates],
            _out_key(base_fit),
            sorted((k, v) for k, v in kw.items()),
        )
        return cached(
            key,
            lambda: real_nested(fit, evaluate, space, base, candidates, base_fit=base_fit, **kw),
        )

    def heldout_rollouts(eng, space, outs, frees, folds, *args, **kw):
        key = _digest(
            "heldout_rollouts",
            list(_engine_key(eng)),
            _space_key(space),
            [_out_key(o) for o in outs],
            [list(f) for f in frees],
            list(folds),
            list(args),
            sorted((k, v) for k, v in kw.items()),
        )
        return cached(key, lambda: real_held(eng, space, outs, frees, folds, *args, **kw))

    def stencil_columns(fn, theta, local, *, local_h=None, stencils=R.STENCILS):
        known = _residual_key(fn)
        if known is None:  # a null draw's residual (an offset added) or one we do not know
            return real_stencil(fn, theta, local, local_h=local_h, stencils=stencils)
        key = _digest("stencil_columns", known, theta, local, local_h, list(stencils))
        return cached(
            key, lambda: real_stencil(fn, theta, local, local_h=local_h, stencils=stencils)
        )

    monkeypatch.setattr(D, "fit_nested", fit_nested)
    monkeypatch.setattr(D, "heldout_rollouts", heldout_rollouts)
    monkeypatch.setattr(R, "stencil_columns", stencil_columns)
    return count

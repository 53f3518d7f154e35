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


def _space_key(space: Any) -> list:
    return [(s.owner, s.param.name) for s in space.slots]


def _out_key(o: Any) -> list:
    return [o.theta, o.local, o.resid, float(o.cost)]


def memoise_fits(monkeypatch: pytest.MonkeyPatch, store: dict[str, Any]) -> dict[str, int]:
    """Route ``diagnose``'s candidate fits and held-out rollouts through ``store``.

    Returns a counter ``{"hits": n, "misses": m}`` that the caller may inspect."""
    count = {"hits": 0, "misses": 0}
    real_nested, real_held = D.fit_nested, D.heldout_rollouts

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

    monkeypatch.setattr(D, "fit_nested", fit_nested)
    monkeypatch.setattr(D, "heldout_rollouts", heldout_rollouts)
    return count

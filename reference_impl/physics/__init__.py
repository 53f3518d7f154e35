"""Model-versus-measurement engine for rigid objects: simulate, compare, diagnose, fit, report.

The user-facing functions live in :mod:`reference_impl.physics.api` (``compare``,
``diagnose``, ``fit_dataset``, ``report``, ``revert``); the registry of effects in
:mod:`reference_impl.physics.effects`. Submodules are imported lazily.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "register_effect",
    "available_effects",
    "get_effect",
    "Effect",
    "Param",
    "load_recording",
]

_LAZY = {
    "load_recording": "reference_impl.physics.recording",
    "register_effect": "reference_impl.physics.effects",
    "available_effects": "reference_impl.physics.effects",
    "get_effect": "reference_impl.physics.effects",
    "Effect": "reference_impl.physics.effects",
    "Param": "reference_impl.physics.effects",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(name)

"""Model-versus-measurement engine for rigid objects: simulate, compare, diagnose, fit, report.

The user-facing functions live in :mod:`robogs.physics.api` (``compare``,
``diagnose``, ``fit_dataset``, ``report``, ``revert``); the registry of effects in
:mod:`robogs.physics.effects`. Submodules are imported lazily.
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
    "load_recording": "robogs.physics.recording",
    "register_effect": "robogs.physics.effects",
    "available_effects": "robogs.physics.effects",
    "get_effect": "robogs.physics.effects",
    "Effect": "robogs.physics.effects",
    "Param": "robogs.physics.effects",
}


# PEP 562 lazy names; physics/arm/__init__.py has the same few lines for its own table by design.
def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(name)

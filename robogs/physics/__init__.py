"""Model-versus-measurement engine for rigid objects: simulate, compare, diagnose, fit, report.

The user-facing functions live in :mod:`robogs.physics.api` (``compare``,
``diagnose``, ``fit_dataset``, ``report``, ``revert``); the registry of effects in
:mod:`robogs.physics.effects`. Submodules are imported lazily.
"""

from __future__ import annotations

from robogs._lazy import lazy_getattr

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


__getattr__ = lazy_getattr(__name__, _LAZY)

"""Model-versus-measurement engine for rigid objects: simulate, compare, diagnose, fit, report.

The public entry points are imported lazily so that ``import reference_impl.physics`` stays
cheap; see :mod:`reference_impl.physics.api`.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "compare",
    "diagnose",
    "fit",
    "report",
    "revert",
    "load_recording",
    "register_effect",
    "available_effects",
    "get_effect",
    "Effect",
    "Param",
]

_LAZY = {
    "compare": "reference_impl.physics.api",
    "diagnose": "reference_impl.physics.api",
    "fit": "reference_impl.physics.api",
    "report": "reference_impl.physics.api",
    "revert": "reference_impl.physics.api",
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

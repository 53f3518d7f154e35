"""Validation checks: a registry of stable codes, grouped as in ``spec/CHECKS.md``.

Built-in groups live in one module each (``schema``, ``integrity``, ``timing``,
``geometry``, ``physics``, ``binding``); :func:`available_checks` imports them
and the ``robogs.checks`` entry points. See :mod:`robogs.format.checks.registry`
for adding a check and :func:`robogs.format.validate.validate` for running them.
"""

from .context import CheckContext, InputReported
from .registry import (
    BUILTIN_MODULES,
    ENTRY_POINT_GROUP,
    GROUPS,
    RETIRED_CODES,
    Check,
    available_checks,
    check,
    get_check,
    plugin_errors,
    register_check,
    unregister_check,
)

__all__ = [
    "BUILTIN_MODULES",
    "ENTRY_POINT_GROUP",
    "GROUPS",
    "RETIRED_CODES",
    "Check",
    "CheckContext",
    "InputReported",
    "available_checks",
    "check",
    "get_check",
    "plugin_errors",
    "register_check",
    "unregister_check",
]

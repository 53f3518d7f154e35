"""The check registry: stable codes, groups, severities, and plug-ins by entry point.

A check is a frozen :class:`Check` record (configuration only) whose ``fn``
yields :class:`~robogs.format.findings.Finding` records for a
:class:`~robogs.format.checks.context.CheckContext`. Built-in checks live in the
modules of this package; users add their own without editing robogs, through
the entry-point group ``robogs.checks`` (an entry point may name a module that
registers checks when imported, a :class:`Check`, an iterable of them, or a
function returning them).

Example:
    >>> from robogs.format.checks import check
    >>> @check("Z901", group="geometry", severity="warning", title="my lab's rule")
    ... def _my_rule(chk, ctx):                                   # doctest: +SKIP
    ...     yield chk.finding("something is off", value=3.0, budget=1.0, unit="mm")
"""

from __future__ import annotations

import importlib
import importlib.util
import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any

from ..findings import Finding, Location, Severity, severity_rank

if TYPE_CHECKING:
    from .context import CheckContext

__all__ = [
    "Check",
    "CheckFn",
    "GROUPS",
    "RETIRED_CODES",
    "ENTRY_POINT_GROUP",
    "BUILTIN_MODULES",
    "check",
    "register_check",
    "unregister_check",
    "available_checks",
    "get_check",
    "plugin_errors",
]

#: check groups, in the order they run and are reported
GROUPS: tuple[str, ...] = ("schema", "integrity", "time", "geometry", "binding", "physics")

#: codes that were used once and must never be given to another check
RETIRED_CODES: frozenset[str] = frozenset()

ENTRY_POINT_GROUP = "robogs.checks"

#: modules of this package that define built-in checks (a missing one is skipped,
#: so a new group such as ``binding`` is added by creating its module)
BUILTIN_MODULES: tuple[str, ...] = (
    "schema",
    "integrity",
    "timing",
    "sync",
    "geometry",
    "physics",
    "binding",
)

_CODE = re.compile(r"^[A-Z][0-9]{3}$")

CheckFn = Callable[["Check", "CheckContext"], Iterable[Finding]]


@dataclass(frozen=True)
class Check:
    """One validation check.

    Attributes:
        code: stable, unique code (a capital letter and three digits, e.g. ``T003``).
        group: one of :data:`GROUPS` (plug-ins may use their own group name).
        severity: default severity of its findings.
        title: short title, as listed in ``spec/CHECKS.md``.
        fn: ``fn(check, ctx)`` yielding findings (use :meth:`finding` to build them).
        needs_full: False if the check reads only the manifest and parquet footers
            (those run under ``--quick``).
        needs_valid_manifest: skip the check when the manifest does not follow its schema.
        quantity: what is measured, e.g. ``largest gap``.
        unit: unit of the measured value.
        budget: name of the budget it is compared with (see ``robogs.format.budgets``).
        hint: default fix hint.
    """

    code: str
    group: str
    severity: Severity
    title: str
    fn: CheckFn
    needs_full: bool = True
    needs_valid_manifest: bool = True
    quantity: str = ""
    unit: str = ""
    budget: str = ""
    hint: str = ""

    def run(self, ctx: CheckContext) -> Iterator[Finding]:
        """Run the check on a context, yielding its findings."""
        yield from self.fn(self, ctx)

    def finding(
        self,
        message: str,
        *,
        location: Location | None = None,
        value: float | None = None,
        budget: float | None = None,
        unit: str | None = None,
        hint: str | None = None,
        severity: Severity | None = None,
        **where: Any,
    ) -> Finding:
        """A finding of this check; defaults come from the check's record.

        Extra keyword arguments (``file=``, ``episode=``, ``t_ns=``...) build the
        :class:`Location` when ``location`` is not given.
        """
        if location is None:
            location = Location(**where)
        elif where:
            raise TypeError("pass either location= or location fields, not both")
        return Finding(
            code=self.code,
            severity=severity or self.severity,
            message=message,
            location=location,
            value=None if value is None else float(value),
            budget=None if budget is None else float(budget),
            unit=self.unit if unit is None else unit,
            hint=self.hint if hint is None else hint,
        )


_REGISTRY: dict[str, Check] = {}
_LOADED = False
_PLUGIN_ERRORS: list[str] = []


def register_check(chk: Check, *, replace: bool = False) -> Check:
    """Add a check to the registry.

    Raises:
        ValueError: malformed or retired code, unknown severity, or a code already
            registered by another check (unless ``replace``).
    """
    if not _CODE.match(chk.code):
        raise ValueError(f"check code {chk.code!r} must be a capital letter and three digits")
    if chk.code in RETIRED_CODES:
        raise ValueError(f"check code {chk.code} is retired and cannot be reused")
    severity_rank(chk.severity)
    if not chk.title:
        raise ValueError(f"check {chk.code} needs a title")
    old = _REGISTRY.get(chk.code)
    if old is not None and not replace and old.fn is not chk.fn:
        raise ValueError(f"check code {chk.code} is already registered ({old.title!r})")
    _REGISTRY[chk.code] = chk
    return chk


def unregister_check(code: str) -> None:
    """Remove a check (tests and plug-ins that replace a built-in)."""
    _REGISTRY.pop(code, None)


def check(
    code: str,
    *,
    group: str,
    severity: Severity,
    title: str,
    needs_full: bool = True,
    needs_valid_manifest: bool = True,
    quantity: str = "",
    unit: str = "",
    budget: str = "",
    hint: str = "",
) -> Callable[[CheckFn], CheckFn]:
    """Decorator registering ``fn(check, ctx)`` as a :class:`Check`."""

    def deco(fn: CheckFn) -> CheckFn:
        register_check(
            Check(
                code=code,
                group=group,
                severity=severity,
                title=title,
                fn=fn,
                needs_full=needs_full,
                needs_valid_manifest=needs_valid_manifest,
                quantity=quantity,
                unit=unit,
                budget=budget,
                hint=hint,
            )
        )
        return fn

    return deco


def _register_loaded(obj: Any, name: str) -> None:
    if isinstance(obj, Check):
        register_check(obj)
    elif isinstance(obj, type(importlib)):
        return  # a module: importing it registered its checks
    elif callable(obj):
        _register_loaded(obj(), name)
    elif isinstance(obj, Iterable):
        for item in obj:
            if not isinstance(item, Check):
                raise TypeError(f"entry point {name!r} yielded {type(item).__name__}, not Check")
            register_check(item)
    else:
        raise TypeError(f"entry point {name!r} is a {type(obj).__name__}, not a module or Check")


def _load_all() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    for mod in BUILTIN_MODULES:
        full = f"{__package__}.{mod}"
        if importlib.util.find_spec(full) is not None:
            importlib.import_module(full)
    try:
        eps = entry_points(group=ENTRY_POINT_GROUP)
    except Exception as exc:  # broken distribution metadata must not stop validation
        _PLUGIN_ERRORS.append(f"listing entry points failed: {exc}")
        return
    for ep in eps:
        try:
            _register_loaded(ep.load(), ep.name)
        except Exception as exc:  # a broken plug-in is reported, never fatal
            _PLUGIN_ERRORS.append(
                f"check plug-in {ep.name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}"
            )


def _order(chk: Check) -> tuple[int, str]:
    rank = GROUPS.index(chk.group) if chk.group in GROUPS else len(GROUPS)
    return rank, chk.code


def available_checks() -> list[Check]:
    """Every registered check (built-in and plug-in), in run order (group, then code)."""
    _load_all()
    return sorted(_REGISTRY.values(), key=_order)


def get_check(code: str) -> Check:
    """The check registered under ``code``.

    Raises:
        KeyError: no such code.
    """
    _load_all()
    return _REGISTRY[code]


def plugin_errors() -> list[str]:
    """Messages of check plug-ins that failed to load (reported as findings by the runner)."""
    _load_all()
    return list(_PLUGIN_ERRORS)

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

import re
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

from ..findings import Finding, Location, Severity, severity_rank
from ..plugins import ENTRY_POINT_GROUPS, Entry, RegistrationError, Registry

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
    "check_entries",
    "get_check",
    "REGISTRY",
    "plugin_errors",
]

#: check groups, in the order they run and are reported
GROUPS: tuple[str, ...] = ("schema", "integrity", "time", "geometry", "binding", "physics")

#: codes that were used once and must never be given to another check
RETIRED_CODES: frozenset[str] = frozenset()

ENTRY_POINT_GROUP = ENTRY_POINT_GROUPS["checks"]

#: modules of this package that define built-in checks (a missing one is skipped,
#: so a new group such as ``binding`` is added by creating its module)
BUILTIN_MODULES: tuple[str, ...] = (
    "schema",
    "integrity",
    "timing",
    "sync",
    "lag_pairs",
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


def _adopt(reg: Registry[Check], name: str, obj: Any) -> None:
    """Register what a ``robogs.checks`` entry point loaded (see the module docstring)."""
    if isinstance(obj, Check):
        register_check(obj)
    elif isinstance(obj, ModuleType):
        return  # importing it registered its checks
    elif callable(obj):
        _adopt(reg, name, obj())
    elif isinstance(obj, Iterable):
        for item in obj:
            if not isinstance(item, Check):
                raise TypeError(f"entry point {name!r} yielded {type(item).__name__}, not Check")
            register_check(item)
    else:
        raise TypeError(f"entry point {name!r} is a {type(obj).__name__}, not a module or Check")


def _order(entry: Entry[Check]) -> tuple[int, str]:
    group = entry.obj.group if entry.obj is not None else ""
    rank = GROUPS.index(group) if group in GROUPS else len(GROUPS) + (entry.obj is None)
    return rank, entry.name


#: the check registry (keys: check codes; a broken plug-in is listed under its entry-point name)
REGISTRY: Registry[Check] = Registry(
    "checks",
    ENTRY_POINT_GROUP,
    noun="check",
    builtins=tuple(f"{__package__}.{m}" for m in BUILTIN_MODULES),
    adopt=_adopt,
    order=_order,
    module_of=lambda c: c.fn.__module__,
    unknown_where="--select",
)


def register_check(chk: Check, *, replace: bool = False) -> Check:
    """Add a check to the registry.

    Raises:
        RegistrationError: malformed or retired code, unknown severity, or a code already
            registered by another check (unless ``replace``); also a ``ValueError``.
    """
    if not _CODE.match(chk.code):
        raise RegistrationError(
            f"check code {chk.code!r} must be a capital letter and three digits"
        )
    if chk.code in RETIRED_CODES:
        raise RegistrationError(f"check code {chk.code} is retired and cannot be reused")
    try:
        severity_rank(chk.severity)
    except ValueError as exc:
        raise RegistrationError(f"check {chk.code}: {exc}") from None
    if not chk.title:
        raise RegistrationError(f"check {chk.code} needs a title")
    return REGISTRY.register(chk.code, chk, replace=replace)


def unregister_check(code: str) -> None:
    """Remove a check (tests and plug-ins that replace a built-in)."""
    REGISTRY.unregister(code)


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
        # A keyword pass-through: alike other keyword lists (render/projection) in shape only.
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


def available_checks() -> dict[str, Check]:
    """``code -> Check`` of every usable check (built-in and plug-in), in run order
    (group, then code); :func:`check_entries` also lists the unavailable plug-ins."""
    return REGISTRY.available()


def check_entries() -> list[Entry[Check]]:
    """Every entry of the check registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


def get_check(code: str) -> Check:
    """The check registered under ``code``.

    Raises:
        InputError: no such code.
        PluginError: the plug-in of that name failed to load.
    """
    return REGISTRY.get(code)


def plugin_errors() -> list[str]:
    """One message per check plug-in that failed to load (reported as ``X004`` findings)."""
    return [
        f"check plug-in {e.name!r} from {e.source} is unavailable: {e.reason}"
        for e in REGISTRY.entries()
        if not e.ok
    ]

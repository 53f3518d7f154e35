"""Run the registered checks on a dataset and collect a :class:`Report`.

Example:
    >>> from robogs.format.validate import validate
    >>> report = validate("scene/", quick=True)          # doctest: +SKIP
    >>> report.failed("error")                            # doctest: +SKIP
    False

The runner never lets a check crash the validation: an unexpected exception
inside a check becomes an ``X001`` finding naming the check; a ``RobogsError``
becomes an ``X002`` finding with its file, place and hint (unless that file
already has a finding of its own). Checks that need a schema-valid manifest are
skipped, with one ``X003`` note, when the manifest is not.

Check modules may offer two hooks, found by name on the module of a check's function:
``expected_seconds(code, ctx) -> float | None`` (a check's rough cost, which weights the
progress bar and its ETA; default :data:`DEFAULT_CHECK_SECONDS`) and ``run_notes(ctx) ->
list[str]`` (what a check left out of this run, e.g. frames a re-render skipped to keep its
time budget; shown with the report as ``Report.notes``).
"""

from __future__ import annotations

import sys
import time
import traceback
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .checks.context import CheckContext, InputReported
from .checks.registry import GROUPS, Check, available_checks, plugin_errors
from .errors import FormatError, RobogsError
from .findings import Finding, Location, severity_rank
from .spec_version import SPEC_VERSION

__all__ = [
    "validate",
    "Report",
    "CheckRun",
    "RUNNER_CODES",
    "select_checks",
    "DEFAULT_MAX_PER_CODE",
    "DEFAULT_CHECK_SECONDS",
    "Progress",
]

#: codes the runner itself emits (not checks): code -> (severity, title)
RUNNER_CODES: dict[str, tuple[str, str]] = {
    "X001": ("error", "a check crashed (internal error)"),
    "X002": ("error", "a check could not read its input"),
    "X003": ("info", "checks skipped because the manifest does not follow the schema"),
    "X004": ("warning", "a check plug-in failed to load"),
}

#: findings kept per code (the rest are counted in the summary)
DEFAULT_MAX_PER_CODE = 50
#: expected wall time of a check without an ``expected_seconds`` hook, s (progress weights only)
DEFAULT_CHECK_SECONDS = 0.1


@dataclass
class CheckRun:
    """How one check went: ``ran``, ``skipped`` (input reported elsewhere or manifest invalid) or ``crashed``."""

    code: str
    group: str
    title: str
    status: str
    seconds: float = 0.0
    findings: int = 0


@dataclass
class Report:
    """The result of a validation.

    Attributes:
        dataset: the folder validated.
        findings: kept findings, most severe first, then by code.
        runs: one record per selected check.
        quick: whether only manifest and footers were read.
        budgets: the budget values used.
        dropped: per code, findings not kept (over the per-code cap).
        seconds: wall time of the run.
        notes: what checks left out of this run and why (e.g. re-rendered frames skipped to
            stay within the time budget), one sentence each.
    """

    dataset: str
    findings: list[Finding]
    runs: list[CheckRun]
    quick: bool
    budgets: dict[str, float]
    dropped: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    def counts(self) -> dict[str, int]:
        """Number of findings per severity (including dropped ones)."""
        c = Counter(f.severity for f in self.findings)
        for code, n in self.dropped.items():
            sev = next((f.severity for f in self.findings if f.code == code), "error")
            c[sev] += n
        return {s: int(c.get(s, 0)) for s in ("error", "warning", "info")}

    def codes(self, *, min_severity: str = "info") -> set[str]:
        """Codes of the findings at or above ``min_severity``."""
        rank = severity_rank(min_severity)
        return {f.code for f in self.findings if severity_rank(f.severity) <= rank}

    def failed(self, fail_on: str = "error") -> bool:
        """True when a finding is at or above ``fail_on`` (``never`` never fails)."""
        if fail_on == "never":
            return False
        rank = severity_rank(fail_on)
        return any(severity_rank(f.severity) <= rank for f in self.findings)

    def groups(self) -> dict[str, dict[str, int]]:
        """Per group: checks run and skipped, errors, warnings, infos."""
        out: dict[str, dict[str, int]] = {}
        by_code = {r.code: r.group for r in self.runs}
        for r in self.runs:
            g = out.setdefault(
                r.group, {"checks": 0, "skipped": 0, "error": 0, "warning": 0, "info": 0}
            )
            g["checks" if r.status != "skipped" else "skipped"] += 1
        for f in self.findings:
            grp = by_code.get(f.code, "runner")
            g = out.setdefault(
                grp, {"checks": 0, "skipped": 0, "error": 0, "warning": 0, "info": 0}
            )
            g[f.severity] += 1
        order = {g: i for i, g in enumerate((*GROUPS, "runner"))}
        return dict(sorted(out.items(), key=lambda kv: order.get(kv[0], len(order))))

    def summary(self) -> dict[str, Any]:
        """Counts and facts for machines (the ``summary`` of the JSON output)."""
        return {
            "dataset": self.dataset,
            "validator_spec_version": SPEC_VERSION,
            "quick": self.quick,
            "counts": self.counts(),
            "checks_run": sum(r.status != "skipped" for r in self.runs),
            "checks_skipped": sorted(r.code for r in self.runs if r.status == "skipped"),
            "groups": self.groups(),
            "dropped": dict(self.dropped),
            "budgets": dict(self.budgets),
            "seconds": round(self.seconds, 3),
            "notes": list(self.notes),
        }

    def to_dict(self) -> dict[str, Any]:
        """``{"findings": [...], "summary": {...}}``."""
        return {"findings": [f.to_dict() for f in self.findings], "summary": self.summary()}


def _matches(chk: Check, selector: str) -> bool:
    s = selector.strip()
    return chk.code.startswith(s.upper()) or s.lower() == chk.group


def select_checks(
    checks: Sequence[Check],
    *,
    select: Iterable[str] | None = None,
    ignore: Iterable[str] | None = None,
    quick: bool = False,
) -> list[Check]:
    """Filter checks by code prefix or group name (``T``, ``T003``, ``time``), and by ``--quick``.

    Raises:
        FormatError: a selector matches no registered check or runner code.
    """
    select = [s for s in (select or []) if s.strip()]
    ignore = [s for s in (ignore or []) if s.strip()]
    for s in (*select, *ignore):
        known_group = s.strip().lower() in GROUPS
        if (
            not known_group
            and not any(_matches(c, s) for c in checks)
            and not any(k.startswith(s.strip().upper()) for k in RUNNER_CODES)
        ):
            raise FormatError(
                f"no check matches {s!r}",
                where="--select/--ignore",
                hint="use codes (T003), prefixes (T) or groups (time); see --list-checks",
            )
    out = []
    for c in checks:
        if select and not any(_matches(c, s) for s in select):
            continue
        if any(_matches(c, s) for s in ignore):
            continue
        if quick and c.needs_full:
            continue
        out.append(c)
    return out


def _code_kept(code: str, selected: set[str], ignore: Sequence[str]) -> bool:
    if code in RUNNER_CODES:
        return not any(code.startswith(s.strip().upper()) for s in ignore)
    return code in selected


def validate(
    path: str | Path,
    *,
    select: Iterable[str] | None = None,
    ignore: Iterable[str] | None = None,
    quick: bool = False,
    budgets: dict[str, float] | None = None,
    progress: bool | Callable[[str, float, float], None] = False,
    max_per_code: int = DEFAULT_MAX_PER_CODE,
    label_threads: int = 2,
    options: dict[str, Any] | None = None,
    runner: Callable[[CheckContext, int], Any] | None = None,
) -> Report:
    """Validate a dataset folder.

    Args:
        path: the dataset root (holding ``manifest.json``).
        select: check codes, code prefixes or group names to run (default: all).
        ignore: check codes, code prefixes or group names to leave out.
        quick: read only the manifest and parquet footers (no hashing, no table bodies).
        budgets: budget overrides, e.g. ``{"geometry.fk_ee_mm": 1.0}``.
        progress: True for a progress bar on stderr (with an ETA), or a callback
            ``(title, done, total)`` where done and total are expected seconds of work.
        max_per_code: findings kept per code; the rest are counted in ``Report.dropped``.
        label_threads: threads decoding label images.
        options: settings for checks that take them (``CheckContext.options``), e.g.
            ``{"stride": 4}``, ``{"full": True}`` or ``{"budget_s": 10.0}`` for the binding
            re-render (which by default subsamples frames to a time budget).
        runner: ``runner(ctx, max_per_code)`` builds the object that runs each check
            (default: in this process); :mod:`robogs.format.distributed` passes one that
            spreads per-episode and per-file checks over workers and replays their findings.

    Returns:
        The :class:`Report`.

    Raises:
        FormatError: the folder or its manifest is unreadable, an unknown budget name
            or a selector that matches nothing (usage errors, exit code 2).
    """
    t0 = time.perf_counter()
    select_l = list(select or [])
    ignore_l = list(ignore or [])
    checks = select_checks(
        list(available_checks().values()), select=select_l, ignore=ignore_l, quick=quick
    )
    ctx = CheckContext(
        path, quick=quick, budgets=budgets, label_threads=label_threads, options=options
    )
    runner = (runner or _Runner)(ctx, max_per_code)
    for msg in plugin_errors():
        runner.add(Finding("X004", "warning", msg, Location(), hint="fix or uninstall the plug-in"))
    bar = Progress(progress, [_expected_seconds(c, ctx) for c in checks])
    ctx.progress = bar
    try:
        for i, chk in enumerate(checks):
            bar.start(i, f"{chk.code} {chk.title}")
            runner.run(chk)
        bar.start(len(checks), "done")
    finally:
        bar.close()
    notes = _run_notes(checks, ctx)
    if runner.skipped_invalid:
        runner.add(
            Finding(
                "X003",
                "info",
                f"{len(runner.skipped_invalid)} checks not run because the manifest does not follow "
                f"the schema: {', '.join(runner.skipped_invalid)}",
                Location(file="manifest.json"),
                hint="fix the schema findings first, then validate again",
            )
        )
    selected = {c.code for c in checks}
    findings = [f for f in runner.findings if _code_kept(f.code, selected, ignore_l)]
    findings.sort(key=lambda f: (severity_rank(f.severity), f.code))
    return Report(
        dataset=str(path),
        findings=findings,
        runs=runner.runs,
        quick=quick,
        budgets=dict(ctx.budgets),
        dropped={k: v for k, v in runner.dropped.items() if v},
        seconds=time.perf_counter() - t0,
        notes=notes,
    )


def _hook(chk: Check, name: str) -> Callable[..., Any] | None:
    module = sys.modules.get(getattr(chk.fn, "__module__", "") or "")
    fn = getattr(module, name, None)
    return fn if callable(fn) else None


def _expected_seconds(chk: Check, ctx: CheckContext) -> float:
    hook = _hook(chk, "expected_seconds")
    try:
        value = hook(chk.code, ctx) if hook is not None else None
    except Exception:  # a hint for the progress bar must never stop a validation
        value = None
    return float(value) if isinstance(value, int | float) and value > 0 else DEFAULT_CHECK_SECONDS


def _run_notes(checks: Sequence[Check], ctx: CheckContext) -> list[str]:
    notes: list[str] = []
    for hook in dict.fromkeys(h for c in checks if (h := _hook(c, "run_notes")) is not None):
        try:
            notes += [str(n) for n in hook(ctx)]
        except Exception as exc:  # a note must never stop a validation
            notes.append(f"notes of {getattr(hook, '__module__', '?')} unavailable: {exc}")
    return notes


class _Runner:
    """Runs checks one by one, guarding the validator against their failures."""

    def __init__(self, ctx: CheckContext, max_per_code: int) -> None:
        self.ctx = ctx
        self.max_per_code = max_per_code
        self.findings: list[Finding] = []
        self.runs: list[CheckRun] = []
        self.per_code: Counter[str] = Counter()
        self.dropped: Counter[str] = Counter()
        self.reported_files: set[str] = set()
        self.seen: set[tuple[str, str, str]] = set()
        self.skipped_invalid: list[str] = []

    def add(self, f: Finding) -> None:
        if f.location.file and severity_rank(f.severity) <= 1:
            self.reported_files.add(f.location.file)
        if self.per_code[f.code] >= self.max_per_code:
            self.dropped[f.code] += 1
            return
        self.per_code[f.code] += 1
        self.findings.append(f)

    def run(self, chk: Check) -> None:
        ctx = self.ctx
        if chk.needs_valid_manifest and not ctx.manifest_valid:
            self.runs.append(CheckRun(chk.code, chk.group, chk.title, "skipped"))
            self.skipped_invalid.append(chk.code)
            return
        t = time.perf_counter()
        status, n = "ran", 0
        try:
            for f in chk.run(ctx):
                self.add(f)
                n += 1
        except InputReported:
            status = "skipped" if n == 0 else "ran"
        except RobogsError as exc:
            f = self._input_finding(chk, exc)
            if f is not None:
                self.add(f)
                n += 1
        except Exception as exc:  # a crashing check must not crash the validator
            tb = traceback.extract_tb(exc.__traceback__)
            at = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?"
            self.add(
                Finding(
                    "X001",
                    "error",
                    f"check {chk.code} ({chk.title}) crashed: {type(exc).__name__}: {str(exc)[:300]} (at {at})",
                    Location(),
                    hint="this is a bug in the check; report it with the dataset's manifest. "
                    f"Run with --ignore {chk.code} to skip it",
                )
            )
            status, n = "crashed", n + 1
        self.runs.append(
            CheckRun(chk.code, chk.group, chk.title, status, time.perf_counter() - t, n)
        )

    def _input_finding(self, chk: Check, exc: RobogsError) -> Finding | None:
        rel = self.ctx.rel(exc.path) if exc.path else None
        if rel and rel in self.reported_files:
            return None
        key = (rel or "", exc.where or "", exc.message)
        if key in self.seen:
            return None
        self.seen.add(key)
        return Finding(
            "X002",
            "error",
            f"check {chk.code} ({chk.title}) could not read its input: {exc.message}",
            Location(file=rel, where=exc.where),
            hint=exc.hint or "fix the file so it can be read",
        )


class Progress:
    """Progress of a validation, weighted by each check's expected seconds.

    Called with a note (``progress("re-rendering ...")``) it shows the note; ``fraction(f)``
    moves the bar within the running check (a long re-render reports its frames). The bar's
    ETA is the remaining expected seconds over the measured rate.

    Args:
        sink: True for a rich bar on stderr, False for nothing, or a callback
            ``(title, done, total)`` (done and total in expected seconds).
        weights: expected seconds of each check, in run order.
    """

    def __init__(
        self, sink: bool | Callable[[str, float, float], None], weights: Sequence[float]
    ) -> None:
        self.weights = [float(w) for w in weights]
        self.before = [sum(self.weights[:i]) for i in range(len(self.weights) + 1)]
        self.total = self.before[-1]
        self.index = 0
        self.title = ""
        self._bar: Any = None
        self._task: Any = None
        self._call: Callable[[str, float, float], None] | None = None
        if callable(sink):
            self._call = sink
        elif sink:
            self._open_bar()

    def _open_bar(self) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        from rich.progress import Progress as RichProgress

        self._bar = RichProgress(
            TextColumn("{task.description:<48}"),
            BarColumn(),
            TextColumn("{task.fields[checks]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
        )
        self._bar.start()
        self._task = self._bar.add_task(
            "validating", total=max(self.total, 1e-9), checks=f"0/{len(self.weights)}"
        )

    def start(self, index: int, title: str) -> None:
        """Check ``index`` (0-based; ``len(weights)`` when all are done) starts."""
        self.index = min(index, len(self.weights))
        self.title = title
        self._show(title, self.before[self.index])

    def fraction(self, f: float) -> None:
        """The running check is this fraction (0..1) done."""
        if self.index >= len(self.weights):
            return
        f = min(max(float(f), 0.0), 1.0)
        self._show(self.title, self.before[self.index] + f * self.weights[self.index])

    def __call__(self, note: str) -> None:
        """A long step of the running check starts (shown as the description)."""
        self._show(f"{self.title.split(' ', 1)[0]} {note}", None)

    def _show(self, title: str, done: float | None) -> None:
        if self._call is not None:
            self._call(title, self.before[self.index] if done is None else done, self.total)
        if self._bar is not None:
            fields: dict[str, Any] = {
                "description": title[:48],
                "checks": f"{self.index}/{len(self.weights)}",
            }
            if done is not None:
                fields["completed"] = done
            self._bar.update(self._task, **fields)

    def close(self) -> None:
        """Remove the bar."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

"""Validation reports for people (rich text, Markdown) and machines (JSON, JUnit XML).

* JSON: one object ``{"findings": [...], "summary": {...}}``; each finding has
  ``code, severity, location, value, budget, unit, message, hint``; ``summary.notes`` says
  what the run left out (e.g. frames a re-render skipped to keep its time budget).
* Text and Markdown end with the same notes.
* JUnit XML: one ``<testsuite>`` per check group, one ``<testcase>`` per check;
  findings at or above ``fail_on`` are ``<failure>`` elements, others go to
  ``<system-out>``; checks not run are ``<skipped/>``.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING

from .findings import Finding, severity_rank

if TYPE_CHECKING:
    from rich.console import Console

    from .checks.registry import Check
    from .validate import Report

__all__ = [
    "to_json",
    "to_junit",
    "to_markdown",
    "render_text",
    "render_check_list",
    "catalogue_markdown",
    "write_atomic",
]

_STYLE = {"error": "bold red", "warning": "yellow", "info": "cyan"}


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file in the same folder.

    Readers see the old file or the whole new one, never a part.

    Raises:
        OSError: the folder is missing or not writable (the temporary file is removed).
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def to_json(report: Report) -> str:
    """The report as one JSON document (``{"findings", "summary"}``)."""
    return json.dumps(report.to_dict(), indent=2, ensure_ascii=False)


def _fails(f: Finding, fail_on: str) -> bool:
    return fail_on != "never" and severity_rank(f.severity) <= severity_rank(fail_on)


def to_junit(report: Report, *, fail_on: str = "error") -> str:
    """The report as JUnit XML (for CI dashboards)."""
    by_code: dict[str, list[Finding]] = {}
    for f in report.findings:
        by_code.setdefault(f.code, []).append(f)
    suites = ET.Element("testsuites", name="robogs-validate", tests=str(len(report.runs)))
    groups: dict[str, ET.Element] = {}
    totals: dict[str, list[int]] = {}
    cases = [(r.group, r.code, r.title, r.status, r.seconds) for r in report.runs]
    cases += [
        ("runner", code, "validator", "ran", 0.0)
        for code in sorted(by_code)
        if code not in {r.code for r in report.runs}
    ]
    for group, code, title, status, seconds in cases:
        suite = groups.get(group)
        if suite is None:
            suite = groups[group] = ET.SubElement(suites, "testsuite", name=f"robogs.{group}")
            totals[group] = [0, 0, 0]
        case = ET.SubElement(
            suite,
            "testcase",
            classname=f"robogs.{group}",
            name=f"{code} {title}",
            time=f"{seconds:.3f}",
        )
        totals[group][0] += 1
        found = by_code.get(code, [])
        failing = [f for f in found if _fails(f, fail_on)]
        if status == "skipped":
            ET.SubElement(
                case, "skipped", message="not run (input reported elsewhere or manifest invalid)"
            )
            totals[group][2] += 1
        for f in failing:
            el = ET.SubElement(
                case, "failure", message=f.message[:500], type=f"{f.code}:{f.severity}"
            )
            el.text = _finding_text(f)
        if failing:
            totals[group][1] += 1
        others = [f for f in found if not _fails(f, fail_on)]
        if others:
            ET.SubElement(case, "system-out").text = "\n".join(_finding_text(f) for f in others)
    for group, suite in groups.items():
        n, failures, skipped = totals[group]
        suite.set("tests", str(n))
        suite.set("failures", str(failures))
        suite.set("errors", "0")
        suite.set("skipped", str(skipped))
    ET.indent(suites)
    return (
        '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"
    )


def _finding_text(f: Finding) -> str:
    lines = [f"{f.code} [{f.severity}] {f.location}: {f.message}"]
    if f.value_text():
        lines.append(f"  measured: {f.value_text()}")
    if f.hint:
        lines.append(f"  hint: {f.hint}")
    return "\n".join(lines)


def _md_cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def to_markdown(report: Report) -> str:
    """The report as a Markdown page (summary table, then one row per finding)."""
    counts = report.counts()
    verdict = "FAIL" if counts["error"] else ("PASS with warnings" if counts["warning"] else "PASS")
    out = [
        f"# robogs validation: `{report.dataset}`",
        "",
        f"**{verdict}** — {counts['error']} errors, {counts['warning']} warnings, {counts['info']} notes"
        f"{' (quick: manifest and parquet footers only)' if report.quick else ''}.",
        "",
        "| group | checks run | skipped | errors | warnings | notes |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for group, g in report.groups().items():
        out.append(
            f"| {group} | {g['checks']} | {g['skipped']} | {g['error']} | {g['warning']} | {g['info']} |"
        )
    out.append("")
    if report.findings:
        out += [
            "| code | severity | location | measured (budget) | message | hint |",
            "|---|---|---|---|---|---|",
        ]
        for f in report.findings:
            out.append(
                "| "
                + " | ".join(
                    _md_cell(x)
                    for x in (
                        f.code,
                        f.severity,
                        str(f.location),
                        f.value_text(),
                        f.message,
                        f.hint,
                    )
                )
                + " |"
            )
    else:
        out.append("No findings.")
    if report.dropped:
        out += [
            "",
            "Not listed (per-code cap): "
            + ", ".join(f"{k}: {v}" for k, v in sorted(report.dropped.items())),
        ]
    if report.notes:
        out += ["", "Notes on this run:", ""] + [f"- {_md_cell(n)}" for n in report.notes]
    return "\n".join(out) + "\n"


def render_text(report: Report, console: Console) -> None:
    """Print the summary table and the findings with rich."""
    from rich.table import Table
    from rich.text import Text

    table = Table(
        title=f"robogs validate {report.dataset}" + (" (quick)" if report.quick else ""),
        title_justify="left",
    )
    for col, just in (
        ("group", "left"),
        ("checks", "right"),
        ("skipped", "right"),
        ("errors", "right"),
        ("warnings", "right"),
        ("notes", "right"),
    ):
        table.add_column(col, justify=just)
    for group, g in report.groups().items():
        table.add_row(
            group,
            str(g["checks"]),
            str(g["skipped"]),
            Text(str(g["error"]), style=_STYLE["error"] if g["error"] else ""),
            Text(str(g["warning"]), style=_STYLE["warning"] if g["warning"] else ""),
            str(g["info"]),
        )
    console.print(table)
    for f in report.findings:
        line = Text()
        line.append(f"{f.code} ", style="bold")
        line.append(f"{f.severity:<7} ", style=_STYLE.get(f.severity, ""))
        line.append(str(f.location), style="dim")
        console.print(line)
        body = Text("    " + f.message)
        if f.value_text():
            body.append(f"  [{f.value_text()}]", style="magenta")
        console.print(body)
        if f.hint:
            console.print(Text(f"    hint: {f.hint}", style="green"))
    for code, n in sorted(report.dropped.items()):
        console.print(
            Text(f"... and {n} more {code} findings (see --json for counts)", style="dim")
        )
    counts = report.counts()
    style = (
        _STYLE["error"]
        if counts["error"]
        else (_STYLE["warning"] if counts["warning"] else "bold green")
    )
    console.print(
        Text(
            f"{counts['error']} errors, {counts['warning']} warnings, {counts['info']} notes "
            f"in {report.seconds:.2f} s",
            style=style,
        )
    )
    for note in report.notes:
        console.print(Text(f"note: {note}", style="dim"))


def render_check_list(checks: list[Check], console: Console) -> None:
    """Print the registered checks (code, group, severity, quick, title, budget)."""
    from rich.table import Table

    table = Table(title="robogs checks", title_justify="left")
    for col in ("code", "group", "severity", "quick", "title", "budget"):
        table.add_column(col)
    for c in checks:
        table.add_row(
            c.code, c.group, c.severity, "yes" if not c.needs_full else "", c.title, c.budget
        )
    console.print(table)


def catalogue_markdown(checks: list[Check], runner_codes: dict[str, tuple[str, str]]) -> str:
    """The catalogue table of ``spec/CHECKS.md``, built from the registry.

    Columns: code, group, severity, quick (runs under ``--quick``), title, measured
    quantity (unit), budget name, hint.
    """
    out = [
        "| code | group | severity | quick | title | measures | budget | hint |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for c in checks:
        measures = f"{c.quantity} ({c.unit})" if c.unit else c.quantity
        out.append(
            "| "
            + " | ".join(
                _md_cell(x)
                for x in (
                    c.code,
                    c.group,
                    c.severity,
                    "yes" if not c.needs_full else "no",
                    c.title,
                    measures,
                    f"`{c.budget}`" if c.budget else "",
                    c.hint,
                )
            )
            + " |"
        )
    for code, (severity, title) in sorted(runner_codes.items()):
        out.append(f"| {code} | runner | {severity} | yes | {_md_cell(title)} |  |  |  |")
    return "\n".join(out) + "\n"

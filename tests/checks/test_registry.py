"""The check registry: stable codes, the CHECKS.md catalogue, plug-ins by entry point."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from plugin_dist import write_dist

from robogs.format.budgets import DEFAULT_BUDGETS
from robogs.format.checks import (
    GROUPS,
    RETIRED_CODES,
    Check,
    available_checks,
    check,
    get_check,
    register_check,
    unregister_check,
)
from robogs.format.checks import registry as reg
from robogs.format.plugins import PluginError, PluginWarning
from robogs.format.validate import RUNNER_CODES

CHECKS_MD = Path(__file__).resolve().parents[2] / "spec" / "CHECKS.md"


def _catalogue() -> dict[str, list[str]]:
    rows = {}
    for line in CHECKS_MD.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^\| ([A-Z][0-9]{3}) \|(.*)\|$", line)
        if m:
            cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", m.group(2))]
            rows[m.group(1)] = cells
    return rows


def test_catalogue_and_registry_agree() -> None:
    rows = _catalogue()
    checks = available_checks()
    assert set(rows) == set(checks) | set(RUNNER_CODES)
    for code, c in checks.items():
        group, severity, quick, title, _measures, budget, hint = rows[code]
        assert (group, severity, title) == (c.group, c.severity, c.title), code
        assert quick == ("yes" if not c.needs_full else "no"), code
        assert budget.strip("`") == c.budget, code
        assert hint == c.hint, code
    for code, (severity, title) in RUNNER_CODES.items():
        assert rows[code][:4] == ["runner", severity, "yes", title]


def test_codes_are_well_formed_and_budgets_exist() -> None:
    letters = {
        "schema": "S",
        "integrity": "I",
        "time": "T",
        "geometry": "G",
        "binding": "B",
        "physics": "P",
    }
    for c in available_checks().values():
        assert re.fullmatch(r"[A-Z][0-9]{3}", c.code)
        assert c.group in GROUPS and c.code[0] == letters[c.group], c.code
        assert c.code not in RETIRED_CODES
        assert not c.budget or c.budget in DEFAULT_BUDGETS, (c.code, c.budget)
        assert c.hint, c.code


def test_available_checks_run_in_group_order() -> None:
    ranks = [GROUPS.index(c.group) for c in available_checks().values()]
    assert ranks == sorted(ranks)


def _noop(chk: Check, ctx: object):
    return iter(())


def test_register_rejects_duplicates_bad_codes_and_retired_codes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    existing = next(iter(available_checks().values()))
    with pytest.raises(ValueError, match="already registered"):
        register_check(Check(existing.code, "schema", "error", "imposter", _noop))
    with pytest.raises(ValueError, match="capital letter"):
        register_check(Check("t1", "time", "error", "bad", _noop))
    with pytest.raises(ValueError, match="severity"):
        register_check(Check("Z990", "time", "fatal", "bad", _noop))
    monkeypatch.setattr(reg, "RETIRED_CODES", frozenset({"Z991"}))
    with pytest.raises(ValueError, match="retired"):
        register_check(Check("Z991", "time", "error", "old", _noop))


def test_decorator_registers_and_finding_defaults() -> None:
    try:

        @check(
            "Z901", group="geometry", severity="warning", title="lab rule", unit="mm", hint="fix it"
        )
        def _rule(chk, ctx):
            yield chk.finding("off", value=3, budget=1, file="a.json")

        chk = get_check("Z901")
        (f,) = list(chk.run(None))
        assert (f.code, f.severity, f.unit, f.hint, f.value, f.budget) == (
            "Z901",
            "warning",
            "mm",
            "fix it",
            3.0,
            1.0,
        )
        assert f.location.file == "a.json"
    finally:
        unregister_check("Z901")


PLUGIN = """
    from robogs.format.checks import Check

    def _noop(chk, ctx):
        return iter(())

    CHECK = Check("Z950", "physics", "info", "plug-in check", _noop)

    def more():
        return [Check("Z951", "time", "info", "p2", _noop)]
"""


def test_entry_point_plugins_are_loaded_and_failures_reported(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_dist(
        tmp_path,
        "robogs-labchecks",
        "labchecks",
        PLUGIN,
        """
        [robogs.checks]
        good = labchecks:CHECK
        list = labchecks:more
        broken = labchecks_absent_xyz
        """,
    )
    with (
        monkeypatch.context() as mp,
        reg.REGISTRY.sandbox(),
        pytest.warns(PluginWarning, match="labchecks_absent_xyz"),
    ):
        mp.syspath_prepend(str(tmp_path))
        codes = available_checks()
        assert {"Z950", "Z951"} <= set(codes)
        assert list(codes)[-1] == "Z950"  # run order: the physics group comes last
        entries = {e.name: e for e in reg.check_entries()}
        assert entries["Z951"].source == entries["broken"].source == "robogs-labchecks"
        (err,) = reg.plugin_errors()
        assert "'broken'" in err and "labchecks_absent_xyz" in err
        with pytest.raises(PluginError, match="robogs-labchecks"):
            get_check("broken")
    assert "Z950" not in available_checks()


def test_binding_group_is_picked_up_from_its_module() -> None:
    assert "binding" in reg.BUILTIN_MODULES and "binding" in GROUPS

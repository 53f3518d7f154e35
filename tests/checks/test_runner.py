"""The validation runner: crash isolation, quick mode, selection, read-only, escaping paths."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from robogs.format.checks import Check, available_checks, register_check, unregister_check
from robogs.format.errors import FormatError
from robogs.format.spec_version import SPEC_VERSION
from robogs.synth import mutations as mut

from .scope import SKIPPED_GROUPS, validate


def _tree_hash(root: Path) -> dict[str, str]:
    out = {}
    for p in sorted(root.rglob("*")):
        st = os.lstat(p)
        key = p.relative_to(root).as_posix()
        out[key] = (
            hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else f"dir {st.st_mode:o}"
        )
        out[key] += f" {st.st_mode:o} {st.st_mtime_ns}"
    return out


def test_validation_never_modifies_the_dataset(clean_copy: Path) -> None:
    mut.drop_frame(clean_copy)  # a dataset with findings exercises more code paths
    before = _tree_hash(clean_copy)
    validate(clean_copy)
    validate(clean_copy, quick=True)
    assert _tree_hash(clean_copy) == before


def test_crashing_check_becomes_x001(tiny_root: Path) -> None:
    def boom(chk, ctx):
        yield from ()
        raise ZeroDivisionError("division by zero in a plug-in")

    register_check(Check("Z902", "geometry", "error", "crashes on purpose", boom))
    try:
        report = validate(tiny_root)
    finally:
        unregister_check("Z902")
    (f,) = [f for f in report.findings if f.code == "X001"]
    assert "Z902" in f.message and "ZeroDivisionError" in f.message and "--ignore Z902" in f.hint
    assert {r.code: r.status for r in report.runs}["Z902"] == "crashed"
    assert report.codes(min_severity="error") == {"X001"}


def test_robogs_error_in_a_check_becomes_x002_with_file_and_hint(tiny_root: Path) -> None:
    def reads(chk, ctx):
        raise FormatError(
            "bad thing", path=ctx.root / "physics.json", where="/objects", hint="fix the thing"
        )
        yield

    register_check(Check("Z903", "physics", "error", "raises a format error", reads))
    try:
        report = validate(tiny_root)
    finally:
        unregister_check("Z903")
    (f,) = [f for f in report.findings if f.code == "X002"]
    assert (f.location.file, f.location.where, f.hint) == (
        "physics.json",
        "/objects",
        "fix the thing",
    )


def test_quick_runs_only_footer_checks_and_reads_no_table_body(
    clean_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_body(*args, **kwargs):
        raise AssertionError("quick mode read a table body")

    monkeypatch.setattr(pq, "read_table", no_body)
    monkeypatch.setattr(pq.ParquetFile, "iter_batches", no_body)
    monkeypatch.setattr(pq.ParquetFile, "read", no_body)
    report = validate(clean_root, quick=True)
    quick = {
        c.code
        for c in available_checks().values()
        if not c.needs_full and c.group not in SKIPPED_GROUPS
    }
    assert {r.code for r in report.runs} == quick
    assert report.findings == [], [f.to_dict() for f in report.findings]


def test_quick_still_catches_footer_level_defects(clean_copy: Path) -> None:
    mut.row_count_mismatch(clean_copy)
    assert validate(clean_copy, quick=True).codes() == {"I005"}


def test_select_and_ignore_by_code_prefix_and_group(clean_copy: Path) -> None:
    mut.gap_in_stream(clean_copy)
    mut.add_extra_file(clean_copy)
    assert validate(clean_copy).codes(min_severity="error") == {"T003", "I002"}
    report = validate(clean_copy, select=["time"])
    assert {r.group for r in report.runs} == {"time"} and report.codes() == {"T003"}
    assert validate(clean_copy, select=["T00"]).codes() == {"T003"}
    assert validate(clean_copy, ignore=["T003"]).codes(min_severity="error") == {"I002"}
    assert validate(clean_copy, select=["I", "T003"], ignore=["integrity"]).codes() == {"T003"}
    with pytest.raises(FormatError, match="no check matches"):
        validate(clean_copy, select=["Q999"])


def test_budget_overrides_apply_and_unknown_names_are_refused(clean_copy: Path) -> None:
    mut.offset_ee_pose(clean_copy, mm=5.0)
    assert "G008" in validate(clean_copy).codes()
    assert "G008" not in validate(clean_copy, budgets={"geometry.fk_ee_mm": 6.0}).codes()
    with pytest.raises(FormatError, match="unknown budget"):
        validate(clean_copy, budgets={"geometry.fk_ee_cm": 1.0})


def test_measured_values_carry_units_and_budgets(clean_copy: Path) -> None:
    mut.offset_ee_pose(clean_copy, mm=5.0)
    (f,) = [f for f in validate(clean_copy).findings if f.code == "G008"]
    assert f.unit == "mm" and f.budget == 2.0 and f.value == pytest.approx(5.0, abs=0.5)
    assert f.location.t_ns is not None and f.location.link


def test_per_code_cap_counts_the_rest(clean_copy: Path) -> None:
    for i in range(7):
        (clean_copy / f"extra{i}.txt").write_text("x")
    report = validate(clean_copy, select=["I002"], max_per_code=3)
    assert len(report.findings) == 3 and report.dropped == {"I002": 4}
    assert report.counts()["error"] == 7


def test_escaping_path_is_reported_and_never_opened(
    clean_copy: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "outside.parquet"
    pq.write_table(pq.read_table(next(clean_copy.rglob("joint_states.parquet"))), target)
    rel = os.path.relpath(target, clean_copy)
    mut.escape_path(clean_copy, target=rel)
    opened: list[str] = []
    real_pf_init = pq.ParquetFile.__init__
    real_read = pq.read_table

    def pf_init(self, source, *args, **kwargs):
        opened.append(str(source))
        real_pf_init(self, source, *args, **kwargs)

    def read_table(source, *args, **kwargs):
        opened.append(str(source))
        return real_read(source, *args, **kwargs)

    monkeypatch.setattr(pq.ParquetFile, "__init__", pf_init)
    monkeypatch.setattr(pq, "read_table", read_table)
    report = validate(clean_copy)
    assert report.codes(min_severity="error") == {"I007"}
    (f,) = [f for f in report.findings if f.code == "I007"]
    assert "escapes" in f.message and f.location.where.endswith("/path")
    assert opened and not any(Path(p).resolve() == target.resolve() for p in opened)


def test_symlink_leading_outside_is_reported(clean_copy: Path, tmp_path: Path) -> None:
    (tmp_path / "secret.txt").write_text("secret")
    os.symlink(tmp_path / "secret.txt", clean_copy / "link.txt")
    report = validate(clean_copy)
    assert report.codes(min_severity="error") == {"I007"}


def test_invalid_manifest_skips_dependent_checks_with_a_note(clean_copy: Path) -> None:
    mut.manifest_wrong_type(clean_copy)
    report = validate(clean_copy)
    assert report.codes() == {"S001", "X003"}
    skipped = {r.code for r in report.runs if r.status == "skipped"}
    assert "T001" in skipped and "I001" not in skipped


def test_newer_major_version_is_a_finding_not_an_exception(clean_copy: Path) -> None:
    mut.set_spec_version(clean_copy, "7.0.0")
    report = validate(clean_copy)
    (f,) = [f for f in report.findings if f.code == "S005"]
    assert "7.0.0" in f.message and SPEC_VERSION in f.message and "upgrade" in f.hint


@pytest.mark.parametrize("content", ["{not json", "[1, 2]", ""])
def test_unreadable_manifest_is_one_clear_error(tmp_path: Path, content: str) -> None:
    (tmp_path / "manifest.json").write_text(content)
    with pytest.raises(FormatError) as info:
        validate(tmp_path)
    assert "manifest" in str(info.value)


def test_missing_folder_is_one_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FormatError, match="does not exist"):
        validate(tmp_path / "nope")


def test_report_json_is_serialisable(clean_copy: Path) -> None:
    mut.gap_in_stream(clean_copy)
    data = json.loads(json.dumps(validate(clean_copy).to_dict()))
    assert data["summary"]["counts"]["error"] == 1

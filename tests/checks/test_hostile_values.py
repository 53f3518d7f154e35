"""Hostile manifest values give findings, never a crashed check (X001) (issue 19, item 8)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robogs.format.errors import PathEscapeError
from robogs.format.paths import NAME_MAX_BYTES, check_relpath

from .scope import validate


def _edit(root: Path, fn) -> None:
    m = json.loads((root / "manifest.json").read_text())
    fn(m)
    (root / "manifest.json").write_text(json.dumps(m))


def test_a_path_component_over_255_bytes_is_an_unsafe_path_not_a_crash(clean_copy: Path) -> None:
    def long_name(m):
        m["episodes"][0]["streams"]["joint_states"]["path"] = "episodes/" + "a" * 300 + ".parquet"

    _edit(clean_copy, long_name)
    report = validate(clean_copy)
    codes = report.codes()
    assert "X001" not in codes, [f.message for f in report.findings if f.code == "X001"]
    (f,) = [f for f in report.findings if f.code == "I007"]
    assert "too long" in f.message and "308 bytes" in f.message


def test_a_stamp_beyond_int64_fails_the_schema_not_a_check(clean_copy: Path) -> None:
    text = (clean_copy / "manifest.json").read_text()
    start = json.loads(text)["episodes"][0]["start_ns"]
    (clean_copy / "manifest.json").write_text(
        text.replace(f'"start_ns": {start}', '"start_ns": 1' + "0" * 400, 1)
    )
    report = validate(clean_copy)
    assert "X001" not in report.codes()
    assert "S001" in report.codes(min_severity="error")


@pytest.mark.parametrize(
    ("rel", "ok"),
    [
        ("a" * NAME_MAX_BYTES, True),
        ("a" * (NAME_MAX_BYTES + 1), False),
        ("é" * 128, False),  # 256 bytes in UTF-8
        ("/".join(["d" * 200] * 5), True),
        ("/".join(["d" * 200] * 6), False),  # 1205 bytes in all
    ],
)
def test_name_and_path_length_limits_are_in_bytes(rel: str, ok: bool) -> None:
    if ok:
        assert check_relpath(rel) == rel
    else:
        with pytest.raises(PathEscapeError, match="too long"):
            check_relpath(rel)

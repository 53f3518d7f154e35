"""The spec prose, the JSON Schemas and their code mirrors agree."""

from __future__ import annotations

import json
import re
from pathlib import Path

from jsonschema import Draft202012Validator

from robogs.format.budgets import DEFAULT_BUDGETS
from robogs.format.schemas import SCHEMA_NAMES, load_schema, schema_dir
from robogs.format.spec_version import SPEC_VERSION
from robogs.format.tables import TABLES

SPEC = Path(__file__).resolve().parents[2] / "spec"


def test_every_schema_is_valid_draft_2020_12_with_versioned_id() -> None:
    files = sorted(p.name for p in schema_dir().glob("*.schema.json"))
    assert files == sorted(f"{n}.schema.json" for n in SCHEMA_NAMES)
    for name in SCHEMA_NAMES:
        schema = load_schema(name)
        Draft202012Validator.check_schema(schema)
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        assert f"/{SPEC_VERSION}/" in schema["$id"]


def test_format_md_budget_table_matches_code() -> None:
    text = (SPEC / "FORMAT.md").read_text()
    rows = dict(re.findall(r"^\| `([a-z]+\.[a-z0-9_]+)` \| ([0-9.e+-]+) \|", text, flags=re.M))
    assert set(rows) == set(DEFAULT_BUDGETS)
    for name, b in DEFAULT_BUDGETS.items():
        assert float(rows[name]) == b.value, name


def test_format_md_lists_every_table_kind() -> None:
    text = (SPEC / "FORMAT.md").read_text()
    kinds = set(re.findall(r"^\| `([a-z_0-9]+)` \| `t_ns`|^\| `([a-z_0-9]+)` \|", text, flags=re.M))
    listed = {a or b for a, b in kinds}
    assert set(TABLES) <= listed


def test_format_md_states_its_version() -> None:
    assert f"specification {SPEC_VERSION}" in (SPEC / "FORMAT.md").read_text()
    assert f"## {SPEC_VERSION}" in (SPEC / "CHANGELOG.md").read_text()
    json.dumps(load_schema("manifest"))

"""Access to the JSON Schemas and validation against them.

The schemas are package data (``robogs/format/schemas``; ``spec/schemas`` in the source tree is a
link to that folder), so an installed wheel carries them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from jsonschema import Draft202012Validator

from .errors import FormatError

__all__ = ["SCHEMA_NAMES", "schema_dir", "load_schema", "schema_problems", "SchemaProblem"]

SCHEMA_NAMES = ("manifest", "camera", "physics", "mdh")


def schema_dir() -> Path:
    """The folder holding the installed JSON Schemas (package data of ``robogs.format``)."""
    cand = Path(__file__).resolve().parent / "schemas"
    if (cand / "manifest.schema.json").is_file():
        return cand
    raise FormatError(
        f"the robogs JSON Schemas are missing from this installation (looked in {cand})",
        hint="reinstall robogs: pip install --force-reinstall robogs",
    )


@cache
def load_schema(name: str) -> dict[str, Any]:
    """Load ``spec/schemas/<name>.schema.json``."""
    if name not in SCHEMA_NAMES:
        raise KeyError(name)
    return json.loads((schema_dir() / f"{name}.schema.json").read_text())


@cache
def _validator(name: str) -> Draft202012Validator:
    return Draft202012Validator(load_schema(name))


@dataclass(frozen=True)
class SchemaProblem:
    """One schema violation: a JSON pointer and a message."""

    pointer: str
    message: str


def schema_problems(name: str, document: Any) -> list[SchemaProblem]:
    """All violations of ``document`` against schema ``name``, sorted by location.

    A document that :func:`robogs.format.fastschema.surely_valid` passes has none (it models
    the schema keywords exactly or answers "not sure"); any other goes through ``jsonschema``.
    """
    from .fastschema import surely_valid

    if surely_valid(load_schema(name), document):
        return []
    out = []
    for err in _validator(name).iter_errors(document):
        pointer = "/" + "/".join(str(p) for p in err.absolute_path)
        msg = err.message
        if len(msg) > 300:
            msg = msg[:297] + "..."
        out.append(SchemaProblem(pointer, msg))
    return sorted(out, key=lambda p: p.pointer)

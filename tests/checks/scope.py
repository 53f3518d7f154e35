"""The validator as these tests run it: every group except ``binding``.

The binding checks re-render every labelled frame, which takes minutes on the
synthetic scene; their mutation tests live with them (``tests/binding``). The
tests here assert "exactly this code and no other error" over all other groups.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from robogs.format.validate import Report
from robogs.format.validate import validate as _validate

__all__ = ["validate", "SKIPPED_GROUPS"]

SKIPPED_GROUPS: tuple[str, ...] = ("binding",)


def validate(path: str | Path, **kwargs: Any) -> Report:
    """:func:`robogs.format.validate.validate` with the binding group left out."""
    kwargs["ignore"] = [*(kwargs.get("ignore") or []), *SKIPPED_GROUPS]
    return _validate(path, **kwargs)

"""I009: NaN and inf in any numeric table are found, with stream, column, row and stamp (issue 19).

The corruptions are written here with pyarrow and hashlib directly (not through the library's
writer), and the manifest is re-hashed so that only the values are wrong.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from .scope import validate


def _stream_path(root: Path, kind: str) -> tuple[str, str]:
    m = json.loads((root / "manifest.json").read_text())
    for ep in m["episodes"]:
        for name, st in ep["streams"].items():
            if st.get("kind") == kind and isinstance(st.get("path"), str):
                return name, st["path"]
    raise AssertionError(f"fixture has no {kind} table")


def _corrupt(root: Path, rel: str, column: str, rows: np.ndarray, value: float) -> np.ndarray:
    """Set ``column[rows] = value``, rewrite the table and its manifest entry; return t_ns."""
    table = pq.read_table(root / rel)
    vals = table.column(column).to_numpy(zero_copy_only=False).copy()
    vals[rows] = value
    i = table.schema.get_field_index(column)
    table = table.set_column(i, table.schema.field(i), pa.array(vals, table.schema.field(i).type))
    pq.write_table(table, root / rel)
    m = json.loads((root / "manifest.json").read_text())
    data = (root / rel).read_bytes()
    m["files"][rel].update(sha256=hashlib.sha256(data).hexdigest(), size=len(data))
    (root / "manifest.json").write_text(json.dumps(m, indent=2))
    return table.column("t_ns").to_numpy()


def test_clean_fixture_has_no_nonfinite_finding(clean_root: Path) -> None:
    assert "I009" not in validate(clean_root, select=["I009"]).codes()


# NaN compares false everywhere, so before I009 nothing caught it; an infinite EE position is
# also (rightly) an infinite EE-vs-FK error for G008.
@pytest.mark.parametrize(
    ("kind", "column_prefix", "value", "codes"),
    [
        ("joint_states", "position.", np.nan, {"I009"}),
        ("ee_poses", "x", np.nan, {"I009"}),
        ("ee_poses", "x", np.inf, {"I009", "G008"}),
    ],
)
def test_nonfinite_values_are_errors_with_their_place(
    clean_copy: Path, kind: str, column_prefix: str, value: float, codes: set[str]
) -> None:
    name, rel = _stream_path(clean_copy, kind)
    cols = [c for c in pq.read_schema(clean_copy / rel).names if c.startswith(column_prefix)]
    n = pq.read_metadata(clean_copy / rel).num_rows
    rows = np.arange(n // 3, n, 10)  # every 10th row of the last two thirds: ~7 % of the rows
    t_ns = _corrupt(clean_copy, rel, cols[0], rows, value)
    report = validate(clean_copy)
    assert report.codes(min_severity="error") == codes, [f.to_dict() for f in report.findings]
    (f,) = [f for f in report.findings if f.code == "I009"]
    assert f.value == len(rows)
    assert f.location.stream == name and f.location.file == rel
    assert f.location.where == f"column {cols[0]}, row {rows[0]}"
    assert f.location.t_ns == int(t_ns[rows[0]])


def test_nulls_are_not_counted_as_nonfinite() -> None:
    from robogs.format.checks.integrity import _nonfinite_rows

    arr = pa.array([1.0, None, float("nan"), 2.0, float("-inf")])
    assert _nonfinite_rows(arr).tolist() == [2, 4]
    lists = pa.array([[0.0, 1.0], [float("nan"), 0.0], None, [1.0, float("inf")]])
    assert _nonfinite_rows(lists).tolist() == [1, 3]

"""Decoded messages of any type as a generic table: ``episodes/<ep>/streams/<topic>.parquet``.

Every message whose type the source defines (ROS 1 ``message_definition``, MCAP schemas, JSON,
protobuf) can be flattened into one row: ``t_ns`` and one column per leaf field, named by its
dotted path (``header.frame_id``, ``wrench.force.x``). Leaves are kept as they are: booleans,
integers (int64), floats (float64), strings. Arrays of numbers or strings become list columns;
an array of messages becomes one list column per leaf of its element type
(``markers.translation.x``), deeper nesting is kept as JSON text. An array longer than
:data:`MAX_ARRAY` elements (image bytes, point clouds) and any ``bytes`` field is stored as
its length only, in a column ``len(<path>)``.

The column set is the union of the fields seen in the first :data:`SCHEMA_ROWS` messages; a
later message with a field outside it (an array of messages that was always empty before) loses
that field and the loss is counted in the provenance. Rows are sorted by ``t_ns`` when the table
is written (stamps are kept as they come, repeats included: the stream kind ``generic`` promises
a non-decreasing order only).
"""

from __future__ import annotations

import array as py_array
import dataclasses
import json
import math
from typing import Any

import numpy as np
import pyarrow as pa

from .provenance import Provenance

__all__ = ["MAX_ARRAY", "SCHEMA_ROWS", "flatten_message", "GenericTable"]

MAX_ARRAY = 256
SCHEMA_ROWS = 64
_MAX_DEPTH = 16
_PRIMS = (bool, int, float, str, np.generic)


def _fields(msg: Any) -> list[tuple[str, Any]] | None:
    """``(name, value)`` of a message's fields, or None for a leaf value."""
    if isinstance(msg, _PRIMS) or msg is None:
        return None
    if dataclasses.is_dataclass(msg) and not isinstance(msg, type):  # rosbags
        return [(f.name, getattr(msg, f.name)) for f in dataclasses.fields(msg)]
    desc = getattr(msg, "DESCRIPTOR", None)
    if desc is not None and hasattr(desc, "fields"):  # protobuf
        return [(f.name, getattr(msg, f.name)) for f in desc.fields]
    slots = getattr(type(msg), "__slots__", None)
    if slots and not isinstance(msg, (list, tuple, bytes, np.ndarray)):  # mcap_ros2
        return [(s, getattr(msg, s)) for s in slots if not s.startswith("_")]
    if hasattr(msg, "__dict__"):  # SimpleNamespace (JSON)
        return [(k, v) for k, v in vars(msg).items() if not k.startswith("_")]
    return None


def _is_seq(v: Any) -> bool:
    if isinstance(v, (list, tuple, np.ndarray, py_array.array)):
        return True
    return (
        hasattr(v, "__len__")
        and hasattr(v, "__getitem__")
        and _fields(v) is None
        and not (isinstance(v, (str, bytes, bytearray, memoryview, dict)))
    )


def _leaf(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, (bool, int, str)) or v is None:
        return v
    if isinstance(v, float):
        return v
    return str(v)


def _flat(prefix: str, msg: Any, out: dict[str, Any], depth: int) -> None:
    if depth > _MAX_DEPTH:
        out[prefix] = json.dumps(str(msg))
        return
    fields = _fields(msg)
    if fields is None:
        if isinstance(msg, (bytes, bytearray, memoryview)):
            out[f"len({prefix})"] = len(msg)
        elif _is_seq(msg):
            _array(prefix, msg, out)
        else:
            out[prefix] = _leaf(msg)
        return
    for name, value in fields:
        _flat(f"{prefix}.{name}" if prefix else name, value, out, depth + 1)


def _array(prefix: str, seq: Any, out: dict[str, Any]) -> None:
    n = len(seq)
    if n > MAX_ARRAY:
        out[f"len({prefix})"] = n
        return
    if isinstance(seq, np.ndarray):
        out[prefix] = seq.tolist()
        return
    items = list(seq)
    if not items or all(_fields(x) is None and not _is_seq(x) for x in items):
        out[prefix] = [_leaf(x) for x in items]
        return
    rows = []
    for x in items:
        sub: dict[str, Any] = {}
        _flat("", x, sub, 1)
        rows.append(sub)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    for k in keys:
        vals = [r.get(k) for r in rows]
        name = f"len({prefix}.{k[4:-1]})" if k.startswith("len(") else f"{prefix}.{k}"
        if any(isinstance(v, list) for v in vals):
            out[name] = json.dumps(vals)
        else:
            out[name] = vals


def flatten_message(msg: Any) -> dict[str, Any]:
    """One row of leaf values (see the module docstring), keyed by dotted field path."""
    out: dict[str, Any] = {}
    _flat("", msg, out, 0)
    if not out:
        out["value"] = _leaf(msg) if _fields(msg) is None else None
    return out


def _arrow_type(values: list[Any]) -> pa.DataType:
    """The column type of a list of row values (None where a row lacks the field)."""
    seen = [v for v in values if v is not None]
    if not seen:
        return pa.string()
    if all(isinstance(v, list) for v in seen):
        inner = [x for v in seen for x in v]
        return pa.list_(_arrow_type(inner))
    if all(isinstance(v, bool) for v in seen):
        return pa.bool_()
    if all(isinstance(v, int) and not isinstance(v, bool) for v in seen):
        return pa.int64() if all(-(2**63) <= v < 2**63 for v in seen) else pa.float64()
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in seen):
        return pa.float64()
    return pa.string()


def _coerce(v: Any, typ: pa.DataType) -> Any:
    if v is None:
        return None
    if pa.types.is_list(typ):
        if not isinstance(v, list):
            return None
        return [_coerce(x, typ.value_type) for x in v]
    if pa.types.is_string(typ):
        return v if isinstance(v, str) else json.dumps(v) if isinstance(v, list) else str(v)
    if pa.types.is_floating(typ):
        return float(v) if isinstance(v, (int, float)) else math.nan
    if pa.types.is_int64(typ):
        return int(v) if isinstance(v, (int, float)) and float(v).is_integer() else None
    if pa.types.is_boolean(typ):
        return bool(v) if isinstance(v, (bool, int)) else None
    return None


class GenericTable:
    """The generic table of one topic, built in memory as Arrow batches.

    Args:
        topic: source topic (provenance key).
        provenance: where lost fields are counted.
        chunk_rows: rows per Arrow batch.
    """

    def __init__(self, topic: str, provenance: Provenance, *, chunk_rows: int = 4096) -> None:
        self.topic = topic
        self.prov = provenance
        self.chunk_rows = chunk_rows
        self.schema: pa.Schema | None = None
        self._t: list[int] = []
        self._rows: list[dict[str, Any]] = []
        self._batches: list[pa.RecordBatch] = []
        self.rows = 0
        self.lengths_only: set[str] = set()

    def add(self, t_ns: int, msg: Any) -> None:
        """Flatten one message stamped ``t_ns`` (ns) into a row."""
        row = flatten_message(msg)
        self.lengths_only.update(k for k in row if k.startswith("len("))
        self._t.append(int(t_ns))
        self._rows.append(row)
        self.rows += 1
        if len(self._rows) >= (SCHEMA_ROWS if self.schema is None else self.chunk_rows):
            self._flush()

    def _flush(self) -> None:
        if not self._rows:
            return
        if self.schema is None:
            keys = [k for k in dict.fromkeys(k for r in self._rows for k in r) if k != "t_ns"]
            fields = [pa.field("t_ns", pa.int64(), nullable=False)]
            fields += [pa.field(k, _arrow_type([r.get(k) for r in self._rows])) for k in keys]
            self.schema = pa.schema(fields)
        names = self.schema.names[1:]
        extra = {k for r in self._rows for k in r} - set(names)
        if extra:
            self.prov.note(
                f"{self.topic}: fields {sorted(extra)[:5]} first appear after the first "
                f"{SCHEMA_ROWS} messages; they are not in its generic table"
            )
            for t, r in zip(self._t, self._rows, strict=True):
                if set(r) & extra:
                    self.prov.issue(
                        self.topic,
                        "message fields outside the generic table's columns",
                        t,
                        drop=False,
                    )
        cols = [pa.array(self._t, pa.int64())]
        for f in self.schema:
            if f.name == "t_ns":
                continue
            cols.append(pa.array([_coerce(r.get(f.name), f.type) for r in self._rows], f.type))
        self._batches.append(pa.RecordBatch.from_arrays(cols, schema=self.schema))
        self._t, self._rows = [], []

    def table(self) -> pa.Table:
        """Every row, sorted by ``t_ns`` (stable: equal stamps keep their arrival order)."""
        self._flush()
        assert self.schema is not None
        tab = pa.Table.from_batches(self._batches, schema=self.schema)
        order = np.argsort(tab.column("t_ns").to_numpy(), kind="stable")
        return tab.take(pa.array(order))

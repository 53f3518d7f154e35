"""The tables of a robogs episode: columns, dtypes, units and frames.

This module is the code mirror of the table section of ``spec/FORMAT.md``.
Columns whose name ends in ``.`` are families: ``position.`` stands for one
column per joint, ``position.<joint name>``.
"""

from __future__ import annotations

from dataclasses import dataclass

import pyarrow as pa

__all__ = [
    "Column",
    "TableSpec",
    "TABLES",
    "check_table_schema",
    "family_columns",
    "non_null_columns",
    "null_problems",
]


@dataclass(frozen=True)
class Column:
    """One column (or, if ``name`` ends in '.', one family of columns)."""

    name: str
    dtype: str
    unit: str = ""
    frame: str = ""
    required: bool = True
    doc: str = ""

    @property
    def is_family(self) -> bool:
        return self.name.endswith(".")


@dataclass(frozen=True)
class TableSpec:
    """A table kind: its columns and whether rows are stamped and sorted by ``t_ns``."""

    kind: str
    columns: tuple[Column, ...]
    stamped: bool = True
    doc: str = ""


_T = Column("t_ns", "int64", "ns", doc="stamp on the dataset clock")
_POSE = (
    Column("x", "float64", "m", "world"),
    Column("y", "float64", "m", "world"),
    Column("z", "float64", "m", "world"),
    Column("qw", "float64", "", "world"),
    Column("qx", "float64", "", "world"),
    Column("qy", "float64", "", "world"),
    Column("qz", "float64", "", "world"),
)

TABLES: dict[str, TableSpec] = {
    t.kind: t
    for t in [
        TableSpec(
            "joint_states",
            (
                _T,
                Column(
                    "position.",
                    "float64",
                    "rad|m",
                    doc="per joint; rad for revolute, m for prismatic",
                ),
                Column("velocity.", "float64", "rad/s|m/s", required=False),
                Column("effort.", "float64", "N·m|N", required=False),
            ),
            doc="measured joint states (encoders)",
        ),
        TableSpec(
            "actions",
            (
                _T,
                Column("command.", "float64", "rad|m|rad/s|N·m", doc="kind declared in the stream"),
            ),
            doc="commanded actions / policy output",
        ),
        TableSpec(
            "ee_poses", (_T, Column("link", "string"), *_POSE), doc="T_world_link of the named link"
        ),
        TableSpec("object_poses", (_T, Column("object", "string"), *_POSE), doc="T_world_object"),
        TableSpec(
            "wrenches",
            (
                _T,
                Column("frame", "string"),
                *(Column(c, "float64", "N", "frame") for c in ("fx", "fy", "fz")),
                *(Column(c, "float64", "N·m", "frame") for c in ("tx", "ty", "tz")),
            ),
            doc="forces and torques in the named frame",
        ),
        TableSpec(
            "boxes2d",
            (
                _T,
                Column("camera", "string"),
                Column("frame_index", "int64"),
                Column("label_id", "int32"),
                *(
                    Column(c, "float64", "px", "image")
                    for c in ("x_min", "y_min", "x_max", "y_max")
                ),
            ),
            doc="2D boxes in pixel-edge coordinates, max exclusive",
        ),
        TableSpec(
            "boxes3d",
            (
                _T,
                Column("object", "string"),
                *_POSE,
                *(Column(c, "float64", "m", "box") for c in ("size_x", "size_y", "size_z")),
            ),
            doc="oriented 3D boxes: centre pose in world, full edge lengths",
        ),
        TableSpec(
            "segments",
            (
                Column("label_id", "int32"),
                Column("category", "string"),
                Column("instance", "int32"),
                Column("kind", "string", doc="robot_link | object | background"),
                Column("target", "string", doc="link or object name, '' for background"),
            ),
            stamped=False,
            doc="panoptic label id -> category, instance, link or object",
        ),
        TableSpec(
            "camera_frames",
            (_T, Column("frame_index", "int64")),
            doc="one row per recorded frame of one camera",
        ),
        TableSpec(
            "camera_labels",
            (
                Column("frame_index", "int64"),
                Column("png", "binary", doc="16-bit PNG of label ids"),
            ),
            stamped=False,
            doc="panoptic label image per frame",
        ),
        TableSpec(
            "camera_extrinsics",
            (_T, *_POSE),
            doc="time-varying T_world_cam",
        ),
        TableSpec(
            "generic",
            (_T,),
            doc="decoded messages of one source topic: t_ns and one column per leaf field",
        ),
    ]
}

_ARROW_OK = {
    "int64": (pa.types.is_int64,),
    "int32": (pa.types.is_int32,),
    "float64": (pa.types.is_float64,),
    "float32": (pa.types.is_float32,),
    "string": (pa.types.is_string, pa.types.is_large_string, pa.types.is_dictionary),
    "binary": (pa.types.is_binary, pa.types.is_large_binary),
}


def family_columns(schema_names: list[str], prefix: str) -> list[str]:
    """Names after ``prefix`` of the columns in a family, in table order."""
    return [n[len(prefix) :] for n in schema_names if n.startswith(prefix)]


def check_table_schema(kind: str, schema: pa.Schema) -> list[str]:
    """Problems of an Arrow schema against the table kind (empty list if it conforms)."""
    spec = TABLES.get(kind)
    if spec is None:
        return [f"unknown table kind {kind!r}"]
    problems: list[str] = []
    names = schema.names
    dups = sorted({n for n in names if names.count(n) > 1})
    if dups:
        return [f"duplicate column names {dups}"]
    for col in spec.columns:
        checks = _ARROW_OK[col.dtype]
        if col.is_family:
            members = [n for n in names if n.startswith(col.name)]
            if col.required and not members:
                problems.append(f"missing column family '{col.name}<name>'")
            for n in members:
                if not any(c(schema.field(n).type) for c in checks):
                    problems.append(
                        f"column {n!r} has type {schema.field(n).type}, expected {col.dtype}"
                    )
            continue
        if col.name not in names:
            if col.required:
                problems.append(
                    f"missing column {col.name!r} ({col.dtype}{', ' + col.unit if col.unit else ''})"
                )
            continue
        typ = schema.field(col.name).type
        if not any(c(typ) for c in checks):
            problems.append(f"column {col.name!r} has type {typ}, expected {col.dtype}")
    return problems


#: column dtypes whose nulls have no meaning (a null stamp, frame index, label id or image)
_NOT_NULL_DTYPES = ("int64", "int32", "binary")


def non_null_columns(kind: str, schema_names: list[str]) -> list[str]:
    """Columns of ``kind`` present in ``schema_names`` that must not hold nulls.

    These are the integer and binary columns of the spec (``t_ns``, ``frame_index``,
    ``label_id``, ``png`` ...): a null there cannot be read as a number or an image.
    """
    spec = TABLES.get(kind)
    if spec is None:
        return []
    return [
        c.name
        for c in spec.columns
        if not c.is_family and c.dtype in _NOT_NULL_DTYPES and c.name in schema_names
    ]


def null_problems(kind: str, table: pa.Table) -> list[str]:
    """Problems of nulls in the columns of ``table`` that must not hold them."""
    return [
        f"column {name!r} holds {table.column(name).null_count} nulls"
        for name in non_null_columns(kind, table.schema.names)
        if table.column(name).null_count
    ]

"""The user's column map (``--map MAP.yaml``): read, checked and turned into a :class:`ColumnMap`.

The YAML format is described in :mod:`robogs.convert.ingest.tabular` (``time``, ``joints``,
``effort_kind``, ``gap_s``, ``hold`` and ``ee_pose``, :mod:`.pose`). A map with ``hold`` or
``ee_pose`` but neither ``time`` nor ``joints`` leaves those to the automatic layouts (layout
``auto``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError

from ..yamlio import read_yaml
from .column_map import ColumnMap, JointColumns
from .pose import read_ee_pose
from .reading import TIME_SCALE

__all__ = ["read_mapping"]

_POS_SCALE = {"rad": 1.0, "deg": math.pi / 180.0, "m": 1.0, "mm": 1e-3}
_VEL_SCALE = {"rad/s": 1.0, "deg/s": math.pi / 180.0, "m/s": 1.0, "mm/s": 1e-3}

#: effort unit (lower case, spaces removed) -> its name in the provenance
_EFFORT_UNITS = {
    "nm": "N m",
    "n*m": "N m",
    "n.m": "N m",
    "n·m": "N m",
    "n": "N",
    "a": "A",
}
_MAX_MAP_BYTES = 1 << 20


def _norm_unit(
    u: Any, table: dict[str, float], what: str, path: Path | None, where: str
) -> tuple[str, float]:
    key = str(u).strip().lower().replace(" ", "")
    aliases = {
        "radian": "rad",
        "radians": "rad",
        "degree": "deg",
        "degrees": "deg",
        "rad/sec": "rad/s",
        "deg/sec": "deg/s",
        "sec": "s",
        "second": "s",
        "seconds": "s",
        "µs": "us",
        "nanoseconds": "ns",
    }
    key = aliases.get(key, key)
    if key not in table:
        raise InputError(
            f"unknown {what} unit {u!r}",
            path=path,
            where=where,
            hint=f"use one of {', '.join(table)}",
        )
    return key, table[key]


def _col_spec(v: Any, path: Path, where: str) -> tuple[str | None, dict[str, Any]]:
    if v is None:
        return None, {}
    if isinstance(v, str):
        return v, {}
    if isinstance(v, dict) and isinstance(v.get("column"), str):
        return v["column"], v
    raise InputError("expected a column name or {column: NAME, unit: ...}", path=path, where=where)


def read_mapping(path: str | Path, joint_names: list[str]) -> ColumnMap:
    """Read a YAML column map (format in the module docstring).

    Raises:
        InputError: unreadable YAML, unknown units, joints not in the URDF, missing keys,
            values of the wrong type.
    """
    path = Path(path)
    doc = read_yaml(path, what="mapping", max_bytes=_MAX_MAP_BYTES)
    try:
        return _parse_mapping(doc, path, joint_names)
    except (TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise InputError(
            f"mapping holds a value of the wrong type ({type(exc).__name__}: {str(exc)[:120]})",
            path=path,
            hint="numbers for gap_s, epoch_ns, torque_constant, gear_ratio; a mapping or a "
            "column name for time and each joint's position, velocity and effort",
        ) from None


def _parse_mapping(doc: Any, path: Path, joint_names: list[str]) -> ColumnMap:
    """The column map of a parsed YAML document (see :func:`read_mapping`)."""
    if not isinstance(doc, dict):
        raise InputError("mapping must be a YAML mapping with 'time' and 'joints'", path=path)
    hold = _read_hold(doc.get("hold"), path, joint_names)
    ee_pose = read_ee_pose(doc.get("ee_pose"), path)
    if doc.get("joints") is None and doc.get("time") is None and (hold or ee_pose):
        gap = _gap_s(doc.get("gap_s"), path)  # no joint columns: automatic layouts for them
        return ColumnMap("auto", "", "s", {}, gap_s=gap, hold=hold, ee_pose=ee_pose)
    t = doc.get("time")
    tcol, tspec = _col_spec(t, path, "time")
    if tcol is None:
        raise InputError(
            "mapping has no time column", path=path, where="time", hint="time: {column: t, unit: s}"
        )
    tunit, _ = _norm_unit(tspec.get("unit", "s"), TIME_SCALE, "time", path, "time/unit")
    kind = str(doc.get("effort_kind", "torque")).lower()
    if kind not in ("torque", "current"):
        raise InputError(
            f"effort_kind {kind!r} is neither 'torque' nor 'current'",
            path=path,
            where="effort_kind",
        )
    joints_doc = doc.get("joints")
    if not isinstance(joints_doc, dict) or not joints_doc:
        raise InputError("mapping has no joints", path=path, where="joints")
    unknown = [j for j in joints_doc if j not in joint_names]
    if unknown:
        raise InputError(
            f"joints {unknown} of the mapping are not in the URDF",
            path=path,
            where="joints",
            hint=f"URDF joints: {joint_names}",
        )
    joints: dict[str, JointColumns] = {}
    held_too = sorted(set(joints_doc) & set(hold))
    if held_too:
        raise InputError(
            f"joints {held_too} are both mapped to columns and held",
            path=path,
            where="hold",
            hint="a joint is either in 'joints' or in 'hold'",
        )
    for j in joint_names:
        if j in joints_doc:
            joints[j] = _joint_columns(joints_doc[j] or {}, kind, path, f"joints/{j}")
    missing = [j for j in joint_names if j not in joints and j not in hold]
    if missing:
        raise InputError(
            f"mapping does not cover joints {missing}",
            path=path,
            where="joints",
            hint=f"URDF joints: {joint_names}; a joint the log leaves out goes under "
            "'hold: {joint: position}'",
        )
    epoch = int(tspec.get("epoch_ns", 0))
    if not -(2**62) <= epoch <= 2**62:
        raise InputError(
            f"epoch_ns {epoch} is outside the int64 nanosecond range",
            path=path,
            where="time/epoch_ns",
            hint="epoch_ns is the dataset-clock stamp (ns) of the log's time zero",
        )
    gap = _gap_s(doc.get("gap_s"), path)
    return ColumnMap("map", tcol, tunit, joints, epoch, kind, gap, hold, ee_pose)


def _joint_columns(spec: Any, kind: str, path: Path, w: str) -> JointColumns:
    """One joint's entry of the map (``w``: its place, ``joints/<name>``); ``kind``: the map's
    ``effort_kind``."""
    pcol, pspec = _col_spec(spec.get("position"), path, f"{w}/position")
    if pcol is None:
        raise InputError("joint has no position column", path=path, where=f"{w}/position")
    punit, pscale = _norm_unit(
        pspec.get("unit", "rad"), _POS_SCALE, "position", path, f"{w}/position/unit"
    )
    vcol, vspec = _col_spec(spec.get("velocity"), path, f"{w}/velocity")
    vunit, vscale = _norm_unit(
        vspec.get("unit", "rad/s"), _VEL_SCALE, "velocity", path, f"{w}/velocity/unit"
    )
    ecol, espec = _col_spec(spec.get("effort"), path, f"{w}/effort")
    units = {"position": punit}
    if vcol:
        units["velocity"] = vunit
    escale = 1.0
    if ecol:
        eunit_raw = str(espec.get("unit", "A" if kind == "current" else "N m")).strip().lower()
        eunit = _EFFORT_UNITS.get(eunit_raw.replace(" ", ""))
        if eunit is None:
            raise InputError(
                f"unknown effort unit {espec.get('unit')!r}",
                path=path,
                where=f"{w}/effort/unit",
                hint="use N m, N or A",
            )
        if eunit == "A" or kind == "current":
            kt, gear = espec.get("torque_constant"), espec.get("gear_ratio", 1.0)
            if kt is None:
                raise InputError(
                    "a motor current needs torque_constant (N m/A)",
                    path=path,
                    where=f"{w}/effort/torque_constant",
                    hint="add torque_constant and gear_ratio, or give a torque column",
                )
            escale = float(kt) * float(gear)
            if not (math.isfinite(escale) and escale != 0.0):
                raise InputError(
                    "torque_constant * gear_ratio must be a finite, non-zero number",
                    path=path,
                    where=f"{w}/effort",
                )
            eunit = "A"
        units["effort"] = eunit
    return JointColumns(pcol, vcol, ecol, pscale, vscale, escale, units)


def _gap_s(value: Any, path: Path) -> float | None:
    """The ``gap_s`` of a map: None, or a positive finite number of seconds."""
    if value is None:
        return None
    gap = float(value)
    if not (math.isfinite(gap) and 0.0 < gap <= 1e6):
        raise InputError(
            f"gap_s must be a positive number of seconds (at most 1e6), got {value!r}",
            path=path,
            where="gap_s",
            hint="gap_s is the time jump (s) that starts a new segment",
        )
    return gap


def _read_hold(doc: Any, path: Path, joint_names: list[str]) -> dict[str, float]:
    """The ``hold`` section: joint -> constant position (rad or m)."""
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise InputError(
            "'hold' must map joint names to positions", path=path, where="hold",
            hint="hold: {panda_finger_joint1: 0.0}",
        )  # fmt: skip
    out: dict[str, float] = {}
    for j, v in doc.items():
        if j not in joint_names:
            raise InputError(
                f"held joint {j!r} is not an actuated joint of the URDF",
                path=path,
                where=f"hold/{j}",
                hint=f"URDF joints: {joint_names}",
            )
        try:
            out[j] = float(v)
        except (TypeError, ValueError):
            raise InputError(
                f"held position {v!r} is not a number (rad or m)", path=path, where=f"hold/{j}"
            ) from None
        if not math.isfinite(out[j]):
            raise InputError("held position is not finite", path=path, where=f"hold/{j}")
    return out

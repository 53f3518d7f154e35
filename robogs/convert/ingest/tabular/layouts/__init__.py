"""The automatic layouts: a log's columns inferred from its header, one module per layout.

:mod:`.rtde` (UR RTDE), :mod:`.franka` (libfranka) and :mod:`.generic` (common names) each
declare their column families; :mod:`.headers` matches them. :func:`auto_mapping` infers the
time and joint columns, :func:`infer_ee_pose` the recorded end-effector pose (RTDE
``actual_TCP_pose``, Franka ``O_T_EE``), :func:`resolve_time` settles a time unit left to be
guessed from the values.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import InputError

from ..column_map import ColumnMap
from ..pose import EePoseColumns
from ..reading import RawLog, guess_time_unit, to_float
from . import franka, generic, rtde
from .generic import SEGMENT_COLUMNS
from .headers import indexed_family, joint_columns, mismatch, zero_based

__all__ = ["EE_POSE_PREFIXES", "SEGMENT_COLUMNS", "auto_mapping", "infer_ee_pose", "resolve_time"]

#: per-joint column families by index, most specific layout first: (layout, kind, base name)
_FAMILIES = (*rtde.JOINT_FAMILIES, *franka.JOINT_FAMILIES, *generic.JOINT_FAMILIES)
#: header prefixes :func:`infer_ee_pose` reads
EE_POSE_PREFIXES = (franka.O_T_EE, rtde.TCP_POSE)


def auto_mapping(columns: list[str], joint_names: list[str], path: Path) -> ColumnMap:
    """Guess the mapping from a header (UR RTDE, Franka, generic indexed or named layouts).

    Time: :data:`.generic.TIME_COLUMNS`, the first present (RTDE's ``timestamp`` in s). Joints:
    the first family of each kind (position, velocity, effort) found by index, in URDF joint
    order (the layout is the most specific family's); else by joint name
    (:func:`.generic.named_joints`).

    Raises:
        InputError: no time or position column, or the joints do not match the URDF (both sets
            listed).
    """
    names = set(columns)
    nj = len(joint_names)
    tcol, tunit = next(((c, u) for c, u in generic.TIME_COLUMNS if c in names), (None, None))
    if tcol is None:
        raise InputError(
            "no time column found (looked for t_ns, t_us, t_ms, t_s, time, timestamp, t, stamp)",
            path=path,
            where="header",
            hint="pass --map MAP.yaml naming the time column and its unit",
        )
    fams: dict[str, dict[int, str]] = {}
    layout = "generic"
    for lay, kind, base in _FAMILIES:
        if kind in fams:
            continue
        cols = zero_based(indexed_family(names, base))
        if cols:
            fams[kind] = cols
            if lay != "generic" and layout == "generic":
                layout = lay
    if "position" not in fams:
        return ColumnMap(
            "generic", tcol, tunit or "s", generic.named_joints(columns, joint_names, path)
        )
    pos, vel, eff = fams["position"], fams.get("velocity", {}), fams.get("effort", {})
    if sorted(pos) != list(range(len(pos))) or len(pos) != nj:
        raise mismatch(path, [pos[k] for k in sorted(pos)], joint_names, layout)
    has_v = sorted(vel) == list(range(nj))
    has_e = sorted(eff) == list(range(nj))
    joints = {
        j: joint_columns(pos[i], vel[i] if has_v else None, eff[i] if has_e else None)
        for i, j in enumerate(joint_names)
    }
    if layout == "rtde" and tcol == rtde.TIME_COLUMN:
        tunit = "s"  # RTDE's timestamp is seconds since the controller started
    return ColumnMap(layout, tcol, tunit or "s", joints)


def infer_ee_pose(columns: list[str], link_names: list[str]) -> tuple[EePoseColumns | None, str]:
    """UR RTDE ``actual_TCP_pose_0..5`` (:func:`.rtde.infer_tcp_pose`) or Franka
    ``O_T_EE_0..15`` (:func:`.franka.infer_o_t_ee`) as an ``ee_pose`` spec, with a sentence
    saying how it is read (or, when ``spec`` is None, why it is not).

    Other robots' links are not guessed: a map's ``ee_pose`` section names them.

    Args:
        columns: the log's header.
        link_names: the robot's links, root first.

    Returns:
        ``(spec, why)``; ``spec`` is None when the columns are not all there or no link fits.
    """
    names = set(columns)
    tcp = zero_based(indexed_family(names, rtde.TCP_POSE))
    if tcp:
        return rtde.infer_tcp_pose(tcp, link_names)
    return franka.infer_o_t_ee(zero_based(indexed_family(names, franka.O_T_EE)), link_names)


def resolve_time(path: Path, raw: RawLog, cmap: ColumnMap, prov: Any) -> None:
    """Settle the time unit of an automatic mapping (from its name, or guessed) and say so."""
    if cmap.layout == "map":
        return
    if cmap.time_unit == "auto":
        col = raw.data.get(cmap.time_column)
        try:
            unit, why = guess_time_unit(to_float(col)[0] if col is not None else np.zeros(0))
        except ValueError as exc:
            raise InputError(
                f"cannot tell the unit of time column {cmap.time_column!r} ({exc})",
                path=path,
                where=f"column {cmap.time_column!r}",
                hint="name it t_s, t_ms, t_us or t_ns, or pass --map with time: {column, unit}",
            ) from None
        cmap.time_unit, cmap.time_from = unit, f"guessed: {why}"
    elif cmap.layout == "rtde" and cmap.time_column == rtde.TIME_COLUMN:  # unit: auto_mapping
        cmap.time_from = "UR RTDE timestamp (s)"
    else:
        cmap.time_from = f"column name {cmap.time_column!r}"
    prov.note(
        f"{path.name}: time column {cmap.time_column!r} read in {cmap.time_unit} "
        f"({cmap.time_from}); a map with 'time: {{column, unit}}' overrides it"
    )

"""Which column map a log file is read with: the user's map, or the automatic layouts.

:func:`file_mapping` applies a ``--map`` (:mod:`.user_map`) to one file, or infers the columns
from the file's header (:mod:`.layouts`) and adds what a map without joints gives (``hold``,
``gap_s``, ``ee_pose``); it settles the time unit, the segment column and a recorded
end-effector pose the layouts recognise.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from .column_map import ColumnMap
from .layouts import EE_POSE_PREFIXES, SEGMENT_COLUMNS, auto_mapping, infer_ee_pose, resolve_time
from .pose import resolve_frame
from .reading import RawLog

__all__ = ["file_mapping"]


def file_mapping(
    f: Path, raw: RawLog, fixed_map: ColumnMap | None, logged: list[str], chain: Any, prov: Any
) -> ColumnMap:
    """The column map of one file: the user's map (copied), or the automatic layouts with the
    map's ``hold``/``gap_s``/``ee_pose``; UR RTDE ``actual_TCP_pose`` or Franka ``O_T_EE``
    inferred when no map names a pose.

    Args:
        f: the log file (named in notes and errors).
        raw: its columns.
        fixed_map: the user's map (None: none).
        logged: the URDF joints the log holds (the held ones left out), in URDF order.
        chain: the robot's kinematic chain (link names, fixed frames).
        prov: the provenance record (notes on how time and poses are read).

    Raises:
        InputError: no time or position column, or joints that do not match the URDF.
    """
    if fixed_map is not None and fixed_map.joints:
        cmap = dataclasses.replace(fixed_map)
    else:
        cmap = auto_mapping(raw.columns, logged, f)
        if fixed_map is not None:
            cmap.hold, cmap.gap_s = dict(fixed_map.hold), fixed_map.gap_s
            cmap.ee_pose = fixed_map.ee_pose
    resolve_time(f, raw, cmap, prov)
    if cmap.segment_column is None:
        cmap.segment_column = next((c for c in SEGMENT_COLUMNS if c in raw.data), None)
    if cmap.ee_pose is None and any(c.startswith(EE_POSE_PREFIXES) for c in raw.columns):
        spec, why = infer_ee_pose(raw.columns, list(chain.link_names))
        if spec is None:
            prov.note(
                f"{f.name}: {why}; declare its link in the map to import it: 'ee_pose: "
                "{link: LINK, format: axis_angle | matrix_colmajor}')"
            )
        else:
            resolve_frame(spec, chain, None)
            cmap.ee_pose = spec
            prov.note(f"{f.name}: {why}; a map's 'ee_pose' overrides it")
    return cmap

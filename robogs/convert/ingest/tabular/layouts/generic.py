"""Generic logs: time, segment and joint columns by common names.

Time: the first of ``t_ns``/``t_us``/``t_ms``/``t_s`` (and ``time_*``, ``timestamp_*``,
``stamp_*``) with the unit its name says, else ``time``/``timestamp``/``t``/``stamp`` with the
unit ``auto`` (guessed from the values). Joints by index (``q``/``pos``/``qd``/``dq``/``vel``/
``tau``/``effort``/``torque`` + index, :mod:`.headers`) in URDF joint order, or by joint name
(``position.<j>``, ``q_<j>``, ``pos_<j>``; ``velocity.``, ``qd_``, ``dq_``, ``vel_``;
``effort.``, ``tau_``, ``effort_``). Segments: a ``segment``/``episode``/``trajectory`` column.
"""

from __future__ import annotations

import re
from pathlib import Path

from robogs.format.errors import InputError

from ..column_map import JointColumns
from .headers import joint_columns, mismatch

__all__ = ["JOINT_FAMILIES", "SEGMENT_COLUMNS", "TIME_COLUMNS", "named_joints"]

#: time columns by name, in order of preference: (name, unit; "auto" = guessed from the values)
TIME_COLUMNS = (
    *(
        (f"{b}_{u}", u)
        for u in ("ns", "us", "ms", "s")
        for b in ("t", "time", "timestamp", "stamp")
    ),
    ("time", "auto"),
    ("timestamp", "auto"),
    ("t", "auto"),
    ("stamp", "auto"),
)
#: columns that name a trajectory; consecutive rows with one value form one segment
SEGMENT_COLUMNS = ("segment", "episode", "trajectory")
#: per-joint column families: (layout, kind, base-name alternation)
JOINT_FAMILIES = (
    ("generic", "position", "q|pos|position|joint_pos|joint_position"),
    ("generic", "velocity", "qd|dq|vel|velocity|joint_vel|joint_velocity"),
    ("generic", "effort", "tau|effort|torque|joint_effort|joint_torque"),
)
_NAMED = {
    "position": r"(?:position\.|q_|pos_)(.+)",
    "velocity": r"(?:velocity\.|qd_|dq_|vel_)(.+)",
    "effort": r"(?:effort\.|tau_|effort_)(.+)",
}


def named_joints(columns: list[str], joint_names: list[str], path: Path) -> dict[str, JointColumns]:
    """Joint columns named after the URDF joints (``position.<j>``, ``q_<j>``, ...); velocity
    and effort only when every joint has one.

    Raises:
        InputError: no position column, or the named joints differ from the URDF's.
    """
    found = {}
    for kind, pattern in _NAMED.items():
        rx = re.compile(pattern)
        found[kind] = {m.group(1): n for n in columns if (m := rx.fullmatch(n))}
    pos, vel, eff = found["position"], found["velocity"], found["effort"]
    if not pos:
        raise InputError(
            "no joint position columns found (actual_q_<i>, q<i>, q_<i>, pos_<i>, "
            "position.<joint>, q_<joint>, pos_<joint>)",
            path=path,
            where="header",
            hint="pass --map MAP.yaml naming the columns",
        )
    if set(pos) != set(joint_names):
        raise mismatch(path, sorted(pos), joint_names, "generic")
    has_v = set(vel) >= set(joint_names)
    has_e = set(eff) >= set(joint_names)
    return {
        j: joint_columns(pos[j], vel[j] if has_v else None, eff[j] if has_e else None)
        for j in joint_names
    }

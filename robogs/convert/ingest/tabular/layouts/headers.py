"""Header matching shared by the automatic layouts: indexed column families and joint columns.

A family is one base name with a joint index, ``i`` from 0 or 1 and ``_``, ``.`` or ``[i]``
before it (``q1``, ``qd_1``, ``tau[0]``, ``actual_q_0``), optionally behind ``field.`` (the
``rostopic echo -p`` / rosbag CSV exports).
"""

from __future__ import annotations

import re
from pathlib import Path

from robogs.format.errors import InputError

from ..column_map import JointColumns

__all__ = ["indexed_family", "joint_columns", "mismatch", "zero_based"]

_IDX = r"(?:_|\.|\[)?(\d+)\]?"
_PRE = r"(?:field\.)?"  # rostopic echo -p / rosbag CSV exports


def indexed_family(names: set[str], base: str) -> dict[int, str]:
    """``index -> column`` of the columns named ``base`` (a regex alternation) plus an index."""
    rx = re.compile(_PRE + f"(?:{base})" + _IDX)
    return {int(m.group(1)): n for n in names if (m := rx.fullmatch(n))}


def zero_based(cols: dict[int, str]) -> dict[int, str]:
    """Indices shifted to start at 0 when they run 1..n (``q1..q6``)."""
    if cols and min(cols) == 1 and sorted(cols) == list(range(1, len(cols) + 1)):
        return {k - 1: v for k, v in cols.items()}
    return cols


def joint_columns(position: str, velocity: str | None, effort: str | None) -> JointColumns:
    """A joint's columns in SI units as logged (rad, rad/s, N m): the automatic layouts' case."""
    units = {"position": "rad"}
    if velocity:
        units["velocity"] = "rad/s"
    if effort:
        units["effort"] = "N m"
    return JointColumns(position, velocity, effort, units=units)


def mismatch(path: Path, found: list[str], joint_names: list[str], layout: str) -> InputError:
    """The error of a header whose joint columns do not match the URDF (both sets listed)."""
    hint = "rename the columns or pass --map MAP.yaml"
    if len(found) < len(joint_names):
        rest = joint_names[len(found) :]
        hint += f"; if the log leaves out joints, hold them in a map: 'hold: {{{rest[0]}: 0.0}}'"
    return InputError(
        f"the {layout} columns name joints {found} but the URDF has {joint_names}",
        path=path,
        where="header",
        hint=hint,
    )

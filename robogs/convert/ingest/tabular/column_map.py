"""The column map of a log: which columns hold the stamps and each joint, in which units.

Built by a user's YAML map (:mod:`.user_map`) or the automatic layouts (:mod:`.layouts`), chosen
per file by :func:`.mapping.file_mapping`, read by the cleaning step (:mod:`.cleaning`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .pose import EePoseColumns

__all__ = ["ColumnMap", "JointColumns"]


@dataclass
class JointColumns:
    """Source columns of one joint and the factors that turn them into SI units.

    Attributes:
        position, velocity, effort: column names (``None`` when absent).
        position_scale: rad (or m) per source unit; velocity_scale likewise per second.
        effort_scale: N m (or N) per source unit (``k_t * gear_ratio`` for currents).
        units: source units as written, for the provenance.
    """

    position: str
    velocity: str | None = None
    effort: str | None = None
    position_scale: float = 1.0
    velocity_scale: float = 1.0
    effort_scale: float = 1.0
    units: dict[str, str] = field(default_factory=dict)


@dataclass
class ColumnMap:
    """How a log's columns map onto the robot's joints.

    Attributes:
        layout: ``rtde`` | ``franka`` | ``generic`` | ``map``.
        time_column, time_unit: the stamp column and its unit (s, ms, us, ns).
        epoch_ns: added to every stamp (ns) to put it on the dataset clock.
        joints: URDF joint name -> its columns, in URDF order.
        effort_kind: ``torque`` or ``current``.
        gap_s: segment split threshold (None: automatic).
        hold: joints not in the log -> their constant position (rad or m).
        ee_pose: recorded end-effector pose columns (None: none).
        time_from: how the time unit was chosen (the map, the column name, or a guess).
        segment_column: column whose value names each row's trajectory (None: none).
    """

    layout: str
    time_column: str
    time_unit: str
    joints: dict[str, JointColumns]
    epoch_ns: int = 0
    effort_kind: str = "torque"
    gap_s: float | None = None
    hold: dict[str, float] = field(default_factory=dict)
    ee_pose: EePoseColumns | None = None
    time_from: str = "the map"
    segment_column: str | None = None

    def columns(self) -> list[str]:
        """Every source column used (time first, end-effector pose columns last)."""
        out = [self.time_column]
        for jc in self.joints.values():
            out += [c for c in (jc.position, jc.velocity, jc.effort) if c]
        if self.ee_pose is not None:
            out += self.ee_pose.columns
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description for the provenance."""
        out: dict[str, Any] = {
            "layout": self.layout,
            "time": {
                "column": self.time_column,
                "unit": self.time_unit,
                "epoch_ns": self.epoch_ns,
                "unit_from": self.time_from,
            },
            "effort_kind": self.effort_kind,
            "joints": {
                j: {
                    k: v
                    for k, v in (
                        ("position", c.position),
                        ("velocity", c.velocity),
                        ("effort", c.effort),
                        ("units", c.units),
                        ("effort_scale", c.effort_scale),
                    )
                    if v
                }
                for j, c in self.joints.items()
            },
        }
        if self.hold:
            out["hold"] = dict(self.hold)
        if self.ee_pose is not None:
            out["ee_pose"] = self.ee_pose.to_dict()
        if self.segment_column is not None:
            out["segment_column"] = self.segment_column
        return out

"""Import tabular joint logs (CSV or Parquet) of a robot arm: ``robogs convert LOG OUT --urdf URDF``.

``LOG`` is one ``.csv``/``.parquet`` file or a folder of them. Each file is one trajectory;
inside a file a forward time jump larger than ``gap_s`` (default: the larger of 1 s and 50
median steps) starts a new segment. Each segment becomes one episode with a
``joint_states`` table (``t_ns``, ``position.<j>``, ``velocity.<j>``, ``effort.<j>``) whose
``segment`` names the file and the segment number.

Columns are mapped automatically for three layouts, or by a small YAML map (``--map``):

* UR RTDE: ``timestamp`` (s), ``actual_q_i`` (rad), ``actual_qd_i`` (rad/s),
  ``target_moment_i`` (N m) for i = 0..J-1 in URDF joint order (``actual_current_i`` is motor
  current: it needs torque constants, so it is used only through a map);
* Franka-like: ``time`` (s), ``q0..``, ``dq0..``, ``tau_J0..``;
* generic: ``t_ns`` (ns) or ``time``/``t``/``timestamp`` (s), and per joint
  ``position.<j>``/``q_<j>``/``pos_<j>``, ``velocity.<j>``/``qd_<j>``/``dq_<j>``/``vel_<j>``,
  ``effort.<j>``/``tau_<j>``/``effort_<j>``, with ``<j>`` a URDF joint name or an index.

The YAML map::

    time: {column: stamp, unit: ms, epoch_ns: 0}        # unit s | ms | us | ns
    effort_kind: torque                                   # or current
    gap_s: 0.5                                            # optional
    joints:
      shoulder_pan_joint:
        position: {column: q0, unit: deg}                 # rad | deg | m | mm
        velocity: {column: v0, unit: deg/s}               # rad/s | deg/s | m/s | mm/s
        effort: {column: i0, unit: A, torque_constant: 0.12, gear_ratio: 101}
        # or effort: {column: tau0, unit: N m}            # N m | N

A joint the log leaves out (a gripper finger, a rail) is held at a constant position (rad or
m) with ``hold: {panda_finger_joint1: 0.0}``; a map that has only ``hold`` (and ``gap_s``)
keeps the automatic layouts for the other joints. Held joints get constant ``position.<j>``
and zero ``velocity.<j>`` columns, listed in the stream's ``derived``, and no effort column.

Recorded end-effector (TCP) poses, e.g. UR RTDE ``actual_TCP_pose_0..5`` or Franka
``O_T_EE_0..15``, become an ``ee_poses`` stream of a declared link with an ``ee_pose`` section
(:mod:`robogs.convert.ingest.tabular_pose`); a map with only ``ee_pose`` (and ``hold``, ``gap_s``)
keeps the automatic layouts for the joints.

A plain string (``position: q0``) names a column in SI units. With ``effort_kind: current``
every effort column is a motor current in A and ``torque_constant`` (N m/A, motor side) and
``gear_ratio`` are required: ``tau = I * k_t * gear_ratio``.

Missing velocities are derived from the positions by the Savitzky-Golay differentiator of
:mod:`robogs.format.differentiate` (listed in the stream's ``derived``); missing
efforts simply give no effort columns.

Bad input is never silently dropped: rows before the header line, unparseable rows, rows with
NaN in a mapped column, duplicated stamps and stamps going back are dropped and counted in the
provenance (file, reason, count, first line numbers). A row with missing fields in the middle
of a file, a mapped column missing or empty, positions that look like degrees given as radians
(beyond the URDF limits in rad, within them in degrees), too many stamps going back, or joint
names that do not match the URDF raise an :class:`~robogs.format.errors.InputError` naming the
file, the row and the column.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError, RobogsError
from robogs.format.urdf import load_urdf

from .tabular_pose import EePoseColumns, pose_samples, read_ee_pose, resolve_frame
from .yamlio import read_yaml

__all__ = [
    "ColumnMap",
    "JointColumns",
    "LogSegment",
    "convert_tabular",
    "detect_tabular",
    "read_mapping",
    "auto_mapping",
    "read_log_file",
]

_SUFFIXES = (".csv", ".parquet", ".pq")
_TIME_SCALE = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_POS_SCALE = {"rad": 1.0, "deg": math.pi / 180.0, "m": 1.0, "mm": 1e-3}
_VEL_SCALE = {"rad/s": 1.0, "deg/s": math.pi / 180.0, "m/s": 1.0, "mm/s": 1e-3}
_EFFORT_UNITS = {
    "n m": "N m",
    "nm": "N m",
    "n*m": "N m",
    "n.m": "N m",
    "n·m": "N m",
    "n": "N",
    "a": "A",
}
_MAX_BACK_FRACTION = 0.01
_MAX_MAP_BYTES = 1 << 20
_EXAMPLES = 5


# ----------------------------------------------------------------------------- mapping


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
    tunit, _ = _norm_unit(tspec.get("unit", "s"), _TIME_SCALE, "time", path, "time/unit")
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
        if j not in joints_doc:
            continue
        spec = joints_doc[j] or {}
        w = f"joints/{j}"
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
            eunit = _EFFORT_UNITS.get(
                eunit_raw.replace(" ", "")
                if eunit_raw.replace(" ", "") in _EFFORT_UNITS
                else eunit_raw
            )
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
        joints[j] = JointColumns(pcol, vcol, ecol, pscale, vscale, escale, units)
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


def _indexed(names: set[str], pattern: str) -> dict[int, str]:
    rx = re.compile(pattern)
    out = {}
    for n in names:
        m = rx.fullmatch(n)
        if m:
            out[int(m.group(1))] = n
    return out


def _mismatch(path: Path, found: list[str], joint_names: list[str], layout: str) -> InputError:
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


#: time columns by name, in order of preference: (name, unit; "auto" = guessed from the values)
_TIME_COLUMNS = (
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
_IDX = r"(?:_|\.|\[)?(\d+)\]?"
_PRE = r"(?:field\.)?"  # rostopic echo -p / rosbag CSV exports
#: per-joint columns by index, most specific layout first: (layout, kind, base-name pattern)
_INDEXED = (
    ("rtde", "position", "actual_q"),
    ("rtde", "velocity", "actual_qd"),
    ("rtde", "effort", "target_moment"),
    ("franka", "effort", "tau_J"),
    ("generic", "position", "q|pos|position|joint_pos|joint_position"),
    ("generic", "velocity", "qd|dq|vel|velocity|joint_vel|joint_velocity"),
    ("generic", "effort", "tau|effort|torque|joint_effort|joint_torque"),
)


def _indexed_family(names: set[str], base: str) -> dict[int, str]:
    return _indexed(names, _PRE + f"(?:{base})" + _IDX)


def _zero_based(cols: dict[int, str]) -> dict[int, str]:
    """Indices shifted to start at 0 when they run 1..n (``q1..q6``)."""
    if cols and min(cols) == 1 and sorted(cols) == list(range(1, len(cols) + 1)):
        return {k - 1: v for k, v in cols.items()}
    return cols


def auto_mapping(columns: list[str], joint_names: list[str], path: Path) -> ColumnMap:
    """Guess the mapping from a header (UR RTDE, Franka, generic indexed or named layouts).

    Time: the first of ``t_ns``/``t_us``/``t_ms``/``t_s`` (and ``time_*``, ``timestamp_*``,
    ``stamp_*``) with the unit its name says, else ``time``/``timestamp``/``t``/``stamp`` with
    the unit ``auto`` (guessed from the values by :func:`guess_time_unit`). Joints by index:
    ``actual_q_i``/``actual_qd_i``/``target_moment_i`` (RTDE), ``q``/``dq``/``qd``/``tau_J``
    (Franka), ``q``/``pos``/``qd``/``dq``/``vel``/``tau``/``effort``/``torque`` with ``i`` from
    0 or 1 and ``_``, ``.`` or ``[i]`` before it (``q1``, ``qd_1``, ``tau[0]``), in URDF joint
    order; or by joint name (``position.<j>``, ``q_<j>``, ...).

    Raises:
        InputError: no time or position column, or the joints do not match the URDF (both sets
            listed).
    """
    names = set(columns)
    nj = len(joint_names)
    tcol, tunit = next(((c, u) for c, u in _TIME_COLUMNS if c in names), (None, None))
    if tcol is None:
        raise InputError(
            "no time column found (looked for t_ns, t_us, t_ms, t_s, time, timestamp, t, stamp)",
            path=path,
            where="header",
            hint="pass --map MAP.yaml naming the time column and its unit",
        )
    fams: dict[str, dict[int, str]] = {}
    layout = "generic"
    for lay, kind, base in _INDEXED:
        if kind in fams:
            continue
        cols = _zero_based(_indexed_family(names, base))
        if cols:
            fams[kind] = cols
            if lay != "generic" and layout == "generic":
                layout = lay
    if "position" in fams:
        pos, vel, eff = fams["position"], fams.get("velocity", {}), fams.get("effort", {})
        if sorted(pos) != list(range(len(pos))) or len(pos) != nj:
            raise _mismatch(path, [pos[k] for k in sorted(pos)], joint_names, layout)
        joints = {}
        has_v = sorted(vel) == list(range(nj))
        has_e = sorted(eff) == list(range(nj))
        for i, j in enumerate(joint_names):
            joints[j] = JointColumns(
                pos[i],
                vel[i] if has_v else None,
                eff[i] if has_e else None,
                units={"position": "rad"}
                | ({"velocity": "rad/s"} if has_v else {})
                | ({"effort": "N m"} if has_e else {}),
            )
        if layout == "rtde" and tcol == "timestamp":
            tunit = "s"  # RTDE's timestamp is seconds since the controller started
        return ColumnMap(layout, tcol, tunit or "s", joints)
    pos_pat = r"(?:position\.|q_|pos_)(.+)"
    vel_pat = r"(?:velocity\.|qd_|dq_|vel_)(.+)"
    eff_pat = r"(?:effort\.|tau_|effort_)(.+)"

    def named(pattern: str) -> dict[str, str]:
        rx = re.compile(pattern)
        return {m.group(1): n for n in columns if (m := rx.fullmatch(n))}

    pos, vel, eff = named(pos_pat), named(vel_pat), named(eff_pat)
    if not pos:
        raise InputError(
            "no joint position columns found (actual_q_<i>, q<i>, q_<i>, pos_<i>, "
            "position.<joint>, q_<joint>, pos_<joint>)",
            path=path,
            where="header",
            hint="pass --map MAP.yaml naming the columns",
        )
    if set(pos) != set(joint_names):
        raise _mismatch(path, sorted(pos), joint_names, "generic")
    has_v = set(vel) >= set(joint_names)
    has_e = set(eff) >= set(joint_names)
    joints = {
        j: JointColumns(
            pos[j],
            vel[j] if has_v else None,
            eff[j] if has_e else None,
            units={"position": "rad"}
            | ({"velocity": "rad/s"} if has_v else {})
            | ({"effort": "N m"} if has_e else {}),
        )
        for j in joint_names
    }
    return ColumnMap("generic", tcol, tunit or "s", joints)


#: (unit, seconds per unit) for the time-unit guess
_UNITS_S = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))


def guess_time_unit(values: np.ndarray) -> tuple[str, str]:
    """The unit of a time column from its values, and why (a phrase for the provenance).

    Unix-epoch stamps are recognised by magnitude (2001..2286 is 1e9..1e10 s, 1e12..1e13 ms,
    1e15..1e16 us, 1e18..1e19 ns). Otherwise the unit is the one whose median step gives a
    sampling rate between 1 Hz and 20 kHz closest (in log scale) to 200 Hz, typical of arm logs.

    Raises:
        ValueError: fewer than two distinct finite values.
    """
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    steps = np.diff(v)
    steps = steps[steps > 0]
    if v.size < 2 or steps.size == 0:
        raise ValueError("fewer than two increasing stamps")
    first = float(np.median(np.abs(v[: min(v.size, 101)])))
    for unit, lo in (("s", 1e9), ("ms", 1e12), ("us", 1e15), ("ns", 1e18)):
        if lo <= first < 10 * lo:
            return unit, f"Unix-epoch values near {first:.4g}"
    dt = float(np.median(steps))
    best: tuple[float, str, float] | None = None
    for unit, sec in _UNITS_S:
        rate = 1.0 / (dt * sec)
        if 1.0 <= rate <= 20_000.0:
            score = abs(math.log10(rate) - math.log10(200.0))
            if best is None or score < best[0]:
                best = (score, unit, rate)
    if best is None:
        raise ValueError(f"median step {dt:g} gives no sampling rate between 1 Hz and 20 kHz")
    return best[1], f"median step {dt:g} -> {best[2]:.4g} Hz"


# ----------------------------------------------------------------------------- reading


@dataclass
class _Raw:
    """A file's columns as text (CSV) or arrays (Parquet), with their source line numbers."""

    columns: list[str]
    data: dict[str, np.ndarray]
    lines: np.ndarray  # [N] 1-based line (CSV) or row (Parquet) of each kept row
    kind: str
    dropped: dict[str, list[int]] = field(default_factory=dict)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _split(line: str, delim: str | None) -> list[str]:
    return [f.strip().strip('"') for f in (line.split(delim) if delim else line.split())]


def _find_header(lines: list[str], path: Path) -> tuple[int, str | None]:
    for i, line in enumerate(lines[:200]):
        if not line.strip():
            continue
        for delim in (",", ";", "\t", None):
            fields = _split(line, delim)
            if len(fields) < 2 or any(_is_number(f) or not f for f in fields):
                continue
            # the next non-empty line must have as many fields, mostly numbers
            for nxt in lines[i + 1 : i + 6]:
                if not nxt.strip():
                    continue
                vals = _split(nxt, delim)
                if len(vals) == len(fields) and sum(
                    _is_number(v) or v == "" for v in vals
                ) >= 0.8 * len(vals):
                    return i, delim
                break
    raise InputError(
        "no header line followed by numeric rows in the first 200 lines",
        path=path,
        hint="the file needs one header line naming the columns",
    )


def _read_csv(path: Path) -> _Raw:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read the log ({exc.strerror})", path=path) from None
    lines = text.splitlines()
    h, delim = _find_header(lines, path)
    columns = _split(lines[h], delim)
    if len(set(columns)) != len(columns):
        dup = sorted({c for c in columns if columns.count(c) > 1})
        raise InputError(f"duplicate column names {dup}", path=path, where=f"line {h + 1}")
    dropped: dict[str, list[int]] = {}
    if h:
        dropped["lines before the header"] = list(range(1, h + 1))
    rows: list[list[str]] = []
    line_no: list[int] = []
    short: list[tuple[int, int]] = []
    for k in range(h + 1, len(lines)):
        line = lines[k]
        if not line.strip():
            continue
        fields = _split(line, delim)
        if len(fields) != len(columns):
            short.append((k + 1, len(fields)))
            continue
        rows.append(fields)
        line_no.append(k + 1)
    if short:
        last_good = line_no[-1] if line_no else h + 1
        interior = [(ln, n) for ln, n in short if ln < last_good]
        if interior:
            ln, n = interior[0]
            col = columns[min(n, len(columns) - 1)]
            raise InputError(
                f"row has {n} fields but the header has {len(columns)} (columns of different lengths)",
                path=path,
                where=f"line {ln}, column {col!r}",
                hint="repair or remove the row; only truncated rows at the end of a file are dropped",
            )
        dropped["truncated rows at the end of the file"] = [ln for ln, _ in short]
    arr = np.array(rows, dtype=object).reshape(len(rows), len(columns))
    data = {c: arr[:, i].astype(str) for i, c in enumerate(columns)}
    return _Raw(columns, data, np.asarray(line_no, dtype=np.int64), "csv", dropped)


def _read_parquet(path: Path) -> _Raw:
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise InputError(
            f"unreadable parquet log ({str(exc).splitlines()[0][:200]})", path=path
        ) from None
    data = {}
    for name in table.schema.names:
        col = table.column(name)
        if pa.types.is_integer(col.type) or pa.types.is_floating(col.type):
            data[name] = col.to_numpy(zero_copy_only=False)
        else:
            data[name] = np.asarray(col.cast(pa.string()).to_pylist(), dtype=object).astype(str)
    return _Raw(
        list(table.schema.names), data, np.arange(1, table.num_rows + 1, dtype=np.int64), "parquet"
    )


def _to_float(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Float array and a mask of unparseable (non-empty, non-numeric) entries."""
    if values.dtype.kind in "iuf":
        return values.astype(np.float64), np.zeros(len(values), dtype=bool)
    v = np.char.strip(values.astype(str))
    empty = (v == "") | (np.char.lower(v) == "nan") | (np.char.lower(v) == "na")
    clean = np.where(empty, "nan", v)
    try:
        return clean.astype(np.float64), np.zeros(len(v), dtype=bool)
    except ValueError:
        out = np.full(len(v), np.nan)
        bad = np.zeros(len(v), dtype=bool)
        for i, s in enumerate(clean):
            try:
                out[i] = float(s)
            except ValueError:
                bad[i] = True
        return out, bad


def _to_ns(values: np.ndarray, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Exact int64 ns from decimal text (or numbers); mask of unparseable/NaN entries."""
    scale = _TIME_SCALE[unit]
    limit = (2**63 - 1) // scale  # larger magnitudes do not fit int64 nanoseconds
    if values.dtype.kind in "iu":
        ok = (values <= limit) & (values >= -limit)
        return np.where(ok, values, 0).astype(np.int64) * scale, ~ok
    if values.dtype.kind == "f":
        ok = np.isfinite(values) & (np.abs(values) < limit)
        return np.where(ok, np.round(np.where(ok, values, 0.0) * scale), 0).astype(np.int64), ~ok
    out = np.zeros(len(values), dtype=np.int64)
    bad = np.zeros(len(values), dtype=bool)
    digits = len(str(scale)) - 1
    for i, s in enumerate(np.char.strip(values.astype(str))):
        m = re.fullmatch(r"([+-]?)(\d*)(?:\.(\d*))?", s)
        if m and (m.group(2) or m.group(3)):
            whole = (m.group(2) or "0").lstrip("0") or "0"
            if len(whole) > 19:  # beyond int64 in any unit
                bad[i] = True
                continue
            frac = (m.group(3) or "")[:digits].ljust(digits, "0") if digits else ""
            v = int(whole) * scale + (int(frac) if frac else 0)
            if v >= 2**63:
                bad[i] = True
                continue
            out[i] = -v if m.group(1) == "-" else v
            continue
        try:
            f = float(s)
        except ValueError:
            bad[i] = True
            continue
        if not math.isfinite(f) or abs(f) >= limit:
            bad[i] = True
        else:
            out[i] = int(round(f * scale))
    return out, bad


def read_log_file(path: Path) -> _Raw:
    """Read one CSV or Parquet log (columns as text for CSV)."""
    if path.suffix.lower() == ".csv":
        return _read_csv(path)
    return _read_parquet(path)


# ----------------------------------------------------------------------------- cleaning


@dataclass
class LogSegment:
    """One trajectory of one file, cleaned and in SI units.

    Attributes:
        source: file name; index: segment number in the file.
        t_ns: [N] int64 stamps; q, qd: [N, J] (all joints, held ones constant); tau:
            [N, len(effort_joints)] or None.
        derived_velocity: velocities were differentiated from positions.
        lines: [N] source line numbers.
        effort_joints: the joints ``tau`` covers (the logged ones, not the held ones).
        ee_t_ns, ee: [M] stamps and [M, 7] end-effector poses (``x y z qw qx qy qz``, world)
            of the rows with a usable pose; None without ``ee_pose`` columns.
    """

    source: str
    index: int
    t_ns: np.ndarray
    q: np.ndarray
    qd: np.ndarray | None
    tau: np.ndarray | None
    derived_velocity: bool
    lines: np.ndarray
    effort_joints: list[str] = field(default_factory=list)
    ee_t_ns: np.ndarray | None = None
    ee: np.ndarray | None = None
    name: str | None = None


@dataclass
class _FileReport:
    rows: int = 0
    written: int = 0
    dropped: dict[str, list[int]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    ee_rows: int = 0
    ee_written: int = 0
    ee_dropped: list[int] = field(default_factory=list)

    def drop(self, reason: str, lines: np.ndarray | list[int]) -> None:
        lst = self.dropped.setdefault(reason, [])
        lst.extend(int(x) for x in np.asarray(lines).ravel())


def _check_degrees(
    path: Path,
    cmap: ColumnMap,
    q: np.ndarray,
    lines: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    joint_names: list[str],
    report: _FileReport,
) -> None:
    for k, j in enumerate(joint_names):
        lo, hi = lower[k], upper[k]
        if not (np.isfinite(lo) and np.isfinite(hi)) or len(q) == 0:
            continue
        qj = q[:, k]
        span = hi - lo
        outside = (qj < lo - 0.05 * span) | (qj > hi + 0.05 * span)
        if not outside.any():
            continue
        as_rad = qj * math.pi / 180.0
        inside_deg = np.all((as_rad >= lo - 1e-9) & (as_rad <= hi + 1e-9))
        worst = int(np.argmax(np.abs(qj)))
        col = cmap.joints[j].position
        if inside_deg and cmap.joints[j].units.get("position", "rad") == "rad":
            raise InputError(
                f"positions of joint {j!r} reach {qj[worst]:.4g} rad, far outside its URDF limits "
                f"[{lo:.4g}, {hi:.4g}] rad but inside them if read as degrees",
                path=path,
                where=f"line {lines[worst]}, column {col!r}",
                hint="the column is probably in degrees: pass --map with 'unit: deg' for it",
            )
        report.notes.append(
            f"joint {j!r} (column {col!r}) leaves its URDF limits on {int(outside.sum())} rows "
            f"(first at line {int(lines[np.argmax(outside)])})"
        )


def _clean_file(
    path: Path,
    raw: _Raw,
    cmap: ColumnMap,
    joint_names: list[str],
    lower: np.ndarray,
    upper: np.ndarray,
    gap_s: float | None,
) -> tuple[list[LogSegment], _FileReport]:
    """Clean one file's rows and cut them into segments: at every change of the
    ``segment_column`` value (time may restart there) and at forward time gaps."""
    report = _FileReport(rows=len(raw.lines) + sum(len(v) for v in raw.dropped.values()))
    for reason, lns in raw.dropped.items():
        report.drop(reason, lns)
    missing = [c for c in cmap.columns() if c not in raw.data]
    if missing:
        raise InputError(
            f"column {missing[0]!r} named by the {cmap.layout} mapping is missing"
            + (f" (and {len(missing) - 1} more: {missing[1:4]})" if len(missing) > 1 else ""),
            path=path,
            where="header",
            hint=f"the file has columns {raw.columns[:12]}{' ...' if len(raw.columns) > 12 else ''}",
        )
    lines = raw.lines
    t_ns, t_bad = _to_ns(raw.data[cmap.time_column], cmap.time_unit)
    t_ns = t_ns + int(cmap.epoch_ns)
    keep = ~t_bad
    if t_bad.any():
        report.drop(f"unparseable or missing stamp in column {cmap.time_column!r}", lines[t_bad])

    def numeric(col: str, scale: float) -> np.ndarray:
        nonlocal keep
        vals, bad = _to_float(raw.data[col])
        nan = ~np.isfinite(vals) & ~bad
        if bool((bad | nan).all()) and len(vals):
            raise InputError(
                f"column {col!r} has no numeric value",
                path=path,
                where=f"column {col!r}",
                hint="check the mapping and the delimiter",
            )
        for mask, reason in (
            (bad & keep, f"unparseable value in column {col!r}"),
            (nan & keep, f"NaN or empty value in column {col!r}"),
        ):
            if mask.any():
                report.drop(reason, lines[mask])
        keep = keep & ~bad & ~nan
        return vals * scale

    logged = [j for j in joint_names if j not in cmap.hold]
    n_rows = len(lines)

    def per_joint(kind: str) -> np.ndarray:
        cols = []
        for j in joint_names:
            jc = cmap.joints.get(j)
            if jc is None:  # held joint
                v = cmap.hold[j] if kind == "position" else 0.0
                cols.append(np.full(n_rows, v))
            else:
                cols.append(numeric(getattr(jc, kind), getattr(jc, f"{kind}_scale")))
        return np.stack(cols, axis=1)

    q = per_joint("position")
    has_v = all(cmap.joints[j].velocity for j in logged)
    has_e = all(cmap.joints[j].effort for j in logged)
    qd = per_joint("velocity") if has_v else None
    tau = (
        np.stack(
            [numeric(cmap.joints[j].effort, cmap.joints[j].effort_scale) for j in logged],
            axis=1,
        )
        if has_e
        else None
    )
    ee = ee_ok = None
    if cmap.ee_pose is not None:  # a bad pose cell drops the pose only, not the joint row
        vals = np.stack([_to_float(raw.data[c])[0] for c in cmap.ee_pose.columns], axis=1)
        ee, ee_ok = pose_samples(vals, cmap.ee_pose, lines, path)
    idx = np.flatnonzero(keep)
    if len(idx) == 0:
        raise InputError(
            "no usable row", path=path, hint="every row was dropped; see the provenance reasons"
        )
    # stamps: drop duplicates and samples that go back (kept order is the file order), within
    # each named trajectory when a segment column names them
    t_k = t_ns[idx]
    group = _group_ids(raw, cmap.segment_column)
    g_k = group[idx]
    prev_max = np.full(len(t_k), np.iinfo(np.int64).min)
    for g in np.unique(g_k):
        sel = np.flatnonzero(g_k == g)
        run_max = np.maximum.accumulate(t_k[sel])
        prev_max[sel[1:]] = run_max[:-1]
    dup = t_k == prev_max
    back = t_k < prev_max
    if back.sum() > max(_MAX_BACK_FRACTION * len(t_k), 2):
        first = int(np.argmax(back))
        raise InputError(
            f"{int(back.sum())} of {len(t_k)} stamps go back in time (not monotonic)",
            path=path,
            where=f"line {lines[idx[first]]}, column {cmap.time_column!r}",
            hint="sort the log by time, or check the time column and its unit",
        )
    if dup.any():
        report.drop("duplicate stamp", lines[idx[dup]])
    if back.any():
        report.drop("stamp earlier than the previous sample", lines[idx[back]])
    idx = idx[~dup & ~back]
    t_k = t_ns[idx]
    g_k = group[idx]
    cols = [k for k, j in enumerate(joint_names) if j in cmap.joints]
    _check_degrees(
        path, cmap, q[idx][:, cols], lines[idx], lower[cols], upper[cols], logged, report
    )
    # segments at forward gaps
    steps = np.diff(t_k)
    med = float(np.median(steps)) if len(steps) else 0.0
    gap_ns = int((gap_s if gap_s is not None else max(1.0, 50 * med * 1e-9)) * 1e9)
    named = np.diff(g_k) != 0
    cuts = np.flatnonzero((steps > gap_ns) | named) + 1
    bounds = np.concatenate([[0], cuts, [len(idx)]])
    segments: list[LogSegment] = []
    from robogs.format.differentiate import savgol_derivative

    for s in range(len(bounds) - 1):
        sel = idx[bounds[s] : bounds[s + 1]]
        if len(sel) < 5:
            report.drop("segment shorter than 5 samples", lines[sel])
            continue
        qs = q[sel]
        qds = qd[sel] if qd is not None else savgol_derivative(t_ns[sel], qs, order=1)
        ee_sel = None
        if ee is not None and ee_ok is not None:
            ee_sel = sel[ee_ok[sel]]
            report.ee_rows += len(sel)
            report.ee_written += len(ee_sel)
            report.ee_dropped.extend(int(x) for x in lines[sel][~ee_ok[sel]])
        segments.append(
            LogSegment(
                path.name,
                len(segments),
                t_ns[sel],
                qs,
                qds,
                tau[sel] if tau is not None else None,
                qd is None,
                lines[sel],
                logged if tau is not None else [],
                t_ns[ee_sel] if ee_sel is not None else None,
                ee[ee_sel] if ee_sel is not None and ee is not None else None,
                _group_name(raw, cmap.segment_column, sel[0]),
            )
        )
        report.written += len(sel)
    n_gaps = int((steps > gap_ns).sum())
    if n_gaps:
        report.notes.append(
            f"{n_gaps} time gap(s) over {gap_ns / 1e9:g} s split the file into {len(bounds) - 1} segments"
        )
    if cmap.segment_column is not None:
        report.notes.append(
            f"column {cmap.segment_column!r} names {len(np.unique(g_k))} trajectories; each "
            "becomes its own episode(s), with its name as the segment"
        )
    return segments, report


def _group_ids(raw: _Raw, column: str | None) -> np.ndarray:
    """[N] int: the run number of each row's segment value (0 everywhere without a column)."""
    n = len(raw.lines)
    if column is None:
        return np.zeros(n, dtype=np.int64)
    vals = np.char.strip(np.asarray(raw.data[column]).astype(str))
    change = np.concatenate([[False], vals[1:] != vals[:-1]]) if n else np.zeros(0, bool)
    return np.cumsum(change).astype(np.int64)


def _group_name(raw: _Raw, column: str | None, row: int) -> str | None:
    """The segment value of a row (None without a segment column)."""
    if column is None:
        return None
    v = str(raw.data[column][row]).strip()
    if v.endswith(".0") and v[:-2].lstrip("-").isdigit():  # 3.0 from a float column
        v = v[:-2]
    return v or "unnamed"


# ----------------------------------------------------------------------------- dataset


def _log_files(log: Path) -> list[Path]:
    if log.is_file():
        if log.suffix.lower() not in _SUFFIXES:
            raise InputError(
                "not a CSV or Parquet log",
                path=log,
                hint="pass a .csv or .parquet file or a folder",
            )
        return [log]
    if log.is_dir():
        files = sorted(p for p in log.iterdir() if p.is_file() and p.suffix.lower() in _SUFFIXES)
        if not files:
            raise InputError("folder holds no .csv or .parquet file", path=log)
        return files
    raise InputError("log does not exist", path=log)


def detect_tabular(path: Path) -> bool:
    """True for a ``.csv``/``.parquet`` file or a folder holding only such logs (plus sidecars)."""
    path = Path(path)
    if path.is_file():
        return path.suffix.lower() in _SUFFIXES
    if path.is_dir():
        files = [p for p in path.iterdir() if p.is_file()]
        logs = [p for p in files if p.suffix.lower() in _SUFFIXES]
        return bool(logs) and all(
            p.suffix.lower() in _SUFFIXES + (".json", ".yaml", ".yml", ".md", ".txt") for p in files
        )
    return False


def _episode_id(stem: str, k: int, n: int, used: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)[:56] or "log"
    eid = base if n == 1 else f"{base}_s{k:02d}"
    while eid in used:
        eid = eid + "x"
    used.add(eid)
    return eid


def _joint_table(seg: LogSegment, joint_names: list[str]) -> pa.Table:
    cols: dict[str, Any] = {"t_ns": pa.array(seg.t_ns, type=pa.int64())}
    for k, j in enumerate(joint_names):
        cols[f"position.{j}"] = pa.array(seg.q[:, k], type=pa.float64())
    if seg.qd is not None:
        for k, j in enumerate(joint_names):
            cols[f"velocity.{j}"] = pa.array(seg.qd[:, k], type=pa.float64())
    if seg.tau is not None:
        for k, j in enumerate(seg.effort_joints):
            cols[f"effort.{j}"] = pa.array(seg.tau[:, k], type=pa.float64())
    return pa.table(cols)


def _ee_table(seg: LogSegment, link: str) -> pa.Table:
    assert seg.ee is not None and seg.ee_t_ns is not None
    cols: dict[str, Any] = {
        "t_ns": pa.array(seg.ee_t_ns, type=pa.int64()),
        "link": pa.array([link] * len(seg.ee_t_ns), type=pa.string()),
    }
    for k, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
        cols[c] = pa.array(seg.ee[:, k], type=pa.float64())
    return pa.table(cols)


def _physics_from_urdf(urdf) -> dict[str, Any]:
    joints: dict[str, dict[str, float]] = {}
    for j in urdf.robot.joints:
        d = j.dynamics
        if j.type == "fixed" or d is None:
            continue
        entry = {}
        for key in ("damping", "friction"):
            v = getattr(d, key, None)
            if v is not None and math.isfinite(float(v)) and float(v) >= 0:
                entry[key] = float(v)
        if entry:
            joints[j.name] = entry
    doc: dict[str, Any] = {"revision": 0, "gravity_mps2": [0.0, 0.0, -9.81], "objects": {}}
    if joints:
        doc["joints"] = joints
    return doc


def _strip_meshes(urdf_path: Path) -> tuple[bytes, int]:
    """URDF bytes with every mesh geometry (visual/collision) removed, and how many."""
    from lxml import etree

    from robogs.format.urdf import parse_urdf_xml

    tree = parse_urdf_xml(urdf_path, verbatim=True, keep_blank_text=True).getroottree()
    n = 0
    for tag in ("visual", "collision"):
        for el in list(tree.getroot().iter(tag)):
            if el.find("geometry/mesh") is not None:
                el.getparent().remove(el)
                n += 1
    return etree.tostring(tree, xml_declaration=True, encoding="utf-8"), n


def _attach_robot(writer, urdf_path: Path, package_roots: dict[str, Path] | None, prov) -> None:
    """Copy the URDF with its meshes; without resolvable meshes copy it mesh-free and say so."""
    from .context import ConvertOptions, IngestContext
    from .progress import ProgressReporter
    from .robot import attach_robot

    ctx = IngestContext(writer, ConvertOptions(), prov, ProgressReporter(False))
    try:
        attach_robot(ctx, urdf_path, package_roots=package_roots)
        return
    except RobogsError as exc:
        writer.remove("robot")
        reason = exc.message
    data, n = _strip_meshes(urdf_path)
    writer.write_bytes("robot/robot.urdf", data)
    from robogs.format.kinematics import Chain

    urdf = load_urdf(urdf_path, load_meshes=False)
    root = Chain.from_urdf(urdf).link_names[0]
    writer.set_robot("robot/robot.urdf", base_link=root)
    prov.note(
        f"robot meshes not copied ({reason}); {n} mesh geometries removed from the URDF "
        "(loaded with load_meshes=False)"
    )
    prov.extra["robot"] = {"urdf": urdf_path.name, "meshes": 0, "root_link": root}


def _resolve_time(path: Path, raw: _Raw, cmap: ColumnMap, prov) -> None:
    """Settle the time unit of an automatic mapping (from its name, or guessed) and say so."""
    if cmap.layout == "map":
        return
    if cmap.time_unit == "auto":
        col = raw.data.get(cmap.time_column)
        try:
            unit, why = guess_time_unit(_to_float(col)[0] if col is not None else np.zeros(0))
        except ValueError as exc:
            raise InputError(
                f"cannot tell the unit of time column {cmap.time_column!r} ({exc})",
                path=path,
                where=f"column {cmap.time_column!r}",
                hint="name it t_s, t_ms, t_us or t_ns, or pass --map with time: {column, unit}",
            ) from None
        cmap.time_unit, cmap.time_from = unit, f"guessed: {why}"
    elif cmap.layout == "rtde" and cmap.time_column == "timestamp":  # unit set by auto_mapping
        cmap.time_from = "UR RTDE timestamp (s)"
    else:
        cmap.time_from = f"column name {cmap.time_column!r}"
    prov.note(
        f"{path.name}: time column {cmap.time_column!r} read in {cmap.time_unit} "
        f"({cmap.time_from}); a map with 'time: {{column, unit}}' overrides it"
    )


def write_tabular(
    writer,
    log_path: Path,
    *,
    urdf_path: Path,
    mapping: Path | None,
    prov,
    gap_s: float | None = None,
) -> list[str]:
    """Read the logs and write episodes and ``physics.json`` through ``writer``.

    Returns:
        The episode ids written.
    """
    from robogs.format.differentiate import describe_differentiator
    from robogs.format.kinematics import Chain

    urdf = load_urdf(urdf_path, load_meshes=False)
    chain = Chain.from_urdf(urdf)
    joint_names = list(chain.joint_names)
    lower, upper = np.asarray(chain.joint_lower), np.asarray(chain.joint_upper)
    fixed_map = read_mapping(mapping, joint_names) if mapping is not None else None
    hold = fixed_map.hold if fixed_map is not None else {}
    for j, v in hold.items():
        k = joint_names.index(j)
        if not lower[k] - 1e-12 <= v <= upper[k] + 1e-12:
            raise InputError(
                f"held position {v:g} of joint {j!r} is outside its URDF limits "
                f"[{lower[k]:g}, {upper[k]:g}]",
                path=mapping,
                where=f"hold/{j}",
                hint="positions are in rad (revolute) or m (prismatic)",
            )
    logged = [j for j in joint_names if j not in hold]
    if not logged:
        raise InputError("every joint is held; the log maps none", path=mapping, where="hold")
    ee_spec = fixed_map.ee_pose if fixed_map is not None else None
    if ee_spec is not None:
        resolve_frame(ee_spec, chain, mapping)
    files = _log_files(Path(log_path))
    used: set[str] = set()
    written: list[str] = []
    maps: dict[str, Any] = {}
    for f in files:
        raw = read_log_file(f)
        if fixed_map is not None and fixed_map.joints:
            cmap = fixed_map
        else:
            cmap = auto_mapping(raw.columns, logged, f)
            if fixed_map is not None:
                cmap.hold, cmap.gap_s = dict(hold), fixed_map.gap_s
                cmap.ee_pose = ee_spec
        _resolve_time(f, raw, cmap, prov)
        if cmap.segment_column is None:
            cmap.segment_column = next((c for c in SEGMENT_COLUMNS if c in raw.data), None)
        maps[f.name] = cmap.to_dict()
        segs, rep = _clean_file(
            f, raw, cmap, joint_names, lower, upper, gap_s if gap_s is not None else cmap.gap_s
        )
        rec = prov.topic(f.name, f.suffix.lstrip(".").lower(), "joint_states")
        rec.messages += rep.rows
        rec.written += rep.written
        rec.stamp_source = "log_time"
        for reason, lns in rep.dropped.items():
            prov.drop(f.name, reason, len(lns))
            first = ", ".join(str(x) for x in lns[:_EXAMPLES])
            prov.note(
                f"{f.name}: {len(lns)} row(s) dropped: {reason} (line {first}{', ...' if len(lns) > _EXAMPLES else ''})"
            )
        for note in rep.notes:
            prov.note(f"{f.name}: {note}")
        if cmap.layout == "rtde" and any(c.startswith("actual_current_") for c in raw.columns):
            prov.note(
                f"{f.name}: efforts from target_moment_* (N m); actual_current_* (A) ignored "
                "(map them with torque constants to use them)"
            )
        if all(jc.effort is None for jc in cmap.joints.values()):
            prov.note(f"{f.name}: no effort columns")
        if ee_spec is not None:
            ee_rec = prov.topic(f"{f.name}#ee_pose", f.suffix.lstrip(".").lower(), "ee_poses")
            ee_rec.messages += rep.ee_rows
            ee_rec.written += rep.ee_written
            ee_rec.stamp_source = "log_time"
            if rep.ee_dropped:
                reason = "empty, NaN or unparseable pose value"
                prov.drop(f"{f.name}#ee_pose", reason, len(rep.ee_dropped))
                first = ", ".join(str(x) for x in rep.ee_dropped[:_EXAMPLES])
                prov.note(
                    f"{f.name}: {len(rep.ee_dropped)} end-effector pose(s) dropped: {reason} "
                    f"(line {first}{', ...' if len(rep.ee_dropped) > _EXAMPLES else ''}; "
                    "the joint rows are kept)"
                )
        elif any(c.startswith("O_T_EE") for c in raw.columns):
            prov.note(
                f"{f.name}: O_T_EE* ignored (declare its link in the map to import it: "
                "'ee_pose: {link: panda_hand_tcp, format: matrix_colmajor}')"
            )
        elif any(c.startswith("actual_TCP_pose_") for c in raw.columns):
            prov.note(
                f"{f.name}: actual_TCP_pose_* ignored (declare its link in the map to import it: "
                "'ee_pose: {link: tool0, format: axis_angle}')"
            )
        if hold:
            prov.note(
                f"{f.name}: joints not in the log, held at a constant position (rad or m): "
                + ", ".join(f"{j} = {v:g}" for j, v in hold.items())
            )
        named: dict[str | None, int] = {}
        for seg in segs:
            named[seg.name] = named.get(seg.name, 0) + 1
        seen: dict[str | None, int] = {}
        for seg in segs:
            if seg.name is None:
                eid = _episode_id(f.stem, seg.index, len(segs), used)
                segment = f"{f.name}#{seg.index}"
            else:
                k = seen[seg.name] = seen.get(seg.name, -1) + 1
                eid = _episode_id(seg.name, k, named[seg.name], used)
                segment = seg.name
            rel = f"episodes/{eid}/joint_states.parquet"
            writer.write_table(rel, _joint_table(seg, joint_names), kind="joint_states")
            ee_streams: dict[str, Any] = {}
            if ee_spec is not None and seg.ee is not None and len(seg.ee):
                ee_rel = f"episodes/{eid}/ee_poses.parquet"
                writer.write_table(ee_rel, _ee_table(seg, ee_spec.link), kind="ee_poses")
                ee_steps = np.diff(seg.ee_t_ns)
                ee_streams["ee_poses"] = {
                    "kind": "ee_poses",
                    "path": ee_rel,
                    "stamp_source": "log_time",
                    "offset_ns": int(cmap.epoch_ns),
                    "source": f.name,
                    "nominal_rate_hz": float(1e9 / np.median(ee_steps)) if len(ee_steps) else None,
                }
            stream: dict[str, Any] = {
                "kind": "joint_states",
                "path": rel,
                "stamp_source": "log_time",
                "offset_ns": int(cmap.epoch_ns),
                "source": f.name,
            }
            steps = np.diff(seg.t_ns)
            stream["nominal_rate_hz"] = float(1e9 / np.median(steps)) if len(steps) else None
            derived = [f"position.{j}" for j in hold]
            if seg.derived_velocity:
                derived += [f"velocity.{j}" for j in joint_names]
                prov.note(f"velocities derived from positions: {describe_differentiator(1)}")
            elif hold:
                derived += [f"velocity.{j}" for j in hold]
            if derived:
                stream["derived"] = derived
            writer.add_episode(
                eid,
                start_ns=int(seg.t_ns[0]),
                end_ns=int(seg.t_ns[-1]),
                streams={"joint_states": stream, **ee_streams},
                segment=segment,
            )
            written.append(eid)
    if not written:
        raise InputError("nothing was converted (every row was dropped)", path=log_path)
    prov.extra["mapping"] = maps
    prov.extra["files"] = [f.name for f in files]
    if ee_spec is not None:  # the link the kinematic model explains (set_robot keeps it)
        writer.manifest["robot"] = {**(writer.manifest.get("robot") or {}), "ee_link": ee_spec.link}
    writer.set_physics(_physics_from_urdf(urdf), note="joint dynamics from the URDF")
    return written


def convert_tabular(
    log_path: str | Path,
    out: str | Path,
    *,
    urdf: str | Path,
    mapping: str | Path | None = None,
    force: bool = False,
    gap_s: float | None = None,
    package_roots: dict[str, str | Path] | None = None,
) -> Path:
    """Convert joint logs into a new dataset (atomically).

    Args:
        log_path: a CSV/Parquet file or a folder of them.
        out: dataset folder to create.
        urdf: robot URDF (copied into ``robot/`` with its meshes when they resolve).
        mapping: YAML column map (default: automatic layouts).
        force: replace an existing dataset at ``out``.
        gap_s: segment split threshold, s (default: max(1 s, 50 median steps)).
        package_roots: ``package://NAME`` -> folder for the URDF's meshes.

    Returns:
        ``out``.

    Raises:
        InputError: unusable logs or mapping (file, row and column named).
    """
    from .provenance import Provenance

    log_path, out, urdf_path = Path(log_path), Path(out), Path(urdf)
    if not urdf_path.is_file():
        raise InputError("URDF file not found", path=urdf_path)
    _log_files(log_path)
    prov = Provenance("tabular", log_path.name)
    writer = Dataset.create(out, overwrite=force, protect=[log_path, urdf_path])
    with writer:
        write_tabular(
            writer,
            log_path,
            urdf_path=urdf_path,
            mapping=Path(mapping) if mapping else None,
            prov=prov,
            gap_s=gap_s,
        )
        _attach_robot(
            writer, urdf_path, {k: Path(v) for k, v in (package_roots or {}).items()} or None, prov
        )
        writer.manifest["provenance"] = prov.to_dict()
        writer.commit()
    return out


def _convert(src: Path, ctx) -> None:
    """Registry entry: write the episodes through the driver's writer (robot attached by it)."""
    mapping = getattr(ctx.options, "mapping", None)
    write_tabular(
        ctx.writer, Path(src), urdf_path=_require_urdf(ctx), mapping=mapping, prov=ctx.provenance
    )


def _require_urdf(ctx) -> Path:
    if ctx.options.urdf is None:
        raise InputError("a joint log needs the robot: pass --urdf URDF", where="--urdf")
    return Path(ctx.options.urdf)


def _register() -> None:
    try:
        from ..registry import register_converter
    except ImportError:  # pragma: no cover - registry not installed
        return
    try:
        register_converter(
            "tabular",
            detect_tabular,
            _convert,
            description="CSV/Parquet joint logs (UR RTDE, Franka-like, generic, or --map YAML)",
            priority=-10,
        )
    except ValueError:
        pass


_register()

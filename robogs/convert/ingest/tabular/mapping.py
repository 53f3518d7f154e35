"""Mapping a log's columns onto the robot's joints: a user YAML map or the automatic layouts.

:func:`read_mapping` reads a ``--map`` YAML (format in :mod:`robogs.convert.ingest.tabular`);
:func:`auto_mapping` recognises UR RTDE, Franka and generic indexed or named columns from the
header; :func:`infer_ee_pose` picks up UR RTDE's ``actual_TCP_pose_0..5`` and Franka's
``O_T_EE_0..15``; :func:`resolve_time` settles
a time unit left to be guessed from the values and says how it was chosen.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import InputError

from ..yamlio import read_yaml
from .pose import EePoseColumns, read_ee_pose
from .reading import TIME_SCALE, RawLog, guess_time_unit, to_float

__all__ = [
    "ColumnMap",
    "JointColumns",
    "EE_POSE_PREFIXES",
    "SEGMENT_COLUMNS",
    "auto_mapping",
    "infer_ee_pose",
    "read_mapping",
    "resolve_time",
]

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
_MAX_MAP_BYTES = 1 << 20


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


#: libfranka ``RobotState.O_T_EE``: the end-effector frame in the base frame ``O``, 4x4 column-major
_FRANKA_EE = "O_T_EE"
#: UR RTDE ``actual_TCP_pose``: the TCP in the controller's base frame, ``x y z`` m and the rotation
#: vector ``rx ry rz`` rad (axis times angle)
_RTDE_TCP = "actual_TCP_pose"
#: ur_description's link for the controller's base frame (``base_link`` turned by pi about z)
_UR_BASE = "base"
#: ur_description's flange link, the TCP when the controller has no TCP offset configured
_UR_TOOL = "tool0"
#: header prefixes :func:`infer_ee_pose` reads
EE_POSE_PREFIXES = (_FRANKA_EE, _RTDE_TCP)


def infer_ee_pose(columns: list[str], link_names: list[str]) -> tuple[EePoseColumns | None, str]:
    """UR RTDE ``actual_TCP_pose_0..5`` or Franka ``O_T_EE_0..15`` as an ``ee_pose`` spec, with
    a sentence saying how it is read (or, when ``spec`` is None, why it is not).

    * RTDE (Universal Robots, "Real-Time Data Exchange" guide): ``actual_TCP_pose`` is ``x y z``
      (m) and the rotation vector ``rx ry rz`` (rad) of the TCP in the controller's base frame.
      ur_description names that frame ``base`` (a fixed child of ``base_link``, turned by pi
      about z) and the flange ``tool0``; the poses are read as ``tool0`` in ``base`` (in the
      root link when the URDF has no ``base``). A TCP offset set on the controller moves the
      recorded point off ``tool0``: a map's ``ee_pose`` then names the right link.
    * Franka: ``O_T_EE`` is ``T_O_EE`` column by column (libfranka ``RobotState``), ``O`` the
      robot base (the URDF root link). The link is the URDF's ``*hand_tcp`` (the end effector
      libfranka reports with a Franka Hand), else, in a URDF without a hand, its ``*link8``
      (the flange, the end effector with no hand configured).

    Other robots' links are not guessed: a map's ``ee_pose`` section names them.

    Args:
        columns: the log's header.
        link_names: the robot's links, root first.

    Returns:
        ``(spec, why)``; ``spec`` is None when the columns are not all there or no link fits.
    """
    names = set(columns)
    rtde = _zero_based(_indexed_family(names, _RTDE_TCP))
    if rtde:
        return _infer_rtde(rtde, link_names)
    cols = _zero_based(_indexed_family(names, _FRANKA_EE))
    if sorted(cols) != list(range(16)):
        return None, f"{_FRANKA_EE}* ignored ({_FRANKA_EE} needs 16 columns {_FRANKA_EE}_0..15"
    tcp = [n for n in link_names if re.search(r"(^|_)hand_tcp$", n)]
    hands = [n for n in link_names if re.search(r"(^|_)hand$", n)]
    flange = [n for n in link_names if re.search(r"(^|_)link8$", n)]
    if len(tcp) == 1:
        link, why = tcp[0], "the hand's TCP link, libfranka's end effector with a Franka Hand"
    elif not hands and len(flange) == 1:
        link, why = flange[0], "the flange link, libfranka's end effector without a hand"
    else:
        return None, (
            f"{_FRANKA_EE}* ignored (the URDF has no Franka end-effector link: one *hand_tcp, "
            "or *link8 without a hand"
        )
    spec = EePoseColumns(link, "matrix_colmajor", [cols[i] for i in range(16)])
    root = link_names[0] if link_names else "?"
    return spec, (
        f"{spec.columns[0]}..{spec.columns[-1]} read as the column-major 4x4 pose of link "
        f"{link!r} in the root link {root!r} (libfranka O_T_EE; link guessed: {why})"
    )


def _infer_rtde(cols: dict[int, str], link_names: list[str]) -> tuple[EePoseColumns | None, str]:
    if sorted(cols) != list(range(6)):
        return None, f"{_RTDE_TCP}* ignored ({_RTDE_TCP} needs 6 columns {_RTDE_TCP}_0..5"
    if _UR_TOOL not in link_names:
        return None, (
            f"{_RTDE_TCP}* ignored (the URDF has no UR flange link {_UR_TOOL!r}, the TCP "
            "without a controller TCP offset"
        )
    frame = _UR_BASE if _UR_BASE in link_names else None
    spec = EePoseColumns(_UR_TOOL, "axis_angle", [cols[i] for i in range(6)], frame=frame)
    where = (
        f"UR's controller base frame, link {_UR_BASE!r}"
        if frame
        else f"the root link {link_names[0]!r} (the URDF has no UR {_UR_BASE!r} link)"
    )
    return spec, (
        f"{spec.columns[0]}..{spec.columns[-1]} read as the UR RTDE TCP pose (x y z m, rotation "
        f"vector rad) of link {_UR_TOOL!r} in {where}; a TCP offset set on the controller "
        "moves it off tool0"
    )


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
    elif cmap.layout == "rtde" and cmap.time_column == "timestamp":  # unit set by auto_mapping
        cmap.time_from = "UR RTDE timestamp (s)"
    else:
        cmap.time_from = f"column name {cmap.time_column!r}"
    prov.note(
        f"{path.name}: time column {cmap.time_column!r} read in {cmap.time_unit} "
        f"({cmap.time_from}); a map with 'time: {{column, unit}}' overrides it"
    )

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
(:mod:`robogs.convert.ingest.tabular.pose`); a map with only ``ee_pose`` (and ``hold``, ``gap_s``)
keeps the automatic layouts for the joints. Without one, UR RTDE's ``actual_TCP_pose_0..5`` is read
as ``tool0`` in UR's ``base`` link, and Franka's ``O_T_EE_0..15`` (libfranka:
the column-major 4x4 ``T_O_EE``) is read as the pose of the URDF's ``*hand_tcp`` link, or of its
``*link8`` flange when the URDF has no hand (:func:`~.mapping.infer_ee_pose`; the provenance
says which).

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

The package is split by job: :mod:`.reading` (files into columns, stamps, time-unit guess),
:mod:`.column_map` (:class:`ColumnMap`, which columns hold what), :mod:`.user_map` (the
``--map`` YAML), :mod:`.layouts` (columns inferred from the header, one module per layout: UR
RTDE, Franka, generic), :mod:`.mapping` (the map a file is read with), :mod:`.cleaning` (drops
and segments), :mod:`.pose` (end-effector poses), :mod:`.writing` (episodes through the dataset
writer) and :mod:`.options` (:class:`TabularOptions` and its CLI flags). The one driver is
:func:`robogs.convert.ingest.convert.convert_path`; :func:`convert_tabular` is a deprecated
alias of it.
"""

from __future__ import annotations

import warnings
from pathlib import Path

from .cleaning import LogSegment
from .column_map import ColumnMap, JointColumns
from .layouts import auto_mapping, infer_ee_pose
from .options import TabularOptions, add_arguments, options_from_args
from .reading import detect_tabular, guess_time_unit, read_log_file, to_ns
from .user_map import read_mapping
from .writing import convert, write_tabular

__all__ = [
    "ColumnMap",
    "JointColumns",
    "LogSegment",
    "TabularOptions",
    "add_arguments",
    "auto_mapping",
    "convert_tabular",
    "detect_tabular",
    "guess_time_unit",
    "infer_ee_pose",
    "options_from_args",
    "read_log_file",
    "read_mapping",
    "write_tabular",
]

_to_ns = to_ns  # the name of the hardening regression tests


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
    """Deprecated: ``convert_path(log_path, out, fmt="tabular", options=...)`` with
    ``ConvertOptions(urdf=urdf, source=TabularOptions(mapping, gap_s, meshes_optional=True))``.

    Converts joint logs into a new dataset (atomically) through the one driver, with
    ``meshes_optional``: a URDF whose meshes do not resolve is copied without them.

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
    from robogs.format.errors import InputError

    from ..context import ConvertOptions
    from ..convert import convert_path

    warnings.warn(
        "convert_tabular is deprecated: use robogs.convert.ingest.convert.convert_path(src, out, "
        'fmt="tabular", options=ConvertOptions(urdf=..., source=TabularOptions(...)))',
        DeprecationWarning,
        stacklevel=2,
    )
    urdf_path = Path(urdf)
    if not urdf_path.is_file():
        raise InputError("URDF file not found", path=urdf_path)
    opts = ConvertOptions(
        urdf=urdf_path,
        package_roots={k: Path(v) for k, v in (package_roots or {}).items()},
        source=TabularOptions(Path(mapping) if mapping else None, gap_s, meshes_optional=True),
    )
    convert_path(log_path, out, fmt="tabular", options=opts, force=force)
    return Path(out)


def _register() -> None:
    from ...registry import register_converter

    try:
        register_converter(
            "tabular",
            detect_tabular,
            convert,
            description="CSV/Parquet joint logs (UR RTDE, Franka-like, generic, or --map YAML)",
            priority=-10,
        )
    except ValueError:  # registered already (a module reload)
        pass


_register()

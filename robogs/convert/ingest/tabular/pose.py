"""Recorded end-effector (TCP) poses in a tabular joint log, written as an ``ee_poses`` stream.

A column map (``robogs convert LOG OUT --urdf URDF --map MAP.yaml``) declares them in an
``ee_pose`` section; a map holding only ``ee_pose`` (and ``hold``, ``gap_s``) keeps the
automatic joint layouts::

    ee_pose:
      link: tool0                  # URDF link whose pose the columns hold (required)
      format: axis_angle           # axis_angle | matrix_colmajor | matrix_rowmajor | quaternion
      columns: actual_TCP_pose_    # a prefix (+ 0..n-1), a pattern with {i}, or a list of n names
      unit: m                      # position unit: m | mm
      frame: base_link             # URDF link the poses are given in (default: the root link)

Formats (``n`` values per row; rotations in rad):

* ``axis_angle`` (n = 6): ``x y z rx ry rz``, position and rotation vector (axis times angle).
  UR RTDE ``actual_TCP_pose``; default columns ``actual_TCP_pose_0..5``.
* ``matrix_colmajor`` (n = 16): the 4x4 ``T_frame_link`` column by column. Franka
  ``O_T_EE``; default columns ``O_T_EE_0..15`` (read without a map too, see
  :func:`robogs.convert.ingest.tabular.layouts.infer_ee_pose`).
* ``matrix_rowmajor`` (n = 16): the same matrix row by row.
* ``quaternion`` (n = 7): ``x y z qw qx qy qz`` (a unit quaternion within 1 %; normalised).

The dataset's world is the robot's root link (``robot.base_link``); poses given in another
``frame`` are moved into it by that link's fixed transform (a frame that a joint moves is an
error). The pose of the row's stamp is ``T_world_link = T_world_frame · T_frame_link``,
stored as ``x y z`` m and ``qw qx qy qz`` (``w >= 0``). A row whose pose cells are empty, NaN or
not numbers loses its pose only (counted in the provenance); a matrix that is not a rigid
transform, or a quaternion far from unit length, is an error naming the file, line and columns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import InputError

__all__ = ["EePoseColumns", "FORMATS", "read_ee_pose", "resolve_frame", "pose_samples"]

FORMATS: dict[str, tuple[int, str | None]] = {
    "axis_angle": (6, "actual_TCP_pose_"),
    "matrix_colmajor": (16, "O_T_EE_"),
    "matrix_rowmajor": (16, None),
    "quaternion": (7, None),
}
"""format -> (values per row, default column prefix)."""

_POS_SCALE = {"m": 1.0, "mm": 1e-3}
_RIGID_TOL = 1e-4
_QUAT_TOL = 0.01


@dataclass
class EePoseColumns:
    """Where a log holds end-effector poses and how to read them.

    Attributes:
        link: URDF link whose pose the columns hold.
        format: one of :data:`FORMATS`.
        columns: the ``n`` source columns, in the format's order.
        scale: m per source position unit.
        frame: URDF link the poses are expressed in (None: the root link).
        T_world_frame: [4, 4] that frame in the world (set by :func:`resolve_frame`).
    """

    link: str
    format: str
    columns: list[str]
    scale: float = 1.0
    unit: str = "m"
    frame: str | None = None
    T_world_frame: np.ndarray = field(default_factory=lambda: np.eye(4))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description for the provenance."""
        out: dict[str, Any] = {
            "link": self.link,
            "format": self.format,
            "columns": list(self.columns),
            "unit": self.unit,
        }
        if self.frame is not None:
            out["frame"] = self.frame
        return out


def read_ee_pose(doc: Any, path: Path) -> EePoseColumns | None:
    """The ``ee_pose`` section of a parsed map (None when absent).

    Raises:
        InputError: not a mapping, no link, unknown format or unit, a column list of the wrong
            length, a prefix for a format without default names.
    """
    if doc is None:
        return None
    where = "ee_pose"
    example = "ee_pose: {link: tool0, format: axis_angle, columns: actual_TCP_pose_}"
    if not isinstance(doc, dict):
        raise InputError("'ee_pose' must be a mapping", path=path, where=where, hint=example)
    link = doc.get("link")
    if not isinstance(link, str) or not link:
        raise InputError(
            "ee_pose needs the URDF link whose pose the columns hold",
            path=path,
            where=f"{where}/link",
            hint=example,
        )
    fmt = str(doc.get("format", "axis_angle")).strip().lower()
    if fmt not in FORMATS:
        raise InputError(
            f"unknown ee_pose format {doc.get('format')!r}",
            path=path,
            where=f"{where}/format",
            hint=f"use one of {', '.join(FORMATS)}",
        )
    n, prefix = FORMATS[fmt]
    cols = doc.get("columns", prefix)
    if cols is None:
        raise InputError(
            f"ee_pose format {fmt} has no default column names",
            path=path,
            where=f"{where}/columns",
            hint=f"list its {n} columns, or give a prefix ('pose_' for pose_0..pose_{n - 1})",
        )
    if isinstance(cols, str):
        columns = [cols.format(i=i) if "{i}" in cols else f"{cols}{i}" for i in range(n)]
    elif isinstance(cols, list) and all(isinstance(c, str) for c in cols):
        columns = list(cols)
    else:
        raise InputError(
            "ee_pose columns must be a prefix or a list of column names",
            path=path,
            where=f"{where}/columns",
        )
    if len(columns) != n or len(set(columns)) != n:
        raise InputError(
            f"ee_pose format {fmt} needs {n} distinct columns, got {len(columns)}",
            path=path,
            where=f"{where}/columns",
            hint={
                "axis_angle": "x y z rx ry rz",
                "quaternion": "x y z qw qx qy qz",
            }.get(fmt, "the 16 entries of the 4x4 matrix"),
        )
    unit = str(doc.get("unit", "m")).strip().lower()
    if unit not in _POS_SCALE:
        raise InputError(
            f"unknown ee_pose position unit {doc.get('unit')!r}",
            path=path,
            where=f"{where}/unit",
            hint="use m or mm (rotations are in rad)",
        )
    frame = doc.get("frame")
    if frame is not None and not isinstance(frame, str):
        raise InputError(
            "ee_pose frame must be a URDF link name", path=path, where=f"{where}/frame"
        )
    return EePoseColumns(link, fmt, columns, _POS_SCALE[unit], unit, frame)


def resolve_frame(spec: EePoseColumns, chain: Any, map_path: Path | None) -> None:
    """Check the link and frame against the robot and set ``spec.T_world_frame``.

    Raises:
        InputError: the link or frame is not a link of the URDF, or a joint moves the frame
            relative to the root link.
    """
    for key, name in (("link", spec.link), ("frame", spec.frame)):
        if name is not None and name not in chain.link_names:
            raise InputError(
                f"ee_pose {key} {name!r} is not a link of the URDF",
                path=map_path,
                where=f"ee_pose/{key}",
                hint=f"links: {chain.link_names}",
            )
    if spec.frame is None or spec.frame == chain.link_names[0]:
        spec.T_world_frame = np.eye(4)
        return
    k = chain.link_index(spec.frame)
    while k > 0:
        jt = chain.joint_types[k - 1]
        if jt != "fixed":
            raise InputError(
                f"ee_pose frame {spec.frame!r} moves with joint {chain.tree_joint_names[k - 1]!r}",
                path=map_path,
                where="ee_pose/frame",
                hint="poses must be given in a frame fixed to the robot base",
            )
        k = chain.parents[k]
    zero = np.zeros(chain.num_joints)
    spec.T_world_frame = chain.forward(zero)[chain.link_index(spec.frame)].numpy()


def _rotvec_quat(r: np.ndarray) -> np.ndarray:
    """[N, 4] (w, x, y, z) of rotation vectors [N, 3] (rad): ``(cos(a/2), sin(a/2) r/a)``."""
    a = np.linalg.norm(r, axis=1)
    half = 0.5 * a
    small = a < 1e-8
    s = np.where(small, 0.5 - a * a / 48.0, np.sin(half) / np.where(small, 1.0, a))
    return np.concatenate([np.cos(half)[:, None], s[:, None] * r], axis=1)


def _matrix_quat(R: np.ndarray) -> np.ndarray:
    """[N, 4] (w, x, y, z) of rotation matrices [N, 3, 3] (Shepperd 1978)."""
    from robogs.format.frames import matrix_to_quat_np

    return matrix_to_quat_np(R)


def _rigid_error(M: np.ndarray) -> np.ndarray:
    """[N] worst deviation of 4x4 matrices [N, 4, 4] from a rigid transform."""
    R = M[:, :3, :3]
    ortho = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    last = np.abs(M[:, 3] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1)
    det = np.abs(np.linalg.det(R) - 1.0)
    return np.maximum(np.maximum(ortho, last), det)


def pose_samples(
    values: np.ndarray, spec: EePoseColumns, lines: np.ndarray, path: Path
) -> tuple[np.ndarray, np.ndarray]:
    """World poses of the log rows.

    Args:
        values: [N, n] the ``spec.columns`` as floats (NaN where empty or not a number).
        lines: [N] source line of each row (for errors).

    Returns:
        ``(pose [N, 7] x y z m, qw qx qy qz, world; usable [N] bool)``; rows with a non-finite
        value are not usable (their pose is NaN).

    Raises:
        InputError: a usable row holds a matrix that is not a rigid transform, or a
            quaternion whose norm is off by more than 1 %.
    """
    n = len(values)
    ok = np.isfinite(values).all(axis=1)
    v = np.where(ok[:, None], values, 0.0)
    cols = f"columns {spec.columns[0]!r}..{spec.columns[-1]!r}"
    if spec.format == "axis_angle":
        pos, quat = v[:, :3], _rotvec_quat(v[:, 3:6])
    elif spec.format == "quaternion":
        pos, q = v[:, :3], v[:, 3:7]
        norm = np.linalg.norm(q, axis=1)
        bad = ok & (np.abs(norm - 1.0) > _QUAT_TOL)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(
                f"quaternion norm {norm[i]:.6g} is not 1 (qw qx qy qz)",
                path=path,
                where=f"line {lines[i]}, {cols}",
                hint="the columns must be x y z qw qx qy qz with a unit quaternion "
                "(scalar first: reorder the list for x y z qx qy qz qw)",
            )
        quat = q / np.where(ok, norm, 1.0)[:, None]
    else:
        M = v.reshape(n, 4, 4)
        if spec.format == "matrix_colmajor":
            M = M.transpose(0, 2, 1)
        err = np.where(ok, _rigid_error(M), 0.0)
        bad = err > _RIGID_TOL
        if bad.any():
            i = int(np.argmax(bad))
            other = "matrix_rowmajor" if spec.format == "matrix_colmajor" else "matrix_colmajor"
            flipped = _rigid_error(M[i : i + 1].transpose(0, 2, 1))[0] <= _RIGID_TOL
            raise InputError(
                f"the {spec.format} values are not a rigid transform (off by {err[i]:.3g})",
                path=path,
                where=f"line {lines[i]}, {cols}",
                hint=(
                    f"they read as one in the other order: use 'format: {other}'"
                    if flipped
                    else "16 values of a 4x4 homogeneous matrix with an orthonormal rotation "
                    "and last row 0 0 0 1"
                ),
            )
        pos, quat = M[:, :3, 3], _matrix_quat(M[:, :3, :3])
    pos = pos * spec.scale
    Tw = spec.T_world_frame
    if not np.array_equal(Tw, np.eye(4)):
        import torch

        from robogs.format.frames import quat_to_matrix

        R = quat_to_matrix(torch.as_tensor(quat, dtype=torch.float64)).numpy()
        pos = pos @ Tw[:3, :3].T + Tw[:3, 3]
        quat = _matrix_quat(Tw[:3, :3] @ R)
    quat = quat * np.where(quat[:, :1] < 0, -1.0, 1.0)
    out = np.concatenate([pos, quat], axis=1)
    out[~ok] = math.nan
    return out, ok

"""Modified Denavit-Hartenberg tables (Craig's convention), batched in torch.

Craig, *Introduction to Robotics: Mechanics and Control* (3rd ed., 2005), §3.4: the transform
from frame i-1 to frame i is

    ^{i-1}T_i = RotX(alpha_{i-1}) @ TransX(a_{i-1}) @ RotZ(theta_i) @ TransZ(d_i),
    theta_i   = theta_offset_i + q_i.

This is the convention of Robo-GS (``kinematic/control_helper.py::create_transformation_matrix_mdh``
in the Robostudio code), without its 1 mrad rounding of measured angles. Row i of a table
(i = 1..n) holds ``a_{i-1}``, ``alpha_{i-1}``, ``d_i`` and ``theta_offset_i``. A fixed
``T_base`` (``T_world_0``: root frame to DH frame 0) and ``T_tool`` (``T_n_tool``: last DH frame
to the tool/flange) complete the chain. The JSON form is the dataset's ``robot/mdh.json``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics.joint_values import as_joint_tensor

__all__ = ["MDHTable", "MDH_CONVENTION", "load_mdh_json", "save_mdh_json", "mdh_transform"]

MDH_CONVENTION = "modified_dh_craig"
"""Value of the ``convention`` field of ``robot/mdh.json``."""


def _rigid_or_raise(T: Any, name: str, path: str | Path | None) -> np.ndarray:
    M = np.asarray(T, dtype=np.float64)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise FormatError(f"{name} must be a finite 4x4 matrix", path=path, where=name)
    R = M[:3, :3]
    if (
        not np.allclose(M[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9)
        or not np.allclose(R.T @ R, np.eye(3), atol=1e-6)
        or np.linalg.det(R) < 0
    ):
        raise FormatError(
            f"{name} is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)",
            path=path,
            where=name,
        )
    return M


def mdh_transform(
    a: torch.Tensor, alpha: torch.Tensor, d: torch.Tensor, theta: torch.Tensor
) -> torch.Tensor:
    """``RotX(alpha) @ TransX(a) @ RotZ(theta) @ TransZ(d)`` element-wise.

    Args:
        a: [...] metres.
        alpha: [...] radians.
        d: [...] metres.
        theta: [...] radians (all four broadcast together).

    Returns:
        [..., 4, 4] transforms ``^{i-1}T_i``.
    """
    a, alpha, d, theta = torch.broadcast_tensors(a, alpha, d, theta)
    ca, sa = torch.cos(alpha), torch.sin(alpha)
    ct, st = torch.cos(theta), torch.sin(theta)
    o, i = torch.zeros_like(a), torch.ones_like(a)
    rows = (
        ct, -st, o, a,
        st * ca, ct * ca, -sa, -d * sa,
        st * sa, ct * sa, ca, d * ca,
        o, o, o, i,
    )  # fmt: skip
    return torch.stack(rows, dim=-1).reshape(*a.shape, 4, 4)


@dataclass
class MDHTable:
    """A serial arm in Craig's modified DH convention.

    Attributes:
        a_m: [n] ``a_{i-1}``, metres.
        alpha_rad: [n] ``alpha_{i-1}``, radians.
        d_m: [n] ``d_i``, metres.
        theta_offset_rad: [n] ``theta_i`` at ``q_i = 0``, radians.
        joint_names: [n] names of the joints (order of ``q``).
        T_base: [4, 4] ``T_world_0`` (root/world frame to DH frame 0).
        T_tool: [4, 4] ``T_n_tool`` (last DH frame to the tool/flange frame).
    """

    a_m: np.ndarray
    alpha_rad: np.ndarray
    d_m: np.ndarray
    theta_offset_rad: np.ndarray
    joint_names: list[str]
    T_base: np.ndarray = field(default_factory=lambda: np.eye(4))
    T_tool: np.ndarray = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        self.a_m = np.asarray(self.a_m, dtype=np.float64).reshape(-1)
        self.alpha_rad = np.asarray(self.alpha_rad, dtype=np.float64).reshape(-1)
        self.d_m = np.asarray(self.d_m, dtype=np.float64).reshape(-1)
        self.theta_offset_rad = np.asarray(self.theta_offset_rad, dtype=np.float64).reshape(-1)
        self.joint_names = [str(n) for n in self.joint_names]
        n = len(self.joint_names)
        for name in ("a_m", "alpha_rad", "d_m", "theta_offset_rad"):
            arr = getattr(self, name)
            if arr.shape != (n,):
                raise FormatError(
                    f"{name} has {arr.shape[0]} entries, expected {n} (one per joint)",
                    where=name,
                )
            if not np.all(np.isfinite(arr)):
                raise FormatError(f"{name} has non-finite values", where=name)
        if len(set(self.joint_names)) != n:
            raise FormatError("joint_names has duplicates", where="joint_names")
        self.T_base = _rigid_or_raise(self.T_base, "T_base", None)
        self.T_tool = _rigid_or_raise(self.T_tool, "T_tool", None)

    @property
    def num_joints(self) -> int:
        """n, the number of joints (rows)."""
        return len(self.joint_names)

    @classmethod
    def from_standard_dh(
        cls,
        a_m: Sequence[float],
        alpha_rad: Sequence[float],
        d_m: Sequence[float],
        theta_offset_rad: Sequence[float],
        joint_names: Sequence[str],
        T_base: np.ndarray | None = None,
        T_tool: np.ndarray | None = None,
    ) -> MDHTable:
        """Convert a standard (distal) DH table to the modified convention.

        Standard DH: ``^{i-1}T_i = RotZ(theta_i) TransZ(d_i) TransX(a_i) RotX(alpha_i)``.
        Regrouping the product (``TransX`` and ``RotX`` commute) gives modified rows with
        ``a_{i-1}, alpha_{i-1}`` taken from the previous standard row (zero for the first) and
        the last row's ``TransX(a_n) RotX(alpha_n)`` folded into ``T_tool``. The tool pose is
        identical; intermediate frame i of the result is the standard frame i-1 moved onto
        joint i's axis.

        Args:
            a_m, alpha_rad, d_m, theta_offset_rad: [n] standard DH parameters (row i = joint i).
            joint_names: [n] joint names.
            T_base: [4, 4] root frame to DH frame 0 (identity by default).
            T_tool: [4, 4] standard frame n to the tool (identity by default).

        Returns:
            The equivalent :class:`MDHTable`.
        """
        a = np.asarray(a_m, dtype=np.float64)
        al = np.asarray(alpha_rad, dtype=np.float64)
        if a.ndim != 1 or a.shape != al.shape or a.size == 0:
            raise InputError("standard DH a and alpha must be equal-length non-empty vectors")
        tail = np.eye(4)
        ca, sa = math.cos(al[-1]), math.sin(al[-1])
        tail[:3, :3] = [[1, 0, 0], [0, ca, -sa], [0, sa, ca]]
        tail[0, 3] = a[-1]
        T_tool = tail @ (np.eye(4) if T_tool is None else np.asarray(T_tool, dtype=np.float64))
        return cls(
            a_m=np.concatenate(([0.0], a[:-1])),
            alpha_rad=np.concatenate(([0.0], al[:-1])),
            d_m=d_m,
            theta_offset_rad=theta_offset_rad,
            joint_names=list(joint_names),
            T_base=np.eye(4) if T_base is None else T_base,
            T_tool=T_tool,
        )

    # ------------------------------------------------------------------ kinematics

    def _check_q(self, q: torch.Tensor) -> torch.Tensor:
        return as_joint_tensor(q, self.joint_names)

    def joint_transforms(self, q: torch.Tensor) -> torch.Tensor:
        """Per-joint transforms ``^{i-1}T_i``.

        Args:
            q: [..., n] joint angles, radians.

        Returns:
            [..., n, 4, 4].
        """
        q = self._check_q(q)

        def tt(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(x, dtype=q.dtype, device=q.device)

        theta = tt(self.theta_offset_rad) + q
        return mdh_transform(tt(self.a_m), tt(self.alpha_rad), tt(self.d_m), theta)

    def forward(self, q: torch.Tensor) -> torch.Tensor:
        """Poses of DH frames 0..n in the world (root) frame.

        Args:
            q: [..., n] joint angles in radians, ``joint_names`` order; any batch shape,
                float32/float64, CPU/CUDA.

        Returns:
            [..., n+1, 4, 4]: index 0 is ``T_base`` (frame 0, fixed), index i is
            ``T_world_i = T_base @ ^0T_1 @ ... @ ^{i-1}T_i``. Differentiable in ``q``.
        """
        Ts = self.joint_transforms(q)
        base = torch.as_tensor(self.T_base, dtype=Ts.dtype, device=Ts.device)
        out = [base.expand(*Ts.shape[:-3], 4, 4)]
        for i in range(self.num_joints):
            out.append(out[-1] @ Ts[..., i, :, :])
        return torch.stack(out, dim=-3)

    def tool_pose(self, q: torch.Tensor) -> torch.Tensor:
        """``T_world_tool = forward(q)[..., n] @ T_tool``.

        Args:
            q: [..., n] joint angles, radians.

        Returns:
            [..., 4, 4] tool (flange) pose in the world frame.
        """
        last = self.forward(q)[..., -1, :, :]
        return last @ torch.as_tensor(self.T_tool, dtype=last.dtype, device=last.device)

    # ------------------------------------------------------------------ JSON

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the ``robot/mdh.json`` layout); floats round-trip exactly."""
        return {
            "convention": MDH_CONVENTION,
            "joint_names": list(self.joint_names),
            "a_m": self.a_m.tolist(),
            "alpha_rad": self.alpha_rad.tolist(),
            "d_m": self.d_m.tolist(),
            "theta_offset_rad": self.theta_offset_rad.tolist(),
            "T_base": self.T_base.tolist(),
            "T_tool": self.T_tool.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, path: str | Path | None = None) -> MDHTable:
        """Build a table from the ``robot/mdh.json`` layout.

        Args:
            data: dict with ``joint_names``, ``a_m``, ``alpha_rad``, ``d_m``,
                ``theta_offset_rad`` and optional ``T_base``, ``T_tool`` (4x4 nested lists,
                identity when absent) and ``convention`` (must be ``"modified_dh_craig"``).
            path: file the dict came from, for error messages.

        Raises:
            FormatError: missing fields, wrong lengths, non-rigid transforms.
        """
        if not isinstance(data, Mapping):
            raise FormatError("MDH table must be a JSON object", path=path)
        conv = data.get("convention", MDH_CONVENTION)
        if conv != MDH_CONVENTION:
            raise FormatError(
                f"unsupported DH convention '{conv}'",
                path=path,
                where="convention",
                hint=f"use '{MDH_CONVENTION}' (or convert with MDHTable.from_standard_dh)",
            )
        missing = [
            k
            for k in ("joint_names", "a_m", "alpha_rad", "d_m", "theta_offset_rad")
            if k not in data
        ]
        if missing:
            raise FormatError(f"MDH table misses fields {missing}", path=path)
        try:
            T_base = _rigid_or_raise(data.get("T_base", np.eye(4)), "T_base", path)
            T_tool = _rigid_or_raise(data.get("T_tool", np.eye(4)), "T_tool", path)
            return cls(
                a_m=np.asarray(data["a_m"], dtype=np.float64),
                alpha_rad=np.asarray(data["alpha_rad"], dtype=np.float64),
                d_m=np.asarray(data["d_m"], dtype=np.float64),
                theta_offset_rad=np.asarray(data["theta_offset_rad"], dtype=np.float64),
                joint_names=list(data["joint_names"]),
                T_base=T_base,
                T_tool=T_tool,
            )
        except FormatError as exc:
            raise FormatError(exc.message, path=path, where=exc.where, hint=exc.hint) from None
        except (TypeError, ValueError) as exc:
            raise FormatError(f"MDH table has non-numeric values ({exc})", path=path) from None


def load_mdh_json(path: str | os.PathLike[str]) -> MDHTable:
    """Read an MDH table from a JSON file (``robot/mdh.json``).

    Raises:
        InputError: the file is missing.
        FormatError: not JSON, or an invalid table.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("MDH table file not found", path=p) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"not valid JSON ({exc.msg})", path=p, where=f"line {exc.lineno} column {exc.colno}"
        ) from None
    return MDHTable.from_dict(data, path=p)


def save_mdh_json(table: MDHTable, path: str | os.PathLike[str]) -> None:
    """Write an MDH table as indented JSON (exact float round trip)."""
    Path(path).write_text(json.dumps(table.to_dict(), indent=2) + "\n", encoding="utf-8")

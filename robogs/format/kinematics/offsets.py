"""Kinematic joint offsets of ``physics.json`` applied to a URDF chain.

A fit of the arm's kinematic model (``robogs fit --add kinematic_offsets``) stores per actuated
joint ``j`` in ``physics.json`` ``joints.<j>.offsets = {dtheta_rad, dd_m, da_m}``. The link
angle (or displacement, prismatic) is ``theta_j = q_j + dtheta_j`` with ``q_j`` the measured
joint value, and the joint frame is translated before its motion:

    T_parent_child = origin_j · Trans(da_j u_j + dd_j z_j) · Motion(z_j, q_j + dtheta_j)

``z_j`` is the unit joint axis and ``u_j`` (:func:`perpendicular`) the joint frame's x axis made
perpendicular to it (its y axis when the axis lies along x), both in the joint frame. On a URDF
written on modified-DH frames (origin ``RotX(alpha) TransX(a) TransZ(d)``, axis +z) ``u_j`` is
the common normal ``x_{j-1}``: ``da_j`` is Khalil & Kleinfinger's (1986) ``delta a_{j-1}``
and ``dd_j`` their ``delta d_j``. A mimic joint follows its source's link value
(``multiplier * (q + dtheta) + offset``); ``da`` and ``dd`` move only the actuated joint's frame.

Since ``Motion(z, q + dtheta) = Motion(z, dtheta) · Motion(z, q)``, every offset is a constant
change of the joint's ``origin`` (:func:`offset_origin`): a chain with the new origins, fed the
measured ``q``, is the fitted model. The same function rewrites the origins of an exported URDF.
This module is the one definition; the physics package's kinematic model is tested against it.

Joint compliance and backlash (``compliance_rad_per_nm``, ``backlash_rad``) are not constant
offsets (one needs gravity torques, the other the history of the motion) and are not applied
here.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import FormatError
from robogs.format.kinematics.chain import Chain

__all__ = [
    "OFFSET_KEYS",
    "JointOffsets",
    "perpendicular",
    "read_joint_offsets",
    "offset_origin",
    "chain_with_offsets",
    "fitted_chain",
    "dataset_fitted_chain",
]

OFFSET_KEYS: dict[str, str] = {"dtheta": "dtheta_rad", "dd": "dd_m", "da": "da_m"}
"""Parameter -> key in ``physics.json`` ``joints.<j>.offsets``."""


@dataclass(frozen=True)
class JointOffsets:
    """Offsets of one actuated joint.

    Attributes:
        dtheta: joint-zero offset, rad (m for a prismatic joint).
        dd: translation along the joint axis before the motion, m.
        da: translation along :func:`perpendicular` of the axis before the motion, m.
    """

    dtheta: float = 0.0
    dd: float = 0.0
    da: float = 0.0

    @property
    def is_zero(self) -> bool:
        return self.dtheta == 0.0 and self.dd == 0.0 and self.da == 0.0


def perpendicular(axis: np.ndarray) -> np.ndarray:
    """The declared perpendicular ``u`` of a joint frame: its x axis made perpendicular to the
    unit ``axis`` [3] (Gram-Schmidt), or its y axis when the axis lies along x."""
    axis = np.asarray(axis, dtype=np.float64)
    for e in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        u = e - (e @ axis) * axis
        n = float(np.linalg.norm(u))
        if n > 1e-6:
            return u / n
    raise AssertionError("unreachable: x and y cannot both be parallel to a unit axis")


def read_joint_offsets(
    physics: Mapping[str, Any] | None,
    joint_names: Iterable[str],
    *,
    path: str | Path | None = "physics.json",
) -> dict[str, JointOffsets]:
    """The non-zero offsets of the named joints in a ``physics.json`` document.

    Joints absent from ``joint_names`` (unknown, fixed or mimic joints) are ignored.

    Raises:
        FormatError: an offset is not a finite number.
    """
    table = (physics or {}).get("joints") or {}
    out: dict[str, JointOffsets] = {}
    for j in joint_names:
        entry = table.get(j) if isinstance(table, Mapping) else None
        off = entry.get("offsets") if isinstance(entry, Mapping) else None
        if not isinstance(off, Mapping):
            continue
        vals: dict[str, float] = {}
        for p, key in OFFSET_KEYS.items():
            v = off.get(key, 0.0)
            try:
                f = float(v)
            except (TypeError, ValueError):
                f = float("nan")
            if isinstance(v, bool) or not np.isfinite(f):
                raise FormatError(
                    f"joint offset {key} = {v!r} is not a finite number",
                    path=path,
                    where=f"joints.{j}.offsets.{key}",
                    hint="refit with robogs fit --add kinematic_offsets, or remove the entry",
                )
            vals[p] = f
        jo = JointOffsets(**vals)
        if not jo.is_zero:
            out[j] = jo
    return out


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def offset_origin(
    origin: np.ndarray,
    axis: np.ndarray,
    joint_type: str,
    *,
    dtheta: float = 0.0,
    dd: float = 0.0,
    da: float = 0.0,
) -> np.ndarray:
    """``origin · Trans(da u + dd z) · Motion(z, dtheta)`` of one joint.

    Args:
        origin: [4, 4] ``T_parent_jointframe`` (URDF ``<origin>``).
        axis: [3] joint axis in the joint frame (normalised here).
        joint_type: ``revolute``/``continuous`` (dtheta rad, a rotation about the axis) or
            ``prismatic`` (dtheta m, a translation along it); ``fixed`` takes no offset.
        dtheta, dd, da: the offsets (see the module docstring).

    Returns:
        [4, 4] float64, the origin the joint must have so that reading ``q`` it moves the
        child as the offset joint reading ``q`` would.
    """
    out = np.array(origin, dtype=np.float64, copy=True)
    if dtheta == 0.0 and dd == 0.0 and da == 0.0:
        return out
    if joint_type == "fixed":
        raise FormatError("a fixed joint has no kinematic offsets", where=f"type {joint_type}")
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    shift = da * perpendicular(z) + dd * z
    R = out[:3, :3].copy()
    if joint_type == "prismatic":
        shift = shift + dtheta * z
    elif joint_type in ("revolute", "continuous"):
        out[:3, :3] = R @ _rotation(z, dtheta)
    else:
        raise FormatError(f"joint type {joint_type!r} takes no kinematic offsets")
    out[:3, 3] = out[:3, 3] + R @ shift
    return out


def chain_with_offsets(chain: Chain, offsets: Mapping[str, JointOffsets]) -> Chain:
    """A copy of ``chain`` whose joint origins carry ``offsets`` (actuated joint -> offsets).

    Mimic joints of an offset joint turn (or slide) by ``multiplier * dtheta`` of their source;
    ``dd`` and ``da`` act on the actuated joint only. Names not in ``chain.joint_names`` are
    ignored. ``forward(q)`` of the copy is the fitted kinematic model at measured ``q``.
    """
    by_index = {chain.joint_names.index(j): o for j, o in offsets.items() if j in chain.joint_names}
    if not by_index:
        return chain
    origins = chain.origins.copy()
    for k, name in enumerate(chain.tree_joint_names):
        jt = chain.joint_types[k]
        if jt == "fixed":
            continue
        src = int(chain.source[k])
        off = by_index.get(src)
        if off is None:
            continue
        if name == chain.joint_names[src]:  # the actuated joint itself
            origins[k] = offset_origin(
                origins[k], chain.axes[k], jt, dtheta=off.dtheta, dd=off.dd, da=off.da
            )
        else:  # a mimic of it
            d = float(chain.multiplier[k]) * off.dtheta
            origins[k] = offset_origin(origins[k], chain.axes[k], jt, dtheta=d)
    return replace(chain, origins=origins, _cache={})


def fitted_chain(
    chain: Chain, physics: Mapping[str, Any], *, path: Path | str | None = None
) -> tuple[Chain, str]:
    """``chain`` with the joint offsets of a ``physics.json`` revision, and a note on them.

    The one place every consumer of forward kinematics (the geometry, timing and binding checks,
    the binding re-render) gets the fitted robot from. Offsets that cannot be read are skipped
    and the note says why; so it does for compliance and backlash, which are not offsets.

    Returns:
        the chain (``chain`` itself without offsets) and a note ("" when there is nothing to say).
    """
    notes = []
    try:
        offsets = read_joint_offsets(physics, chain.joint_names, path=path)
    except FormatError as exc:
        offsets = {}
        notes.append(f"joint offsets not applied ({exc.message})")
    rev = physics.get("revision")
    if offsets:
        chain = chain_with_offsets(chain, offsets)
        notes.append(f"FK with the joint offsets of physics revision {rev}")
    joints = physics.get("joints") or {}
    unmodelled = {
        k
        for j in chain.joint_names
        for k in ("compliance_rad_per_nm", "backlash_rad")
        if isinstance(joints, Mapping) and isinstance(joints.get(j), Mapping) and joints[j].get(k)
    }
    if unmodelled:
        notes.append(f"{', '.join(sorted(unmodelled))} of physics revision {rev} not applied")
    return chain, "; ".join(notes)


def dataset_fitted_chain(dataset: Any, chain: Chain) -> tuple[Chain, str]:
    """:func:`fitted_chain` with the ``physics.json`` a dataset declares (``manifest.physics``).

    No declared physics gives ``chain`` unchanged; one that cannot be read gives ``chain`` and a
    note saying why, so that viewers and renderers still work on the nominal robot.
    """
    from robogs.format.errors import RobogsError

    rel = dataset.manifest.get("physics")
    if not isinstance(rel, str):
        return chain, ""
    try:
        physics = dataset.physics()
    except RobogsError as exc:
        return chain, f"joint offsets not applied ({exc})"
    return fitted_chain(chain, physics, path=rel)

"""The physical model an exporter writes: link and object inertias, joint dynamics, contact.

The URDF is the base; ``physics.json`` overrides it. For a robot link, an entry of the same
name in ``physics.json`` ``objects`` replaces the URDF inertial where it gives ``mass_kg``
(with ``com_m`` in the link frame and ``inertia_kgm2`` about the CoM in link axes) and
supplies the contact material (``friction_static``, ``friction_dynamic``, ``restitution``).
An entry in ``physics.json`` ``joints`` replaces the URDF ``<dynamics>`` values it names.
Every other ``objects`` entry is a scene object whose mesh is ``assets/<name>``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yourdfpy

from robogs.format import Dataset
from robogs.format.errors import FormatError

__all__ = [
    "BodyInertia",
    "ContactMaterial",
    "JointDynamics",
    "SceneObject",
    "contact_material",
    "joint_dynamics",
    "link_inertias",
    "principal_axes",
    "scene_objects",
]


@dataclass(frozen=True)
class BodyInertia:
    """Mass properties of a rigid body.

    Attributes:
        mass: kg.
        com: [3] centre of mass, metres, body frame.
        inertia: [3, 3] kg·m², about the CoM, body axes.
        frame: [4, 4] inertial frame in the body frame as written by the source (URDF
            ``<inertial><origin>``); ``inertia`` equals ``R @ I_frame @ R.T``.
        inertia_in_frame: [3, 3] the tensor in that inertial frame.
    """

    mass: float
    com: np.ndarray
    inertia: np.ndarray
    frame: np.ndarray
    inertia_in_frame: np.ndarray


@dataclass(frozen=True)
class ContactMaterial:
    """Contact parameters (dimensionless; ``None`` where the dataset gives none)."""

    friction_static: float | None
    friction_dynamic: float | None
    restitution: float | None

    def as_dict(self) -> dict[str, float]:
        return {k: v for k, v in vars(self).items() if v is not None}


@dataclass(frozen=True)
class JointDynamics:
    """Passive joint dynamics (URDF semantics).

    Attributes:
        damping: N·m·s/rad (revolute) or N·s/m (prismatic).
        friction: Coulomb friction, N·m (revolute) or N (prismatic).
        armature: reflected rotor inertia, kg·m² (revolute) or kg (prismatic); None if unknown.
    """

    damping: float | None
    friction: float | None
    armature: float | None


@dataclass(frozen=True)
class SceneObject:
    """A ``physics.json`` object that is not a robot link.

    Attributes:
        name: object (and asset) name.
        equation: ``static`` | ``rigid`` | ``kinematic`` | ``articulated``.
        inertia: mass properties, None when ``mass_kg`` is absent.
        material: contact parameters.
        mesh_path: the asset's mesh file, None when the asset has no mesh.
        params: the raw ``physics.json`` entry.
    """

    name: str
    equation: str
    inertia: BodyInertia | None
    material: ContactMaterial
    mesh_path: Path | None
    params: dict[str, Any]


def _entry_inertia(entry: dict[str, Any]) -> BodyInertia | None:
    if "mass_kg" not in entry:
        return None
    com = np.asarray(entry.get("com_m", (0.0, 0.0, 0.0)), dtype=np.float64)
    inertia = np.asarray(entry.get("inertia_kgm2", np.zeros((3, 3))), dtype=np.float64)
    frame = np.eye(4)
    frame[:3, 3] = com
    return BodyInertia(float(entry["mass_kg"]), com, inertia, frame, inertia)


def contact_material(entry: dict[str, Any] | None) -> ContactMaterial:
    """The contact parameters of a ``physics.json`` object entry (all None if absent)."""
    entry = entry or {}

    def get(key: str) -> float | None:
        return None if entry.get(key) is None else float(entry[key])

    return ContactMaterial(get("friction_static"), get("friction_dynamic"), get("restitution"))


def link_inertias(urdf: yourdfpy.URDF, physics: dict[str, Any] | None) -> dict[str, BodyInertia]:
    """Mass properties of every link that has them (URDF, overridden by ``physics.json``).

    Returns:
        link name -> :class:`BodyInertia`; links with neither a URDF inertial nor a
        ``physics.json`` mass are absent.
    """
    objects = (physics or {}).get("objects", {})
    out: dict[str, BodyInertia] = {}
    for link in urdf.robot.links:
        override = _entry_inertia(objects.get(link.name, {}))
        if override is not None:
            out[link.name] = override
            continue
        inertial = link.inertial
        if inertial is None or inertial.mass is None:
            continue
        frame = (
            np.eye(4) if inertial.origin is None else np.asarray(inertial.origin, dtype=np.float64)
        )
        I_f = (
            np.zeros((3, 3))
            if inertial.inertia is None
            else np.asarray(inertial.inertia, dtype=np.float64)
        )
        R = frame[:3, :3]
        out[link.name] = BodyInertia(
            float(inertial.mass), frame[:3, 3].copy(), R @ I_f @ R.T, frame, I_f
        )
    return out


def joint_dynamics(urdf: yourdfpy.URDF, physics: dict[str, Any] | None) -> dict[str, JointDynamics]:
    """Damping, friction and armature of every non-fixed joint (``physics.json`` wins)."""
    table = (physics or {}).get("joints", {})
    out: dict[str, JointDynamics] = {}
    for j in urdf.robot.joints:
        if j.type == "fixed":
            continue
        dyn = j.dynamics
        entry = table.get(j.name, {})

        def pick(key: str, urdf_value: float | None, entry: dict[str, Any] = entry) -> float | None:
            if entry.get(key) is not None:
                return float(entry[key])
            return None if urdf_value is None else float(urdf_value)

        out[j.name] = JointDynamics(
            pick("damping", None if dyn is None else dyn.damping),
            pick("friction", None if dyn is None else dyn.friction),
            pick("armature", None),
        )
    return out


def scene_objects(
    ds: Dataset, physics: dict[str, Any] | None, robot_links: set[str]
) -> list[SceneObject]:
    """The ``physics.json`` objects that are not robot links, with their asset meshes."""
    out: list[SceneObject] = []
    for name, entry in sorted((physics or {}).get("objects", {}).items()):
        if name in robot_links:
            continue
        asset = ds.assets.get(name, {})
        mesh = ds.resolve(asset["mesh"], where=f"assets/{name}/mesh") if "mesh" in asset else None
        out.append(
            SceneObject(
                name=name,
                equation=str(entry.get("equation", "rigid")),
                inertia=_entry_inertia(entry),
                material=contact_material(entry),
                mesh_path=mesh,
                params=dict(entry),
            )
        )
    return out


def principal_axes(
    inertia: np.ndarray, *, where: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Diagonalise a symmetric inertia tensor.

    Args:
        inertia: [3, 3] kg·m², symmetric.

    Returns:
        ``(d, R)``: [3] principal moments (ascending) and [3, 3] proper rotation whose columns
        are the principal axes, with ``inertia == R @ diag(d) @ R.T``.

    Raises:
        FormatError: the tensor is not symmetric or not finite.
    """
    inertia = np.asarray(inertia, dtype=np.float64)
    if not np.all(np.isfinite(inertia)) or not np.allclose(
        inertia, inertia.T, atol=1e-12, rtol=1e-9
    ):
        raise FormatError("inertia tensor is not a finite symmetric matrix", where=where)
    d, R = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    return d, R

"""Arm torque-model physics an exporter writes besides the joint dynamics: payload and mass scale.

``fit --add payload`` stores ``physics.json`` ``payload: {link, mass_kg, com_m}``: a point mass
rigidly attached to ``link`` with its centre of mass at ``com_m`` (m, in ``link``'s frame). The
torque model gives it no rotational inertia of its own about its CoM (see
:class:`robogs.physics.arm.effects.Payload`), but a body with a zero inertia tensor is
not positive definite: validators (check G003) flag it and simulators reject it. The exported
body is therefore a solid sphere of radius :data:`PAYLOAD_RADIUS_M` (1 cm) about the CoM,
``I = 2/5 m r^2`` per axis (:func:`payload_inertia`). The joint torques it adds to the point
mass are ``J_w^T I w_dot`` (the gyroscopic term of an isotropic body is zero), at most
``I |w_dot|`` with ``w_dot`` the payload link's angular acceleration: 6e-4 N m for a 1.5 kg
payload at 10 rad/s^2, far below joint-torque noise (0.05-0.2 N m on the UR5 logs).
``fit --add mass_scale`` stores ``effects: [{name: mass_scale, params: {s}}]``: every URDF link
mass and inertia times ``s`` (the payload is not scaled).

This module only reads ``physics.json`` and the URDF; it does not import the physics package.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yourdfpy

from robogs.format.errors import FormatError

from .physics_model import BodyInertia

__all__ = [
    "PAYLOAD_RADIUS_M",
    "PayloadSpec",
    "payload_spec",
    "payload_inertia",
    "mass_scale",
    "unique_name",
    "deepest_moving_link",
]

PAYLOAD_RADIUS_M = 0.01
"""m; radius of the solid sphere whose inertia the exported payload body gets about its CoM."""


@dataclass(frozen=True)
class PayloadSpec:
    """A fitted payload.

    Attributes:
        parent: link it is welded to (the link it was fitted on).
        mass: kg (> 0).
        com: [3] centre of mass, m, in the ``parent`` link frame.
    """

    parent: str
    mass: float
    com: np.ndarray


def payload_inertia(spec: PayloadSpec, radius: float = PAYLOAD_RADIUS_M) -> BodyInertia:
    """Mass properties of the exported payload body, in the frame of its parent link.

    A solid sphere of ``radius`` (m) centred on the CoM: ``I = 2/5 m r^2`` (kg m^2) on every
    axis, so the tensor is positive definite and meets the triangle inequality.
    """
    inertia = np.eye(3) * (0.4 * spec.mass * radius**2)
    frame = np.eye(4)
    frame[:3, 3] = spec.com
    return BodyInertia(spec.mass, np.asarray(spec.com, dtype=np.float64), inertia, frame, inertia)


def deepest_moving_link(urdf: yourdfpy.URDF) -> str | None:
    """Child link of the actuated joint with the most actuated joints above it (None if none).

    This is the torque model's default payload link (``ArmModel.last_link``).
    """
    joints = {j.child: j for j in urdf.robot.joints}
    best, best_depth = None, 0
    for j in urdf.robot.joints:
        if j.type == "fixed":
            continue
        depth, link = 0, j.child
        while link in joints:
            if joints[link].type != "fixed":
                depth += 1
            link = joints[link].parent
        if depth > best_depth:
            best, best_depth = j.child, depth
    return best


def payload_spec(
    physics: dict[str, Any] | None,
    urdf: yourdfpy.URDF,
    manifest: dict[str, Any],
    *,
    path: str | Path | None = "physics.json",
) -> PayloadSpec | None:
    """The ``physics.json`` payload, or None when there is none or its mass is not positive.

    The parent link is ``payload.link``; if absent, the manifest's ``robot.ee_link``, then the
    deepest moving link (the same default as the torque model).

    Raises:
        FormatError: the link is not in the URDF, or the values are not finite.
    """
    p = (physics or {}).get("payload") or {}
    if "mass_kg" not in p:
        return None
    mass = float(p["mass_kg"])
    com = np.asarray(p.get("com_m", (0.0, 0.0, 0.0)), dtype=np.float64)
    if com.shape != (3,) or not np.all(np.isfinite(com)) or not np.isfinite(mass):
        raise FormatError(
            "payload mass_kg / com_m are not finite numbers (com_m needs 3)",
            path=path,
            where="payload",
        )
    if mass <= 0.0:
        return None
    link = (
        p.get("link") or (manifest.get("robot") or {}).get("ee_link") or deepest_moving_link(urdf)
    )
    if link not in urdf.link_map:
        raise FormatError(
            f"payload link {link!r} is not a link of the robot URDF",
            path=path,
            where="payload.link",
            hint="refit the payload (robogs fit --add payload) or set payload.link to a URDF link",
        )
    return PayloadSpec(str(link), mass, com)


def mass_scale(
    physics: dict[str, Any] | None, *, path: str | Path | None = "physics.json"
) -> float | None:
    """The fitted ``mass_scale`` factor ``s`` of ``physics.json`` ``effects`` (None if absent)."""
    for e in (physics or {}).get("effects", []) or []:
        if e.get("name") == "mass_scale":
            s = float((e.get("params") or {}).get("s", 1.0))
            if not np.isfinite(s) or s <= 0.0:
                raise FormatError(
                    f"mass_scale s = {s} is not a positive number",
                    path=path,
                    where="effects[mass_scale].params.s",
                )
            return s
    return None


def unique_name(base: str, taken: set[str]) -> str:
    """``base``, or ``base_2``, ``base_3``... whichever is not in ``taken``."""
    name, k = base, 2
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name

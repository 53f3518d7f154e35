"""Built-in effects of the rigid-object model (registered on import).

Contact family: viscous damping, quadratic drag, Stribeck friction, table tilt (constant bias
acceleration), anisotropic friction, restitution, CoM offset, mass. Sensor family: camera-encoder time
offset, planar camera extrinsics error. The catalogue follows the effect table of
``research/physics.md`` section 6.1 (E2-E6, E8, E9, E13, E14) plus the mass error of E9.

Hook parameter shapes: ``body``, ``accel``, ``friction`` and ``from_sensor`` receive [M, 1]
tensors (broadcast against [M, T]); ``sample_times`` and ``to_sensor`` receive [M, 1, 1]
(broadcast against [M, T, N]).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from robogs.physics.effects import Effect, Param, register_effect
from robogs.physics.model import Body, FreeState, Slip, yaw_rotate

__all__ = [
    "ViscousDamping",
    "QuadraticDrag",
    "Stribeck",
    "TableTilt",
    "AnisotropicFriction",
    "Restitution",
    "ComOffset",
    "Mass",
    "TimeOffset",
    "CameraExtrinsics",
]

_SPEED_RANGE = "slides over a wider range of start speeds (viscous grows with v, drag with v^2)"
_DIRECTIONS = (
    "pushes in opposite directions (tilt flips sign with the direction, anisotropy does not)"
)


@dataclass(frozen=True)
class ViscousDamping(Effect):
    """Linear drag ``a = -c v`` on the free object (E2)."""

    name: str = "viscous_damping"
    family: str = "contact"
    params: tuple[Param, ...] = (Param("c", "1/s", 0.0, 10.0, 0.0, 1.0),)
    needs: tuple[str, ...] = ("object_poses", "sliding")
    separate_by: str = _SPEED_RANGE
    description: str = "velocity-proportional dissipation (lubrication, linear air drag)"

    def accel(self, th, state: FreeState):
        return -th["c"].unsqueeze(-1) * state.v, None


@dataclass(frozen=True)
class QuadraticDrag(Effect):
    """Quadratic drag ``a = -k |v| v`` (E3)."""

    name: str = "quadratic_drag"
    family: str = "contact"
    params: tuple[Param, ...] = (Param("k", "1/m", 0.0, 30.0, 0.0, 2.0),)
    needs: tuple[str, ...] = ("object_poses", "sliding")
    separate_by: str = _SPEED_RANGE
    description: str = "dissipation growing with speed squared (air drag)"

    def accel(self, th, state: FreeState):
        sp = torch.linalg.vector_norm(state.v, dim=-1, keepdim=True)
        return -th["k"].unsqueeze(-1) * sp * state.v, None


@dataclass(frozen=True)
class Stribeck(Effect):
    """Stribeck friction ``mu(v) = mu_d (1 + dmu exp(-(v/v_s)^2))`` (E4)."""

    name: str = "stribeck"
    family: str = "contact"
    params: tuple[Param, ...] = (
        Param("dmu", "-", 0.0, 3.0, 0.0, 0.4),
        Param("v_s", "m/s", 0.01, 1.0, 0.1, 0.15),
    )
    needs: tuple[str, ...] = ("object_poses", "sliding")
    separate_by: str = (
        "pushes and slides released at several speeds between v_s and about 3 v_s (a free slide "
        "spends under v_s / (mu_d g) s below v_s, so the curve shows through how far each release "
        "speed slides; well above v_s only the product v_s^2 ln(1 + dmu) is seen)"
    )
    description: str = "friction rising at low sliding speed (stiction)"
    starts: tuple[dict[str, float], ...] = ({"dmu": 0.4, "v_s": 0.15},)

    def friction(self, th, mu_s, mu_d, slip: Slip):
        bump = th["dmu"] * torch.exp(-((slip.speed / th["v_s"]) ** 2))
        return mu_s, mu_d * (1.0 + bump)


@dataclass(frozen=True)
class TableTilt(Effect):
    """Constant planar bias acceleration (table tilt, air flow, cable pull) (E5)."""

    name: str = "table_tilt"
    family: str = "contact"
    params: tuple[Param, ...] = (
        Param("g_x", "m/s^2", -2.0, 2.0, 0.0, 0.2),
        Param("g_y", "m/s^2", -2.0, 2.0, 0.0, 0.2),
    )
    needs: tuple[str, ...] = ("object_poses", "sliding", "directions")
    separate_by: str = _DIRECTIONS
    description: str = "direction-dependent deceleration from a tilted table or a bias force"

    def accel(self, th, state: FreeState):
        z = torch.zeros_like(state.w)
        a = torch.stack([th["g_x"].expand_as(z), th["g_y"].expand_as(z), z], dim=-1)
        return a, None


@dataclass(frozen=True)
class AnisotropicFriction(Effect):
    """Direction-dependent friction ``mu_d (1 + a_c cos 2phi + a_s sin 2phi)``, phi the slip
    heading in the world (table grain) frame (E6)."""

    name: str = "anisotropic_friction"
    family: str = "contact"
    params: tuple[Param, ...] = (
        Param("a_c", "-", -0.6, 0.6, 0.0, 0.2),
        Param("a_s", "-", -0.6, 0.6, 0.0, 0.2),
    )
    needs: tuple[str, ...] = ("object_poses", "sliding", "directions")
    separate_by: str = _DIRECTIONS
    description: str = "friction that depends on the sliding direction"

    def friction(self, th, mu_s, mu_d, slip: Slip):
        s2 = slip.speed * slip.speed
        c2 = (slip.vx * slip.vx - slip.vy * slip.vy) / s2
        s2phi = 2.0 * slip.vx * slip.vy / s2
        fac = 1.0 + th["a_c"] * c2 + th["a_s"] * s2phi
        return mu_s, mu_d * fac


@dataclass(frozen=True)
class Restitution(Effect):
    """Restitution error: ``e = e_nominal + e_delta`` for box-table impacts (E8)."""

    name: str = "restitution"
    family: str = "contact"
    params: tuple[Param, ...] = (Param("e_delta", "-", -1.0, 0.95, 0.0, 0.3),)
    needs: tuple[str, ...] = ("object_poses", "impact")
    separate_by: str = "drops from several heights onto the table"
    description: str = "bounce (or its absence) at impacts with the table"
    starts: tuple[dict[str, float], ...] = ({"e_delta": 0.3},)

    def body(self, th, body: Body) -> Body:
        return replace(body, restitution=(body.restitution + th["e_delta"]).clamp(0.0, 0.98))


@dataclass(frozen=True)
class ComOffset(Effect):
    """Centre-of-mass offset in the object frame (E9): moves the friction centre and the
    lever arm of the pusher, so off-centre pushes rotate the box differently."""

    name: str = "com_offset"
    family: str = "contact"
    params: tuple[Param, ...] = (
        Param("dx", "m", -0.03, 0.03, 0.0, 0.01),
        Param("dy", "m", -0.03, 0.03, 0.0, 0.01),
    )
    needs: tuple[str, ...] = ("object_poses", "contact")
    separate_by: str = "pushes at several offsets from the box centre line"
    description: str = "wrong mass distribution (push rotation)"

    def body(self, th, body: Body) -> Body:
        off = torch.cat([th["dx"], th["dy"]], dim=-1).unsqueeze(1)
        return replace(body, com=body.com + off)


@dataclass(frozen=True)
class Mass(Effect):
    """Mass error ``m = m_nominal (1 + dm)``, the yaw inertia scaled with it (uniform density).

    With a kinematic pusher, Coulomb friction and gravity every force on the box scales with its
    mass or is a velocity constraint, so object poses alone do not change with ``dm``: the fit
    reports it unidentifiable unless the data carry forces.
    """

    name: str = "mass"
    family: str = "contact"
    params: tuple[Param, ...] = (Param("dm", "-", -0.5, 2.0, 0.0, 0.2),)
    needs: tuple[str, ...] = ("object_poses", "contact")
    separate_by: str = (
        "forces: a force-torque sensor at the pusher or a weighed object (poses of a pushed, "
        "sliding or dropped box do not depend on its mass)"
    )
    description: str = "wrong object mass (and inertia)"

    def body(self, th, body: Body) -> Body:
        s = 1.0 + th["dm"]
        return replace(body, mass=body.mass * s, inertia_z=body.inertia_z * s)


@dataclass(frozen=True)
class TimeOffset(Effect):
    """Camera (pose tracker) stamps late by ``delta`` against the encoder clock (E13)."""

    name: str = "time_offset"
    family: str = "sensor"
    params: tuple[Param, ...] = (Param("delta", "s", -0.25, 0.25, 0.0, 0.02),)
    needs: tuple[str, ...] = ("object_poses", "contact")
    separate_by: str = "a sharp pusher start or stop seen by both the encoders and the camera"
    description: str = "camera-encoder clock offset"

    def sample_times(self, th, t):
        return t - th["delta"]


@dataclass(frozen=True)
class CameraExtrinsics(Effect):
    """Planar error of the camera extrinsics as it shows in tracked object poses (E14):
    reported = Rz(dyaw) * true + (dx, dy, 0), rotation about the world origin."""

    name: str = "camera_extrinsics"
    family: str = "sensor"
    params: tuple[Param, ...] = (
        Param("dx", "m", -0.05, 0.05, 0.0, 0.005),
        Param("dy", "m", -0.05, 0.05, 0.0, 0.005),
        Param("dyaw", "rad", -0.1, 0.1, 0.0, 0.01),
    )
    needs: tuple[str, ...] = ("object_poses", "contact", "directions")
    separate_by: str = "calibrating the camera on the arm (tracked EE vs forward kinematics)"
    description: str = "camera pose error (object poses shifted against the robot frame)"

    def to_sensor(self, th, pos, yaw):
        x, y = yaw_rotate(pos[..., 0], pos[..., 1], th["dyaw"])
        out = torch.stack([x + th["dx"], y + th["dy"], pos[..., 2]], dim=-1)
        return out, yaw + th["dyaw"]

    def from_sensor(self, th, pos, yaw):
        x, y = yaw_rotate(pos[..., 0] - th["dx"], pos[..., 1] - th["dy"], -th["dyaw"])
        return torch.stack([x, y, pos[..., 2]], dim=-1), yaw - th["dyaw"]


for _cls in (
    ViscousDamping,
    QuadraticDrag,
    Stribeck,
    TableTilt,
    AnisotropicFriction,
    Restitution,
    ComOffset,
    Mass,
    TimeOffset,
    CameraExtrinsics,
):
    register_effect(_cls())

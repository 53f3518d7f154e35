"""Build the model constants (:class:`~robogs.physics.model.BoxScene`) from physics.json."""

from __future__ import annotations

from typing import Any

from robogs.format.errors import FormatError
from robogs.physics.model import BoxScene

__all__ = ["scene_from_physics", "base_params"]


def _need(doc: dict[str, Any], key: str, where: str) -> Any:
    if key not in doc:
        raise FormatError(
            f"physics.json lacks {key!r}",
            path="physics.json",
            where=where,
            hint="the rigid model needs size_m, mass_kg, inertia_kgm2 and friction of the object",
        )
    return doc[key]


def scene_from_physics(physics: dict[str, Any], object_name: str, *, dt: float = 1e-3) -> BoxScene:
    """Nominal scene constants of ``object_name`` (a box) from a physics.json document.

    Reads ``objects[object_name]`` (``size_m``, ``mass_kg``, ``inertia_kgm2``, ``com_m``,
    friction, restitution, damping), ``objects.table.plane_z_m`` (default 0) and
    ``objects.pusher.radius_m`` (default 0.01 m) and ``length_m`` (capsule, default 0: sphere), and ``gravity_mps2`` (default -9.81 z).
    """
    objects = physics.get("objects", {})
    if object_name not in objects:
        raise FormatError(
            f"physics.json has no object {object_name!r}", path="physics.json", where="objects"
        )
    ob = objects[object_name]
    where = f"objects/{object_name}"
    size = tuple(float(s) for s in _need(ob, "size_m", where))
    mass = float(_need(ob, "mass_kg", where))
    inertia = ob.get("inertia_kgm2")
    izz = (
        float(inertia[2][2]) if inertia is not None else mass * (size[0] ** 2 + size[1] ** 2) / 12.0
    )
    com = ob.get("com_m", [0.0, 0.0, 0.0])
    grav = physics.get("gravity_mps2", [0.0, 0.0, -9.81])
    return BoxScene(
        size=size,  # type: ignore[arg-type]
        mass=mass,
        inertia_z=izz,
        com=(float(com[0]), float(com[1])),
        friction_static=float(ob.get("friction_static", ob.get("friction_dynamic", 0.5))),
        friction_dynamic=float(ob.get("friction_dynamic", 0.4)),
        restitution=float(ob.get("restitution", 0.0)),
        damping_linear=float(ob.get("damping_linear", 0.0)),
        table_z=float(objects.get("table", {}).get("plane_z_m", 0.0)),
        pusher_radius=float(objects.get("pusher", {}).get("radius_m", 0.01)),
        pusher_length=float(objects.get("pusher", {}).get("length_m", 0.0)),
        gravity=float(-grav[2]),
        dt=dt,
        friction_bounds=_prior_bounds(physics, f"objects.{object_name}.friction_dynamic"),
    )


def _prior_bounds(physics: dict[str, Any], key: str) -> tuple[float, float]:
    """``sources.<key>.bounds`` of a prior (robogs physics init), else the model's 0.02-2."""
    b = ((physics.get("sources") or {}).get(key) or {}).get("bounds")
    if isinstance(b, list) and len(b) == 2 and 0 < float(b[0]) < float(b[1]):
        return float(b[0]), float(b[1])
    return 0.02, 2.0


def base_params(scene: BoxScene) -> list:
    """The base model's always-refitted parameters (their ``zero`` is the nominal value)."""
    from robogs.physics.effects import Param

    mu = scene.friction_dynamic
    lo, hi = scene.friction_bounds
    return [Param("friction_dynamic", "-", lo, hi, min(max(mu, lo), hi), max(mu, 0.05))]

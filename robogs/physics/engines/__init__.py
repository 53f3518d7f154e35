"""Simulation engines of the physics loop, in one registry (entry-point group
``robogs.engines``).

Built in:

* ``mujoco`` - :class:`~robogs.physics.engines.mujoco_engine.MujocoEngine`: 3-D contact
  dynamics, several objects, box or convex-mesh shapes, pusher friction.
* ``planar`` - :class:`~robogs.physics.engines.planar.PlanarEngine`: a thin adapter over the
  batched torch model of :mod:`robogs.physics.model` (one box on a horizontal plane,
  frictionless sphere or capsule pusher).

The fitting engine (:class:`robogs.physics.engine.Engine`, ``backend="planar"|"mujoco"|"auto"``)
rolls out parameter spaces with effects on either simulator: the MuJoCo side is
:mod:`~robogs.physics.engines.mujoco_fit`, the effect mapping
:mod:`~robogs.physics.engines.mujoco_effects`.

An engine is a class following :class:`~robogs.physics.engines.base.Engine`; a user engine is
registered with :func:`register_engine` or an entry point whose object is such a class::

    [project.entry-points."robogs.engines"]
    bullet = "my_package.bullet_engine:BulletEngine"
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, Registry
from robogs.physics.engines.base import Engine, ObjectState, Predicted, make_drive

__all__ = [
    "Engine",
    "ObjectState",
    "Predicted",
    "REGISTRY",
    "available_engines",
    "choose_engine",
    "engine_entries",
    "get_engine",
    "make_drive",
    "register_engine",
]

_BUILTIN = {
    "mujoco": "robogs.physics.engines.mujoco_engine",
    "planar": "robogs.physics.engines.planar",
}

#: the engine registry (keys: engine names; values: engine classes)
REGISTRY: Registry[type] = Registry(
    "engines",
    ENTRY_POINT_GROUPS["engines"],
    noun="engine",
    builtins=_BUILTIN,
    unknown_where="--engine",
)


def register_engine(cls: type, *, name: str | None = None, replace: bool = False) -> type:
    """Register an engine class (its ``name`` attribute unless ``name`` is given)."""
    return REGISTRY.register(name or cls.name, cls, replace=replace)


def get_engine(name: str) -> type:
    """The engine class registered as ``name``."""
    return REGISTRY.get(name)


def available_engines() -> dict[str, type]:
    """``name -> engine class`` of the usable engines."""
    return REGISTRY.available()


def engine_entries() -> list[Entry[type]]:
    """Every engine entry, usable or not."""
    return REGISTRY.entries()


def choose_engine(
    physics: Mapping[str, Any], meshes: Mapping[str, Any] | None = None, *, prefer: str = "planar"
) -> tuple[str, str]:
    """``auto``: ``prefer`` when it can represent the scene, else the first usable engine that
    can; returns ``(name, reason)``.

    Raises:
        InputError: no registered engine can represent the scene (the reasons are listed).
    """
    from robogs.format.errors import InputError

    engines = available_engines()
    order = [prefer] + [n for n in engines if n != prefer]
    why = []
    for name in order:
        if name not in engines:
            continue
        ok, reason = engines[name].can_represent(physics, meshes)
        if ok:  # one line: why the engines tried first cannot, then what this one represents
            cannot = [w.replace(":", " cannot represent it:", 1) for w in why]
            return name, "; ".join([*cannot, f"{name}: {reason}"])
        why.append(f"{name}: {reason}")
    raise InputError("no engine can represent this scene", hint="; ".join(why))

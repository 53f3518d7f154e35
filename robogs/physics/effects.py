"""Effect plug-ins: named physical or sensor effects with bounded parameters.

An effect is a small frozen dataclass. It names its parameters (with units, bounds, the value
that switches it off and a typical value), says which streams or excitation it needs, and
overrides one or more *hooks* of the model it plugs into. The rigid-object model
(:mod:`robogs.physics.model`) calls these hooks:

* ``body(th, body)``: change body constants (CoM, restitution) before a rollout;
* ``accel(th, state)``: extra linear and yaw acceleration while the object is free;
* ``friction(th, mu_s, mu_d, slip)``: change the table friction coefficients;
* ``sample_times(th, t)`` / ``to_sensor`` / ``from_sensor``: measurement effects
  (clock offset, frame error) applied to the observation, not to the dynamics.

Other models (the robot-arm model in ``robogs.physics.arm``) declare their own hooks
and select effects with ``model="arm"``; the registry, the fitter and the diagnosis do not
care which model an effect belongs to.

Effects are collected in a :class:`~robogs.format.plugins.Registry`: the built-in ones of
every model (:data:`BUILTIN_MODULES`) register on the first listing or look-up, user ones
with :func:`register_effect` or through the ``robogs.effects`` entry-point group (the entry
point names an ``Effect`` instance, an ``Effect`` subclass, a module registering effects, or
a callable returning an instance or subclass). A plug-in that fails to load is listed as
unavailable with the reason (:func:`effect_entries`).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType
from typing import Any

from robogs.format.errors import InputError
from robogs.format.plugins import ENTRY_POINT_GROUPS, Entry, Registry

__all__ = [
    "Param",
    "Effect",
    "FAMILIES",
    "register_effect",
    "unregister_effect",
    "available_effects",
    "effect_entries",
    "BUILTIN_MODULES",
    "REGISTRY",
    "get_effect",
    "overrides",
]

FAMILIES = ("contact", "joint", "sensor")

#: modules of the built-in effects: the rigid-object catalogue, the arm's torque and kinematic
#: effects, and the camera-mask effect (each registers its effects on import)
BUILTIN_MODULES: tuple[str, ...] = (
    "robogs.physics.catalogue",
    "robogs.physics.arm.effects",
    "robogs.physics.intrinsics",
)


@dataclass(frozen=True)
class Param:
    """One parameter of an effect.

    Attributes:
        name: short identifier, unique inside its effect.
        unit: SI unit as text (``"1/s"``, ``"m/s^2"``, ``"s"``...).
        lower: lower bound used by the fitter.
        upper: upper bound used by the fitter.
        zero: the value that switches the effect off (the baseline model).
        nominal: a typical magnitude; sets the finite-difference step and parameter scaling.
    """

    name: str
    unit: str
    lower: float
    upper: float
    zero: float = 0.0
    nominal: float = 1.0

    def __post_init__(self) -> None:
        if not (self.lower <= self.zero <= self.upper):
            raise ValueError(f"parameter {self.name}: zero value outside [lower, upper]")


@dataclass(frozen=True)
class Effect:
    """Base class of every effect; subclass it as a frozen dataclass and override hooks.

    Attributes:
        name: registry key (snake_case).
        family: ``"contact"``, ``"joint"`` or ``"sensor"``.
        params: the effect's parameters.
        needs: streams or excitations the effect needs to be identifiable. Known words for
            the rigid model: ``object_poses``, ``ee_poses``, ``contact`` (pusher contact),
            ``sliding`` (free sliding on the table), ``impact`` (a drop onto the table),
            ``directions`` (pushes in at least three directions), ``wrenches``, ``efforts``.
        model: which model the hooks belong to (``"rigid"`` or ``"arm"``).
        separate_by: the experiment that tells this effect apart from look-alikes.
        description: one line for reports.
        starts: extra start points of the fit besides the zero values, as ``{param: value}``
            (the fitter keeps the best). Needed where the predictions are flat in the
            parameter at its zero value, e.g. a bounce height grows with the square of the
            restitution, so its gradient vanishes at zero.
    """

    name: str = ""
    family: str = "contact"
    params: tuple[Param, ...] = ()
    needs: tuple[str, ...] = ()
    model: str = "rigid"
    separate_by: str = ""
    description: str = ""
    starts: tuple[dict[str, float], ...] = ()

    # --- rigid-model hooks (no-ops here; overridden by concrete effects) -----------------
    def body(self, th: dict[str, Any], body: Any) -> Any:
        """Return body constants changed by the effect (``th``: param name -> [M, 1])."""
        return body

    def accel(self, th: dict[str, Any], state: Any) -> tuple[Any, Any] | None:
        """Extra acceleration of the free object: ``([M, T, 3] m/s^2, [M, T] rad/s^2)``."""
        return None

    def friction(self, th: dict[str, Any], mu_s: Any, mu_d: Any, slip: Any) -> tuple[Any, Any]:
        """Table friction coefficients given the slip state (see ``model.Slip``)."""
        return mu_s, mu_d

    def sample_times(self, th: dict[str, Any], t: Any) -> Any:
        """Map measurement stamps [s] to the model times they observe."""
        return t

    def to_sensor(self, th: dict[str, Any], pos: Any, yaw: Any) -> tuple[Any, Any]:
        """Map model poses (world) to what the sensor reports."""
        return pos, yaw

    def from_sensor(self, th: dict[str, Any], pos: Any, yaw: Any) -> tuple[Any, Any]:
        """Inverse of :meth:`to_sensor` (used for the measured initial pose)."""
        return pos, yaw

    # --- helpers ---------------------------------------------------------------------------
    def param_names(self) -> list[str]:
        """Names of the parameters, in order."""
        return [p.name for p in self.params]

    def zero_values(self) -> dict[str, float]:
        """Parameter values that switch the effect off."""
        return {p.name: p.zero for p in self.params}


def overrides(effect: Effect, hook: str) -> bool:
    """Whether ``effect`` overrides ``hook`` of :class:`Effect` (lets models skip no-ops)."""
    return getattr(type(effect), hook) is not getattr(Effect, hook)


def _validate(effect: Effect) -> None:
    if not effect.name or not effect.name.replace("_", "").isalnum():
        raise InputError(
            f"effect name {effect.name!r} is not a snake_case identifier",
            where="register_effect",
            hint="give the dataclass a name like 'my_drag'",
        )
    if effect.family not in FAMILIES:
        raise InputError(
            f"effect {effect.name!r} has family {effect.family!r}",
            where="register_effect",
            hint=f"use one of {', '.join(FAMILIES)}",
        )
    names = [p.name for p in effect.params]
    if len(set(names)) != len(names):
        raise InputError(
            f"effect {effect.name!r} repeats a parameter name", where="register_effect"
        )


def _adopt(reg: Registry[Effect], name: str, obj: Any) -> None:
    """A ``robogs.effects`` entry point: an ``Effect`` instance or subclass, a module that
    registers effects on import, or a callable returning an instance or subclass."""
    if isinstance(obj, ModuleType):
        return
    if callable(obj) and not isinstance(obj, (Effect, type)):
        obj = obj()
    register_effect(obj)


#: the effect registry (keys: effect names); the built-in catalogue of every model registers
#: on the first listing or look-up
REGISTRY: Registry[Effect] = Registry(
    "effects",
    ENTRY_POINT_GROUPS["effects"],
    noun="effect",
    builtins=BUILTIN_MODULES,
    adopt=_adopt,
    module_of=lambda e: type(e).__module__,
    unknown_where="effects",
)


def register_effect(effect: Effect | type[Effect], *, replace: bool = False) -> Effect:
    """Add an effect to the registry and return the registered instance.

    Args:
        effect: an ``Effect`` instance, or a subclass whose defaults describe it.
        replace: allow replacing an effect of the same name.

    Raises:
        InputError: not an effect, or a malformed one.
        RegistrationError: another effect of that name exists and ``replace`` is False.
    """
    inst = effect() if isinstance(effect, type) else effect
    if not isinstance(inst, Effect):
        raise InputError(
            f"{effect!r} is not an Effect",
            where="register_effect",
            hint="subclass robogs.physics.effects.Effect",
        )
    _validate(inst)
    return REGISTRY.register(inst.name, inst, replace=replace)


def unregister_effect(name: str) -> None:
    """Remove an effect from the registry (no error if absent)."""
    REGISTRY.unregister(name)


def available_effects(*, model: str | None = None, family: str | None = None) -> dict[str, Effect]:
    """``name -> Effect`` of every usable effect (built-in catalogues of all models, entry
    points, user registrations), by name; :func:`effect_entries` also lists unavailable ones.

    Args:
        model: keep effects of this model only (``"rigid"``, ``"arm"``, ``"camera"``).
        family: keep effects of this family only.
    """
    return {
        n: e
        for n, e in REGISTRY.available().items()
        if (model is None or e.model == model) and (family is None or e.family == family)
    }


def effect_entries() -> list[Entry[Effect]]:
    """Every entry of the effect registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


def get_effect(name: str) -> Effect:
    """The registered effect called ``name``.

    Raises:
        InputError: no such effect.
        PluginError: its plug-in failed to load.
    """
    return REGISTRY.get(name)

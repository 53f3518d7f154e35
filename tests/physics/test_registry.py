"""Effect registry: built-ins, user registration, entry points, validation."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from robogs.format.errors import InputError
from robogs.physics import effects as fx
from robogs.physics.effects import (
    Effect,
    Param,
    available_effects,
    get_effect,
    register_effect,
)


def test_builtin_catalogue():
    names = available_effects(model="rigid")
    for n in (
        "viscous_damping",
        "quadratic_drag",
        "stribeck",
        "table_tilt",
        "anisotropic_friction",
        "restitution",
        "com_offset",
        "time_offset",
        "camera_extrinsics",
    ):
        assert n in names
    assert get_effect("time_offset").family == "sensor"
    assert all(p.lower <= p.zero <= p.upper for n in names for p in get_effect(n).params)


@dataclass(frozen=True)
class _Bad(Effect):
    name: str = "bad_family"
    family: str = "magic"


def test_invalid_and_duplicate_registrations_are_refused():
    with pytest.raises(InputError):
        register_effect(_Bad())
    with pytest.raises(InputError):
        register_effect(Effect(name="viscous_damping", family="contact"))
    with pytest.raises(InputError):
        get_effect("no_such_effect")


def test_entry_point_effects_are_loaded(monkeypatch):
    @dataclass(frozen=True)
    class Plug(Effect):
        name: str = "plugged_in"
        params: tuple[Param, ...] = (Param("a", "-", 0.0, 1.0),)

    class _EP:
        name = "plugged_in"

        def load(self):
            return Plug

    monkeypatch.setattr(
        fx.importlib.metadata,
        "entry_points",
        lambda group: [_EP()] if group == "robogs.effects" else [],
    )
    monkeypatch.setattr(fx._REGISTRY, "entry_points_loaded", False)
    try:
        assert "plugged_in" in available_effects()
        assert get_effect("plugged_in").params[0].name == "a"
    finally:
        fx.unregister_effect("plugged_in")

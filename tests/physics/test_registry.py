"""Effect registry: built-ins, user registration, entry points, validation."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from plugin_dist import write_dist

from robogs.format.errors import InputError
from robogs.format.plugins import PluginError, PluginWarning, RegistrationError
from robogs.physics import effects as fx
from robogs.physics.effects import (
    Effect,
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
    with pytest.raises(RegistrationError, match="'viscous_damping' is already registered"):
        register_effect(Effect(name="viscous_damping", family="contact"))
    with pytest.raises(InputError):
        get_effect("no_such_effect")


def test_every_model_is_listed_without_imports_by_hand():
    """Arm and camera effects are in the catalogue from the first listing (the module's
    registry loads every built-in catalogue lazily)."""
    assert {"joint_friction", "backlash"} <= set(available_effects(model="arm"))
    assert list(available_effects(model="camera")) == ["camera_intrinsics"]
    assert all(e.source == "builtin" and e.ok for e in fx.effect_entries())


def test_entry_point_effects_are_loaded(tmp_path, monkeypatch):
    write_dist(
        tmp_path,
        "robogs-labfx",
        "labfx",
        """
        from dataclasses import dataclass

        from robogs.physics.effects import Effect, Param

        @dataclass(frozen=True)
        class Plug(Effect):
            name: str = "plugged_in"
            params: tuple = (Param("a", "-", 0.0, 1.0),)

        def make():
            return Plug(name="plugged_too")

        BAD = Plug(name="plugged_bad", family="magic")
        """,
        """
        [robogs.effects]
        plugged_in = labfx:Plug
        plugged_too = labfx:make
        plugged_bad = labfx:BAD
        """,
    )
    with monkeypatch.context() as mp, fx.REGISTRY.sandbox():
        mp.syspath_prepend(str(tmp_path))
        with pytest.warns(PluginWarning, match="'plugged_bad'.*family 'magic'"):
            names = available_effects()
        assert {"plugged_in", "plugged_too"} <= set(names) and "plugged_bad" not in names
        assert get_effect("plugged_in").params[0].name == "a"
        assert {e.name: e.source for e in fx.effect_entries()}["plugged_too"] == "robogs-labfx"
        with pytest.raises(PluginError, match="family 'magic'"):
            get_effect("plugged_bad")
    assert "plugged_in" not in available_effects()

"""Lazy package names (robogs._lazy): resolved on first read, errors as for any module."""

from __future__ import annotations

import subprocess
import sys

import pytest

from robogs._lazy import lazy_getattr


def test_lazy_name_is_the_defining_modules_object() -> None:
    import robogs.physics as physics
    import robogs.physics.arm as arm
    from robogs.physics.arm.rnea import ArmModel
    from robogs.physics.effects import get_effect

    assert physics.get_effect is get_effect
    assert arm.ArmModel is ArmModel
    for pkg in (physics, arm):
        assert set(pkg._LAZY) == set(pkg.__all__)  # every public name resolves
        for name in pkg.__all__:
            assert getattr(pkg, name) is not None


def test_unknown_name_raises_attribute_error_naming_the_package() -> None:
    import math

    import robogs.physics as physics

    getter = lazy_getattr("pkg.sub", {"pi": "math"})
    assert getter("pi") == math.pi
    with pytest.raises(AttributeError, match=r"module 'pkg.sub' has no attribute 'nope'"):
        getter("nope")
    assert not hasattr(physics, "no_such_name")


def test_importing_the_package_does_not_import_the_lazy_modules() -> None:
    code = (
        "import sys, robogs.physics, robogs.physics.arm;"
        "print(sorted(m for m in ('robogs.physics.effects', 'robogs.physics.arm.rnea') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"

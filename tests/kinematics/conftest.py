"""Shared fixtures for the kinematics/frames/URDF/interp tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

# name -> (URDF path, allowed root, package roots), relative to the real-data folder
# (fixture real_data of tests/conftest.py; see SOURCES.md there).
REAL_URDFS: dict[str, tuple[str, str, dict[str, str]]] = {
    "ur5": (
        "ur5/robots/ur_description/urdf/ur5_robot.urdf",
        "ur5",
        {"example-robot-data": "ur5"},
    ),
    "franka_panda": (
        "franka_panda/robots/panda_description/urdf/panda.urdf",
        "franka_panda",
        {"example-robot-data": "franka_panda"},
    ),
    "dobot_cr5": ("dobot_cr5/dobot_description/urdf/cr5_robot.urdf", "dobot_cr5", {}),
    "dobot_cr3": ("dobot_cr3/dobot_description/urdf/cr3_robot.urdf", "dobot_cr3", {}),
}


@pytest.fixture
def real_urdf_args(real_data: Path) -> Callable[[str], tuple[Path, Path, dict[str, Path]]]:
    """``(name) -> (urdf path, root, package_roots)`` for one of :data:`REAL_URDFS`."""

    def args(name: str) -> tuple[Path, Path, dict[str, Path]]:
        rel, root, pkgs = REAL_URDFS[name]
        return real_data / rel, real_data / root, {k: real_data / v for k, v in pkgs.items()}

    return args

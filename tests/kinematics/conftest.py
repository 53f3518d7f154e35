"""Shared fixtures for the kinematics/frames/URDF/interp tests."""

from __future__ import annotations

from pathlib import Path

import pytest

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "fixtures" / "real"

# name -> (URDF path, allowed root, package roots), relative to REAL (see SOURCES.md there).
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


def real_dir() -> Path:
    """The real-data folder; fails (never skips) when it is missing."""
    if not REAL.is_dir():
        pytest.fail(f"real-data fixture folder is missing: {REAL}")
    return REAL


def real_urdf_args(name: str) -> tuple[Path, Path, dict[str, Path]]:
    """(urdf path, root, package_roots) for one of :data:`REAL_URDFS`."""
    base = real_dir()
    rel, root, pkgs = REAL_URDFS[name]
    return base / rel, base / root, {k: base / v for k, v in pkgs.items()}

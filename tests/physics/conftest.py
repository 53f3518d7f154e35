"""Shared fixtures of the physics tests (the scenarios live in ``physics_scenarios``)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from robogs.synth.armlogs import ur5_urdf


@pytest.fixture(autouse=True)
def _threads():
    torch.set_num_threads(1)
    yield


@pytest.fixture(scope="module")
def ur5(tmp_path_factory) -> Path:
    """The synthetic UR5's URDF written to a temporary folder (for the arm-log tests)."""
    p = tmp_path_factory.mktemp("robot") / "ur5.urdf"
    p.write_text(ur5_urdf())
    return p

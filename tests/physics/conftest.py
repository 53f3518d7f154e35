"""Shared fixtures of the physics tests: small hidden-effect scenarios (cached per session)."""

from __future__ import annotations

import functools
from pathlib import Path

import pytest
import torch

from fixtures.armlogs import ur5_urdf
from fixtures.scenarios import make_scenario


@functools.lru_cache(maxsize=16)
def scenario(
    effect: str, seed: int = 0, noise: str = "nominal", kinds: tuple[str, ...] = ("push",)
):
    """A 6-push scenario (2 speeds x 3 directions) unless ``kinds`` says otherwise."""
    return make_scenario(
        effect, seed=seed, noise=noise, kinds=kinds, n_speeds=2, n_dirs=3, check=False
    )


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

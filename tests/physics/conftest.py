"""Shared fixtures of the physics tests: small hidden-effect scenarios (cached per session)."""

from __future__ import annotations

import functools

import pytest
import torch

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

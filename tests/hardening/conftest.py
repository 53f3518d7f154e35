"""Fixtures of the hardening tests: the seed inputs, built once per session."""

from __future__ import annotations

import pytest

from .seeds import Seeds, build_seeds


@pytest.fixture(scope="session")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> Seeds:
    """Every seed input (dataset, bags, MCAP, videos, calibrations, logs, meshes)."""
    return build_seeds(tmp_path_factory.mktemp("hardening") / "seeds")

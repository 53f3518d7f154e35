"""Fixtures for the validator tests: a clean dataset built once per session, copied per test.

``clean_root`` is the synthetic scene of ``robogs.synth.scene`` (small size, seed 0)
when that generator is installed, and otherwise the tiny scene of
:mod:`tiny_scene` (also available on its own as ``tiny_root``).
"""

from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

from .tiny_scene import build_tiny_scene


def _synthesize():
    if importlib.util.find_spec("robogs.synth.scene") is None:
        return None
    import robogs.synth.scene as synth

    return getattr(synth, "synthesize", None)


@pytest.fixture(scope="session")
def tiny_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny scene, built once per session (do not modify; copy it)."""
    return build_tiny_scene(tmp_path_factory.mktemp("tiny") / "ds")


@pytest.fixture(scope="session")
def clean_root(tmp_path_factory: pytest.TempPathFactory, tiny_root: Path) -> Path:
    """The clean fixture: the synthetic scene (small, seed 0) if available, else the tiny scene."""
    synthesize = _synthesize()
    if synthesize is None:
        return tiny_root
    out = tmp_path_factory.mktemp("synth") / "ds"
    synthesize(out, seed=0, size="small")
    return out


@pytest.fixture
def clean_copy(clean_root: Path, tmp_path: Path) -> Path:
    """A private copy of the clean fixture, free to corrupt."""
    dst = tmp_path / "ds"
    shutil.copytree(clean_root, dst, symlinks=True)
    return dst


@pytest.fixture
def tiny_copy(tiny_root: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny scene, free to corrupt."""
    dst = tmp_path / "tiny"
    shutil.copytree(tiny_root, dst, symlinks=True)
    return dst

"""Shared inputs of the reconstruction tests: a tiny multi-view capture, built once per session."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch

from robogs.synth.multiview import MultiviewTruth, synthesize_multiview


@pytest.fixture(autouse=True)
def _one_thread():
    """Deterministic, contention-free CPU maths (the machines running tests are shared)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, MultiviewTruth]:
    """A 48x36-px, 8-view capture of the two-link scene and its truth (do not modify; copy it)."""
    root = tmp_path_factory.mktemp("mv") / "tiny"
    truth = synthesize_multiview(root, n_views=8, width=48, height=36, supersample=2)
    return root, truth


@pytest.fixture(scope="session")
def tiny_capture(tiny_scene: tuple[Path, MultiviewTruth]) -> Path:
    """The tiny capture's folder (do not modify; copy it)."""
    return tiny_scene[0]


@pytest.fixture
def capture_copy(tiny_capture: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny capture."""
    dst = tmp_path / "ds"
    shutil.copytree(tiny_capture, dst)
    return dst

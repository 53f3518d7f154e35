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


@pytest.fixture(scope="session")
def push_walkthrough(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> dict:
    """docs/physics.md's bag walkthrough run once per test session, also under pytest-xdist
    (:func:`session_once.once_per_session`): ``{"dir": folder, "runs": [...]}`` (see
    :func:`bag_walkthrough.run_walkthrough`)."""
    import json

    from bag_walkthrough import run_walkthrough
    from session_once import once_per_session

    folder, runs = once_per_session(
        "push_walkthrough",
        tmp_path_factory.getbasetemp(),
        worker_id,
        run_walkthrough,
        lambda r: json.dumps(r).encode(),
        json.loads,
    )
    return {"dir": folder, "runs": runs}


@pytest.fixture(scope="module")
def _fit_store() -> dict:
    """One module's memo of diagnose's candidate fits and held-out rollouts (fit_memo)."""
    return {}


@pytest.fixture
def shared_fits(monkeypatch: pytest.MonkeyPatch, _fit_store: dict) -> dict[str, int]:
    """``diagnose_recording`` reuses candidate fits and held-out rollouts that an earlier call
    in this module (same worker) computed on identical inputs (:mod:`fit_memo`); returns the
    hit/miss counter."""
    from fit_memo import memoise_fits

    return memoise_fits(monkeypatch, _fit_store)

"""``robogs render --backend auto``: the compiled numba backend where installed, frame for frame
the same labels, colours and depth as the torch backend (the validator's re-renderer)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robogs.format import Dataset
from robogs.format.kinematics import Chain
from robogs.format.render import available_backends
from robogs.format.render_trajectory import (
    TrajectoryRenderer,
    episode_trajectory,
    resolve_backend,
)
from robogs.synth.scene import synthesize

HAS_NUMBA = "numba" in available_backends()


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("render_backend") / "s"
    synthesize(out, seed=2, size="small", progress=False)
    return out


def test_auto_resolves_to_an_available_backend() -> None:
    assert resolve_backend("auto") == ("numba" if HAS_NUMBA else "torch")
    assert resolve_backend("auto", "cuda") == "torch"
    assert resolve_backend("torch") == "torch" and resolve_backend("dense") == "dense"


@pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed: auto is the torch backend")
def test_numba_frames_equal_torch_frames(scene: Path) -> None:
    ds = Dataset.open(scene)
    ep = ds.episode()
    traj = episode_trajectory(ep, Chain.from_urdf(ds.urdf(load_meshes=False)), {"elbow_joint": 0.1})
    t = ep.frames("cam0").column("t_ns").to_numpy()
    r = {
        b: TrajectoryRenderer(ds, ep, traj, ds.camera("cam0"), backend=b)
        for b in ("torch", "numba")
    }
    for k in (5, len(t) // 2, len(t) - 5):
        a, b = (r[x].frame(int(t[k])) for x in ("torch", "numba"))
        assert (a.labels > 0).mean() > 0.05  # the robot and the box are in view
        assert np.array_equal(a.labels, b.labels), k
        assert np.abs(a.rgb.astype(int) - b.rgb).max() <= 1, k
        assert np.abs(a.depth - b.depth).max() <= 1e-5, k  # m

"""An episode without ee_poses is driven by forward kinematics of its joint_states.

Oracle: the synthetic scene records ``ee_poses`` as its own (independent) FK of the true joint
angles, and ``joint_states`` as those angles plus 1e-4 rad noise: FK of the measured joints
must match the recorded poses to the noise (about 0.1 mm at the tool of a 0.8 m arm).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from robogs.format.errors import FormatError
from robogs.physics.recording import load_recording


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("fk") / "scene"
    synthesize(root, seed=0, size="small", progress=False)
    return root


def _without(src: Path, dst: Path, streams: tuple[str, ...], drop_robot: bool = False) -> Path:
    shutil.copytree(src, dst)
    m = json.loads((dst / "manifest.json").read_text())
    for ep in m["episodes"]:
        for s in streams:
            ep["streams"].pop(s)
    if drop_robot:
        m.pop("robot")
    (dst / "manifest.json").write_text(json.dumps(m))
    return dst


def test_end_effector_from_joints_matches_recorded_poses(scene: Path, tmp_path: Path) -> None:
    rec = load_recording(scene).trajectories[0]
    fk = load_recording(_without(scene, tmp_path / "no_ee", ("ee_poses",))).trajectories[0]
    assert np.array_equal(rec.ee_t_ns, fk.ee_t_ns)  # the scene stamps both at the joint clock
    d_mm = np.linalg.norm(rec.ee_pos - fk.ee_pos, axis=1) * 1000.0
    assert np.median(d_mm) < 0.15 and d_mm.max() < 0.5
    dot = np.abs(np.sum(rec.ee_quat * fk.ee_quat, axis=1))
    assert np.degrees(2 * np.arccos(np.clip(dot, -1, 1))).max() < 0.05
    assert np.array_equal(rec.object_pos, fk.object_pos)


def test_no_end_effector_source_is_a_clear_error(scene: Path, tmp_path: Path) -> None:
    bare = _without(scene, tmp_path / "bare", ("ee_poses",), drop_robot=True)
    with pytest.raises(FormatError, match="no ee_poses stream, and no robot URDF"):
        load_recording(bare)

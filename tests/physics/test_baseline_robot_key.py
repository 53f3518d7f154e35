"""The baseline cache key covers the robot pusher's geometry (objects.pusher.geometry "robot"):
a change to the URDF alone, or to a link's pose in the pusher frame, must not reuse a memoised
fit of the old geometry."""

from __future__ import annotations

import numpy as np

from robogs.physics.baseline import _fingerprint
from robogs.physics.engines.mujoco_robot import RobotPusher
from robogs.physics.recording import Recording

URDF = '<robot name="r"><link name="ee"><collision><geometry><sphere radius="{r}"/></geometry></collision></link></robot>'


def _rec(tmp_path, radius: float, shift: float = 0.0) -> Recording:
    urdf = tmp_path / f"r{radius}.urdf"
    urdf.write_text(URDF.format(r=radius))
    T = np.eye(4)
    T[0, 3] = shift
    rp = RobotPusher(urdf=urdf, link="ee", frames={"ee": T})
    return Recording(trajectories=[], physics={}, robot_pusher=rp)


def test_key_changes_with_the_urdf_and_the_link_pose(tmp_path):
    base = _fingerprint(_rec(tmp_path, 0.01))
    assert _fingerprint(_rec(tmp_path, 0.01)) == base  # same geometry: same key
    assert _fingerprint(_rec(tmp_path, 0.012)) != base  # the URDF's collision radius changed
    assert _fingerprint(_rec(tmp_path, 0.01, 1e-3)) != base  # the link moved 1 mm in the pusher
    assert _fingerprint(Recording(trajectories=[], physics={})) != base  # primitive pusher

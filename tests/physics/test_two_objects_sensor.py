"""Sensor effects on MuJoCo reach every tracked object, not only the pushed one.

One camera sees both boxes, so a camera-extrinsics error or a stamp offset of the pose stream
moves box B's measurements exactly as box A's. Oracle: the generator's noise-free two-box data,
mutated here with numpy (a planar rigid transform of both boxes' poses; a shift of the pose
stamps), must be reproduced with the effect at the planted value as well as the unmutated data
is with the effect off. Before the sensor effects mapped box B, B stayed 14.6 mm off under the
camera mutation (A 2.3 mm, pushed into a misplaced B) and 1.30 mm under the stamp shift.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robogs.physics.effects import get_effect
from robogs.physics.engine import Engine
from robogs.physics.residuals import tracked_rms
from robogs.synth.scenarios.two_objects import TwoBoxTruth, make_two_objects

TRUTH = TwoBoxTruth()


def _qz_mul(yaw: float, q: np.ndarray) -> np.ndarray:
    """Rz(yaw) (x) q for quaternions q [N, 4] (w, x, y, z), the Hamilton product written out."""
    c, s = np.cos(yaw / 2), np.sin(yaw / 2)
    w, x, y, z = q.T
    return np.stack([c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w], axis=-1)


def _camera(p: np.ndarray, dx: float, dy: float, dyaw: float) -> np.ndarray:
    rot = np.array([[np.cos(dyaw), -np.sin(dyaw), 0], [np.sin(dyaw), np.cos(dyaw), 0], [0, 0, 1]])
    return p @ rot.T + np.array([dx, dy, 0.0])


def _rms(rec, effect: str, values: dict[str, float]) -> tuple[float, float]:
    """(A, B) position RMS [mm] at the true frictions, ``effect`` at ``values``."""
    eng = Engine(rec, backend="mujoco", threads=1)
    space = eng.space([get_effect(effect)])
    th = space.zero.copy()
    th[space.index("base", "friction_dynamic")] = TRUTH.mu_a
    th[space.index("base", "objects.box_b.friction_dynamic")] = TRUTH.mu_b
    for k, v in values.items():
        th[space.index(effect, k)] = v
    r = eng.evaluate(space, th[None], np.zeros((1, eng.prep.n_traj, 3)))[0]
    a = np.linalg.norm(eng.raw(r)[..., :3], axis=-1)[eng.mask] * 1e3
    return float(np.sqrt(np.mean(a**2))), tracked_rms(eng.prep, r)["box_b"]["rms_mm"]


@pytest.fixture(scope="module")
def clean():
    rec = make_two_objects(seed=0, noise=False)
    return rec, _rms(rec, "camera_extrinsics", {})


def test_camera_extrinsics_maps_both_boxes(clean):
    """reported = Rz(dyaw) true + (dx, dy) on both boxes: with the effect at those values the
    residuals equal the clean data's to 1e-6 mm (measured 1e-12); with it off B is > 10 mm off."""
    rec, (a0, b0) = clean
    dx, dy, dyaw = 0.02, -0.015, 0.05
    trs = [
        dataclasses.replace(
            tr,
            object_pos=_camera(tr.object_pos, dx, dy, dyaw),
            object_quat=_qz_mul(dyaw, tr.object_quat),
            other_pos=_camera(tr.other_pos, dx, dy, dyaw),
            other_quat=_qz_mul(dyaw, tr.other_quat),
        )
        for tr in rec.trajectories
    ]
    moved = dataclasses.replace(rec, trajectories=trs)
    a, b = _rms(moved, "camera_extrinsics", {"dx": dx, "dy": dy, "dyaw": dyaw})
    print(f"clean A {a0:.4f} B {b0:.4f} mm; mutated, effect at truth A {a:.4f} B {b:.4f} mm")
    assert b0 < 2.0  # the clean fit itself (measured 0.97 mm)
    assert a == pytest.approx(a0, abs=1e-6) and b == pytest.approx(b0, abs=1e-6)
    _, b_off = _rms(moved, "camera_extrinsics", {})
    assert b_off > 10.0  # measured 15.1 mm: the mutation is visible in B


def test_time_offset_shifts_both_boxes_stamps(clean):
    """Pose stamps 15 ms late on both boxes: with ``time_offset.delta`` = 15 ms box B's RMS is
    back within 0.05 mm of the clean data's (the start pose, read from shifted samples, differs
    slightly); with the effect off it is >= 0.2 mm worse."""
    rec, (_, b0) = clean
    d = 0.015
    late = dataclasses.replace(
        rec,
        trajectories=[
            dataclasses.replace(tr, t_ns=tr.t_ns + int(d * 1e9)) for tr in rec.trajectories
        ],
    )
    _, b = _rms(late, "time_offset", {"delta": d})
    _, b_off = _rms(late, "time_offset", {})
    print(f"clean B {b0:.4f} mm; stamps late: effect at truth {b:.4f}, off {b_off:.4f} mm")
    assert b == pytest.approx(b0, abs=0.05)
    assert b_off > b0 + 0.2

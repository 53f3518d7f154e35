"""Reverting physics revisions restores the camera intrinsics in force at that revision, when
later revisions carry the ``sensors.<cam>.intrinsics`` record over (a rigid refit after an
intrinsics fit) or a revert brought an older record back; the record follows the schema.

Oracle: the intrinsics written at each revision, tracked while the history is built (the
edits reproduce what ``fit --add camera_intrinsics`` and a rigid refit write).
"""

from __future__ import annotations

import copy
from dataclasses import replace

import pytest

from robogs.format.cameras import CameraModel
from robogs.format.dataset import Dataset
from robogs.format.schemas import schema_problems
from robogs.physics.api import revert

KEYS = ("fx", "fy", "cx", "cy")


def _values(cam: CameraModel) -> dict[str, float]:
    return {k: float(getattr(cam, k)) for k in KEYS}


def _intrinsics_fit(root, fx: float, cx: float) -> int:
    ds = Dataset.open(root)
    cam = ds.camera("cam0")
    new = replace(cam, fx=fx, fy=fx, cx=cx)
    doc = copy.deepcopy(ds.physics())
    doc.setdefault("sensors", {}).setdefault("cam0", {})["intrinsics"] = {
        **_values(new),
        "previous": _values(cam),
        "boundary_px_before": 2.0,
        "boundary_px_after": 0.9,
    }
    assert schema_problems("physics", doc) == []
    with ds.edit() as w:
        w.set_camera(new)
        rev = w.set_physics(doc, note="fit: added camera_intrinsics")
        w.commit()
    return rev


def _rigid_fit(root) -> int:
    ds = Dataset.open(root)
    doc = copy.deepcopy(ds.physics())  # a refit starts from the stored physics
    doc["objects"]["box"] = {"equation": "rigid", "mass_kg": 0.1 * doc["revision"]}
    with ds.edit() as w:
        rev = w.set_physics(doc, note="fit: added nothing")
        w.commit()
    return rev


def test_revert_restores_the_intrinsics_in_force_at_the_revision(tmp_path):
    root = tmp_path / "ds"
    w = Dataset.create(root)
    with w:
        w.set_camera(CameraModel("cam0", 160, 120, 130.0, 130.0, 80.5, 60.5))
        in_force = {w.set_physics({"objects": {}}, note="nominal"): 130.0}
        w.commit()
    in_force[_intrinsics_fit(root, 126.0, 78.5)] = 126.0
    in_force[_rigid_fit(root)] = 126.0  # carries the record over
    in_force[_intrinsics_fit(root, 125.0, 77.5)] = 125.0
    in_force[_rigid_fit(root)] = 125.0
    assert sorted(in_force) == [1, 2, 3, 4, 5]
    for target in (3, 1, 4, 2, 5, 1):
        rev = revert(root, target)
        in_force[rev] = in_force[target]
        cam = Dataset.open(root).camera("cam0")
        assert cam.fx == pytest.approx(in_force[target]), (target, cam.fx)
        assert cam.cx == pytest.approx({130.0: 80.5, 126.0: 78.5, 125.0: 77.5}[cam.fx])

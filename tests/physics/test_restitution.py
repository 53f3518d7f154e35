"""Restitution is found from drops (its bounce height grows with e^2: the fit needs a second
start point), with a value close to the hidden truth of the independent simulator."""

from __future__ import annotations

import pytest
from physics_scenarios import scenario

from robogs.physics.diagnose import diagnose_recording


def test_restitution_is_found_from_drops():
    rec = scenario("restitution", seed=3, kinds=("grasp_place",))
    res = diagnose_recording(rec, effects=["restitution", "viscous_damping"])
    top = res.rows[0]
    got = {p.name: p for p in top.params}
    assert top.name == "restitution" and top.reported
    assert got["e_delta"].value == pytest.approx(rec.meta["true_params"]["e_delta"], rel=0.08)
    assert top.rms_after < 1.15 * res.noise_floor

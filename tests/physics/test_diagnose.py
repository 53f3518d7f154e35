"""diagnose: null data reports nothing, a hidden effect is found, bad input is refused."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import torch
from physics_scenarios import scenario

from robogs.format.errors import InputError, RobogsError
from robogs.physics.diagnose import diagnose_recording
from robogs.physics.effects import Effect, Param, register_effect, unregister_effect
from robogs.physics.recording import as_recording

CANDIDATES = ["viscous_damping", "table_tilt", "time_offset", "camera_extrinsics"]


def test_null_data_reports_nothing():
    res = diagnose_recording(scenario("none", seed=5), effects=CANDIDATES)
    assert res.reported == []
    assert len(res.rows) == len(CANDIDATES)
    assert res.rms_base < 1.2 * res.noise_floor


def test_time_offset_is_found_first_with_its_value():
    rec = scenario("time_offset", seed=2)
    res = diagnose_recording(rec, effects=CANDIDATES)
    top = res.rows[0]
    assert top.name == "time_offset" and top.reported and top.verdict == "add"
    # one seed of a 6-push design (half the suite's): seeds 0-7 give 0.06-1.1 ms, median 0.5 ms;
    # the 1 ms criterion is on the median of the 20-seed suite (bench/diagnose.py)
    assert abs(top.params[0].value - rec.meta["true_params"]["delta"]) < 1.5e-3
    assert top.params[0].low < rec.meta["true_params"]["delta"] < top.params[0].high
    assert top.delta_bic < -10 and top.heldout_rms_after < top.heldout_rms_before
    assert top.rms_after < 1.1 * res.noise_floor
    d = top.to_dict()
    for key in (
        "name",
        "family",
        "reported",
        "delta_bic",
        "heldout_rms_before",
        "heldout_rms_after",
        "params",
    ):
        assert key in d
    assert set(d["params"][0]) == {"name", "value", "low", "high", "unit"}


@dataclass(frozen=True)
class ConstantPull(Effect):
    """A user effect: a constant horizontal pull (here the same physics as a table tilt)."""

    name: str = "constant_pull"
    family: str = "contact"
    params: tuple[Param, ...] = (
        Param("ax", "m/s^2", -2, 2, 0.0, 0.2),
        Param("ay", "m/s^2", -2, 2, 0.0, 0.2),
    )
    needs: tuple[str, ...] = ("object_poses", "sliding")

    def accel(self, th, state):
        z = torch.zeros_like(state.w)
        return torch.stack([th["ax"].expand_as(z), th["ay"].expand_as(z), z], dim=-1), None


def test_custom_effect_is_diagnosed_and_fitted():
    register_effect(ConstantPull())
    try:
        rec = scenario("table_tilt", seed=1)
        res = diagnose_recording(rec, effects=["constant_pull", "viscous_damping"])
        top = res.rows[0]
        assert top.name == "constant_pull" and top.reported
        truth = rec.meta["true_params"]
        got = {p.name: p.value for p in top.params}
        assert got["ax"] == pytest.approx(truth["g_x"], abs=0.1)
        assert got["ay"] == pytest.approx(truth["g_y"], abs=0.1)
    finally:
        unregister_effect("constant_pull")


@dataclass(frozen=True)
class NeedsWrenches(Effect):
    name: str = "needs_wrenches"
    params: tuple[Param, ...] = (Param("k", "-", 0.0, 1.0, 0.0, 0.1),)
    needs: tuple[str, ...] = ("wrenches",)


def test_effect_needing_a_missing_stream_is_skipped_with_the_reason():
    register_effect(NeedsWrenches())
    try:
        res = diagnose_recording(scenario("none", seed=5), effects=["needs_wrenches", "table_tilt"])
        assert [r.name for r in res.rows] == ["table_tilt"]
        assert res.skipped == [("needs_wrenches", "needs wrenches (not in the data)")]
    finally:
        unregister_effect("needs_wrenches")


def test_nan_in_measurements_names_stream_and_time():
    rec = as_recording(scenario("none", seed=5))
    tr = rec.trajectories[1]
    tr.object_pos = tr.object_pos.copy()
    tr.object_pos[7, 1] = np.nan
    with pytest.raises(InputError) as info:
        diagnose_recording(rec, effects=["table_tilt"])
    msg = str(info.value)
    assert "object_poses" in msg and str(int(tr.t_ns[7])) in msg and tr.name in msg
    assert isinstance(info.value, RobogsError)

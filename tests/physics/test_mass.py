"""Mass cannot be told from object poses: the diagnosis must say so, never claim a value."""

from __future__ import annotations

from physics_scenarios import scenario

from robogs.physics import api
from robogs.physics.diagnose import diagnose_recording


def test_mass_is_unidentifiable_from_poses_and_never_written(tmp_path):
    """Poses of a pushed, sliding or dropped box do not depend on its mass (every force scales
    with it or is a velocity constraint): the diagnosis must say unidentifiable, not a value."""
    rec = scenario("mass", seed=2, kinds=("offset_push",))
    res = diagnose_recording(rec, effects=["mass", "com_offset"])
    row = next(r for r in res.rows if r.name == "mass")
    assert row.verdict == "unidentifiable" and not row.reported
    assert row.params[0].low == float("-inf") and row.params[0].high == float("inf")
    assert "forces" in row.note and "do not change" in row.note
    assert res.reported == []  # nothing else is blamed for a mass error either
    fit = api.fit(rec, add=["mass"], write=False)
    assert fit.unidentifiable == ["mass.dm"]
    assert all(e["name"] != "mass" for e in fit.physics["effects"])

"""Prior bounds (``sources.<key>.bounds`` written by ``robogs physics init``) bound the fit.

Oracle: the independent force-push truth has mu_d = 0.35; a prior whose range stops at 0.30
must hold the fitted coefficient exactly at 0.30 and say so, a prior that spans the truth must
let it reach 0.35 and say nothing.
"""

from __future__ import annotations

import copy

import pytest

from robogs.physics.baseline import baseline
from robogs.physics.sanity import bound_notes
from robogs.physics.scene import base_params, scene_from_physics
from robogs.synth.scenarios.force_push import make_force_push


def _rec(bounds):
    rec = make_force_push(mass_true=0.4, mass_nominal=0.4, seed=2, n_traj=4)
    for tr in rec.trajectories:  # poses only: the slides fix mu_d
        tr.wrench_t_ns = tr.wrench_force = None
    rec.physics = copy.deepcopy(rec.physics)
    if bounds is not None:
        key = "objects.box.friction_dynamic"
        rec.physics["sources"] = {key: {"source": "prior(plastic)", "value": 0.3, "bounds": bounds}}
    return rec


def test_scene_reads_the_prior_bounds():
    rec = _rec([0.15, 0.6])
    scene = scene_from_physics(rec.physics, "box")
    assert scene.friction_bounds == (0.15, 0.6)
    (p,) = base_params(scene)
    assert (p.lower, p.upper) == (0.15, 0.6)
    assert scene_from_physics(_rec(None).physics, "box").friction_bounds == (0.02, 2.0)


@pytest.mark.parametrize("bounds,on_bound", [([0.15, 0.30], "upper"), ([0.15, 0.6], "")])
def test_fit_respects_and_reports_the_bound(bounds, on_bound):
    rec = _rec(bounds)
    b = baseline(rec)
    mu = float(b.outcome.theta[b.free[0]])
    assert b.outcome.on_bound == [on_bound]
    notes = bound_notes(rec)
    if on_bound:
        assert mu == pytest.approx(0.30, abs=1e-12)  # projected, never beyond the prior
        (line,) = notes
        assert "upper bound 0.3 of prior(plastic)" in line and "friction_dynamic" in line
    else:
        assert mu == pytest.approx(0.35, abs=0.02)  # the truth, inside the prior
        assert notes == []

"""The fitting engine on MuJoCo (CI size): ``Engine(backend=...)``, ``--engine`` selection, and
the base model refitted on MuJoCo against slides of the independent generator
(``robogs.synth.scenarios``), with the planar engine as the reference on the same data.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("mujoco")

from physics_scenarios import scenario  # noqa: E402

from robogs.format.errors import InputError  # noqa: E402
from robogs.physics.baseline import fit_baseline  # noqa: E402
from robogs.physics.engine import Engine, resolve_backend  # noqa: E402


def test_resolve_backend_auto_and_named():
    rec = scenario("none", seed=3, kinds=("release_slide",))
    name, why = resolve_backend(rec.physics, "auto")
    assert name == "planar" and "one box" in why
    doc = copy.deepcopy(rec.physics)
    doc["objects"]["pusher"]["friction_dynamic"] = 0.3
    name, why = resolve_backend(doc, "auto")
    assert name == "mujoco"
    with pytest.raises(InputError, match="cannot represent"):
        resolve_backend(doc, "planar")
    with pytest.raises(InputError, match="unknown engine"):
        resolve_backend(doc, "bullet")


def test_base_refit_on_mujoco_matches_planar_on_generator_slides():
    """Friction refitted on MuJoCo is the generator's within 1 %, and the refitted residual is
    the planar engine's within 2 % (both at the noise floor): the MuJoCo path (grasp, release,
    slide, sampling, nuisance offsets) matches the planar one where both can represent the
    scene."""
    rec = scenario("none", seed=3, kinds=("release_slide",))
    out = {}
    for be in ("planar", "mujoco"):
        eng = Engine(rec, backend=be)
        assert eng.backend == be
        _, _, fit, res = fit_baseline(eng)
        out[be] = (float(fit.theta[0]), res.rms_mm)
    mu_true = rec.meta["true_friction_dynamic"]
    assert out["mujoco"][0] == pytest.approx(mu_true, rel=0.01)
    assert out["mujoco"][1] == pytest.approx(out["planar"][1], rel=0.02)
    assert np.isfinite(out["mujoco"][1])

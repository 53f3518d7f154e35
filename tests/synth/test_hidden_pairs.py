"""Two effects hidden at once by the scenario generator (``make_scenario("a+b")``).

Oracles: single-effect scenarios are unchanged (fingerprints recorded with the generator
before combinations existed, commit 5873a46, and a combination whose partner is set to zero is
bit-identical to the single effect); closed forms for a sensor effect beside a contact one on
noiseless data (camera extrinsics: a rigid map of the poses; time offset: stamps late by
``delta``); two weak contact effects superpose up to a second-order cross term; names and
the per-member detectability check.
"""

from __future__ import annotations

import numpy as np
import pytest

from robogs.synth.scenarios import generate as gen
from robogs.synth.scenarios.generate import TRUE_PARAMS, effect_members, make_scenario

SLIDES = ("release_slide",)  # 4 trajectories: a few seconds per truth
T0 = 1_700_000_000_000_000_000

# sums of object_pos, object_quat, ee_pos, stamps [s after T0], the nominal friction and z of
# make_scenario(effect, seed=3, kinds=SLIDES, check=False) at 5873a46 (before this change)
BEFORE = {
    "table_tilt": (
        89.53849126222994,
        88.04670927062867,
        1741.9545384315525,
        2704.2278108460005,
        0.387,
        34.51377301501097,
    ),
    "camera_extrinsics": (
        90.33416599127477,
        87.38203043585318,
        1741.9545384315525,
        2704.2278108460005,
        0.387,
        57.18128330375868,
    ),
    "time_offset": (
        89.39462792693125,
        88.04670927062867,
        1741.9545384315525,
        2709.417810846,
        0.387,
        62.156277569487855,
    ),
}
ARRAYS = ("t_ns", "object_pos", "object_quat", "ee_t_ns", "ee_pos", "ee_quat", "grasp")


def _fingerprint(rec) -> tuple[float, ...]:
    tr = rec.trajectories
    v = [
        float(sum(getattr(x, k).sum() for x in tr)) for k in ("object_pos", "object_quat", "ee_pos")
    ]
    v.append(float(sum(((x.t_ns - T0) * 1e-9).sum() for x in tr)))
    return (*v, rec.physics["objects"]["box"]["friction_dynamic"], rec.meta["detectability_z"])


def _yaw(q: np.ndarray) -> np.ndarray:
    return 2.0 * np.arctan2(q[:, 3], q[:, 0])


@pytest.fixture
def fresh_caches():
    """The truth and detectability caches are keyed by effect name, not by its values."""
    gen._truth.cache_clear()
    gen._detectability.cache_clear()
    yield
    gen._truth.cache_clear()
    gen._detectability.cache_clear()


@pytest.mark.parametrize("effect", sorted(BEFORE))
def test_single_effect_scenarios_are_unchanged(effect):
    rec = make_scenario(effect, seed=3, kinds=SLIDES, check=False)
    np.testing.assert_allclose(_fingerprint(rec), BEFORE[effect], rtol=1e-12)
    assert rec.meta["effect"] == effect and "effects" not in rec.meta


def test_a_pair_with_a_zero_partner_is_the_single_effect(monkeypatch, fresh_caches):
    monkeypatch.setitem(TRUE_PARAMS, "viscous_damping", {"c": 0.0})
    pair = make_scenario("viscous_damping+table_tilt", seed=3, kinds=SLIDES, check=False)
    one = make_scenario("table_tilt", seed=3, kinds=SLIDES, check=False)
    for a, b in zip(pair.trajectories, one.trajectories, strict=True):
        for k in ARRAYS:
            assert np.array_equal(getattr(a, k), getattr(b, k)), k
    assert pair.physics == one.physics


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # z at zero noise divides by 0
def test_camera_extrinsics_beside_a_tilt_maps_the_tilted_poses_rigidly():
    p = TRUE_PARAMS["camera_extrinsics"]
    pair = make_scenario("table_tilt+camera_extrinsics", seed=1, kinds=SLIDES, noise="zero")
    tilt = make_scenario("table_tilt", seed=1, kinds=SLIDES, noise="zero")
    c, s = np.cos(p["dyaw"]), np.sin(p["dyaw"])
    for a, b in zip(pair.trajectories, tilt.trajectories, strict=True):
        x, y = b.object_pos[:, 0], b.object_pos[:, 1]
        want = np.stack([c * x - s * y + p["dx"], s * x + c * y + p["dy"], b.object_pos[:, 2]], -1)
        np.testing.assert_allclose(a.object_pos, want, atol=1e-12)
        dyaw = np.angle(np.exp(1j * (_yaw(a.object_quat) - _yaw(b.object_quat))))
        np.testing.assert_allclose(dyaw, p["dyaw"], atol=1e-12)
        assert np.array_equal(a.t_ns, b.t_ns)
    assert pair.meta["effect"] == "camera_extrinsics+table_tilt"
    assert pair.meta["family"] == "sensor+contact"
    assert pair.meta["true_params"]["table_tilt"] == TRUE_PARAMS["table_tilt"]
    assert pair.meta["effects"] == ["camera_extrinsics", "table_tilt"]


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # z at zero noise divides by 0
def test_time_offset_beside_a_tilt_delays_the_tilted_stamps():
    pair = make_scenario("time_offset+table_tilt", seed=2, kinds=SLIDES, noise="zero")
    tilt = make_scenario("table_tilt", seed=2, kinds=SLIDES, noise="zero")
    late = round(TRUE_PARAMS["time_offset"]["delta"] * 1e9)
    for a, b in zip(pair.trajectories, tilt.trajectories, strict=True):
        assert np.array_equal(a.object_pos, b.object_pos)
        assert np.abs(a.t_ns - b.t_ns - late).max() <= 1  # ns, rounding of the stamps


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # z at zero noise divides by 0
def test_two_weak_contact_effects_both_act_and_superpose(monkeypatch, fresh_caches):
    """Tilt and viscous damping at a tenth of their values on the same slides: the pair's
    change from the plain model is the sum of the single changes up to their cross term, which
    is second order (at full values it is 17 % of the pair's change, here 1.8 %)."""
    for k in ("table_tilt", "viscous_damping"):
        monkeypatch.setitem(TRUE_PARAMS, k, {a: 0.1 * v for a, v in TRUE_PARAMS[k].items()})
    kw = dict(seed=0, kinds=SLIDES, noise="zero", check=False)
    pos = {
        e: np.concatenate([t.object_pos[:, :2] for t in make_scenario(e, **kw).trajectories])
        for e in ("none", "table_tilt", "viscous_damping", "table_tilt+viscous_damping")
    }
    d_t = pos["table_tilt"] - pos["none"]
    d_v = pos["viscous_damping"] - pos["none"]
    d_p = pos["table_tilt+viscous_damping"] - pos["none"]
    # a pair that dropped either member would miss by that member's whole change
    assert np.linalg.norm(d_p - d_t - d_v) < 0.2 * min(np.linalg.norm(d_t), np.linalg.norm(d_v))


def test_names_and_the_detectability_check():
    assert effect_members("table_tilt+stribeck") == ("stribeck", "table_tilt")
    assert effect_members("stribeck") == ("stribeck",) and effect_members("none") == ("none",)
    for bad in ("tilt+stribeck", "stribeck+stribeck", "none+stribeck"):
        with pytest.raises(ValueError):
            effect_members(bad)
    # mass does not move a free slide (z ~ 0): the pair is refused, naming it
    with pytest.raises(ValueError, match="effect mass is not detectable"):
        make_scenario("table_tilt+mass", seed=0, kinds=SLIDES)
    rec = make_scenario("table_tilt+mass", seed=0, kinds=SLIDES, check=False)
    z = rec.meta["detectability_z_each"]
    assert z["mass"] < 8.0 <= z["table_tilt"] and rec.meta["detectability_z"] == z["mass"]
    assert z["table_tilt"] == pytest.approx(BEFORE["table_tilt"][-1], rel=1e-12)  # its own z

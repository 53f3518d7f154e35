"""An object that tips out of the plane is seen in the data, and only MuJoCo's free joint takes it.

Oracles: the tilt of a composed rotation (closed form: the roll angle, whatever the yaw or the
resting face); generator recordings at both noise levels and design B (flat: never flagged);
the same recordings with one trajectory's object tipped by a known roll (must be flagged and
named, with ``auto`` switching to MuJoCo's free joint and ``planar`` refused).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from robogs.format.errors import InputError
from robogs.physics.engine import Engine
from robogs.physics.planarity import RUN, SIGMAS, out_of_plane, tilt_components
from robogs.physics.prepare import prepare
from robogs.synth.scenarios.design_b import make_design_b
from robogs.synth.scenarios.generate import make_scenario


def _q(axis: str, angle: np.ndarray) -> np.ndarray:
    """(w, x, y, z) quaternions of rotations by ``angle`` [rad] about a body axis."""
    a = np.asarray(angle, float)
    q = np.zeros((a.size, 4))
    q[:, 0] = np.cos(a / 2)
    q[:, "xyz".index(axis) + 1] = np.sin(a / 2)
    return q


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=1,
    )


def _tilt_deg(quat: np.ndarray, rest: np.ndarray) -> np.ndarray:
    return np.degrees(np.arcsin(np.linalg.norm(tilt_components(quat, rest), axis=1)))


def test_tilt_is_the_roll_whatever_the_yaw_and_the_resting_face():
    rng = np.random.default_rng(0)
    n = 200
    yaw = rng.uniform(-np.pi, np.pi, n)
    roll = np.where(np.arange(n) < 50, 0.0, rng.uniform(0.0, np.radians(60.0), n))
    rest = np.arange(n) < 50
    # world yaw, then a tilt about a world-horizontal axis: q = q_tilt(world) * q_yaw
    axis_angle = rng.uniform(-np.pi, np.pi, n)
    q_tilt = _mul(_mul(_q("z", axis_angle), _q("x", roll)), _q("z", -axis_angle))
    for face in (0.0, np.pi / 2, np.pi):  # resting on its bottom, side and top face
        q_face = _q("x", np.full(n, face))
        quat = _mul(_mul(q_tilt, _q("z", yaw)), q_face)
        np.testing.assert_allclose(_tilt_deg(quat, rest), np.degrees(roll), atol=1e-9)


def _tip(rec, traj: int, peak_deg: float):
    """A copy of ``rec`` whose object tips about a world-horizontal axis on the trajectory's
    middle third (a smooth hump up to ``peak_deg``), every other number unchanged."""
    out = copy.deepcopy(rec)
    tr = out.trajectories[traj]
    n = len(tr.t_ns)
    s = np.zeros(n)
    a, b = n // 3, 2 * n // 3
    s[a:b] = np.sin(np.linspace(0.0, np.pi, b - a)) ** 2
    ang = np.radians(peak_deg) * s
    tr.object_quat = _mul(_mul(_q("z", np.full(n, 0.7)), _q("y", ang)), _q("z", np.full(n, -0.7)))
    tr.object_quat = _mul(tr.object_quat, rec.trajectories[traj].object_quat)
    return out


@pytest.mark.parametrize(
    "make",
    [
        lambda: make_scenario("none", seed=0),
        lambda: make_scenario("none", seed=1, noise="hard"),
        lambda: make_design_b("none", seed=0),
    ],
    ids=["A-nominal", "A-hard", "B"],
)
def test_flat_recordings_stay_planar_and_a_tip_is_named(make):
    rec = make()
    prep = prepare(rec)
    chk = out_of_plane(prep.rec, prep.labels)
    assert chk.tipped == [] and chk.reason() is None
    # the generators' roll/pitch noise: 0.5 deg nominal, 1.5 deg hard (per axis), design B its own
    assert 0.2 < chk.sigma_deg < 2.0
    assert chk.threshold_deg == pytest.approx(max(3.0, SIGMAS * chk.sigma_deg))
    assert max(chk.peak_deg) < 0.5 * chk.threshold_deg  # the margin on flat data

    k = len(rec.trajectories) // 2
    tipped = _tip(rec, k, 1.5 * chk.threshold_deg)
    prep_t = prepare(tipped)
    chk_t = out_of_plane(prep_t.rec, prep_t.labels)
    assert chk_t.tipped == [rec.trajectories[k].name]
    # brute force: the hump's largest value held over RUN consecutive samples (noise aside)
    n = len(rec.trajectories[k].t_ns)
    a, b = n // 3, 2 * n // 3
    hump = 1.5 * chk.threshold_deg * np.sin(np.linspace(0.0, np.pi, b - a)) ** 2
    held = max(hump[i : i + RUN].min() for i in range(len(hump) - RUN + 1))
    assert chk_t.peak_deg[k] == pytest.approx(held, rel=0.15)
    assert "tilts out of the plane" in chk_t.reason()
    # below the threshold it is noise: a tip of half the threshold is not reported
    half = _tip(rec, k, 0.5 * chk.threshold_deg)
    prep_h = prepare(half)
    assert out_of_plane(prep_h.rec, prep_h.labels).tipped == []


def test_the_threshold_follows_the_recorded_noise():
    rec = make_scenario("none", seed=2)
    base = out_of_plane(*(lambda p: (p.rec, p.labels))(prepare(rec)))
    noisy = copy.deepcopy(rec)
    rng = np.random.default_rng(5)
    for tr in noisy.trajectories:  # 3x the roll/pitch noise about world-horizontal axes
        n = len(tr.t_ns)
        extra = _mul(_q("x", rng.normal(0, np.radians(1.0), n)), _q("y", rng.normal(0, 0.0175, n)))
        tr.object_quat = _mul(extra, tr.object_quat)
    p = prepare(noisy)
    chk = out_of_plane(p.rec, p.labels)
    expect = np.hypot(1.0, base.sigma_deg)  # independent noises add in quadrature
    assert chk.sigma_deg == pytest.approx(expect, rel=0.1)
    assert chk.threshold_deg == pytest.approx(SIGMAS * chk.sigma_deg)
    assert chk.tipped == []


def test_a_single_outlier_is_not_a_tip():
    rec = make_scenario("none", seed=0)
    out = copy.deepcopy(rec)
    tr = out.trajectories[0]
    i = len(tr.t_ns) // 2
    tr.object_quat[i : i + RUN - 1] = _mul(
        _q("x", np.full(RUN - 1, np.radians(40.0))), tr.object_quat[i : i + RUN - 1]
    )
    p = prepare(out)
    assert out_of_plane(p.rec, p.labels).tipped == []


def test_auto_picks_mujocos_free_joint_and_planar_is_refused_for_a_tipping_box():
    pytest.importorskip("mujoco")
    rec = make_scenario("none", seed=0, kinds=("release_slide",))
    flat = Engine(rec, backend="auto")
    assert flat.backend == "planar"
    tipped = _tip(rec, 1, 20.0)
    eng = Engine(tipped, backend="auto")
    assert eng.backend == "mujoco"
    assert "tilts out of the plane" in eng.backend_reason
    assert eng._mujoco.eng.planar is False  # the free joint: roll and pitch can follow
    with pytest.raises(InputError, match="planar engine cannot represent this recording"):
        Engine(tipped, backend="planar")


def test_the_cli_prints_the_choice_the_fit_makes(tmp_path, capsys):
    pytest.importorskip("mujoco")
    from robogs.cli.main import main
    from robogs.synth.scenarios import write_scenario

    rec = _tip(make_scenario("none", seed=0, kinds=("release_slide",)), 1, 20.0)
    ds = tmp_path / "tipped"
    write_scenario(rec, ds)
    assert main(["compare", str(ds), "--engine", "auto"]) == 0
    out = capsys.readouterr().out
    assert (
        "engine: mujoco (auto: planar cannot represent it: the object tilts out of the plane" in out
    )
    assert main(["compare", str(ds), "--engine", "planar"]) != 0
    err = capsys.readouterr()
    assert "planar engine cannot represent this recording" in err.out + err.err

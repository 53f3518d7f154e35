"""The pusher-friction generator against closed forms of quasi-static pushing.

Oracles: Mason's centre of rotation for a frictionless point push on the ellipsoidal limit
surface (at ``-c^2 / y_c`` across the centre; Mason 1986; Lynch, Maekawa & Tanie 1992), pure
translation at ``mu_t m g`` for a central push, the Coulomb cone at the pusher (inside the
motion cone the contact sticks; outside it the force sits on the cone edge), every contact
wrench on the limit surface, and rate independence.
"""

from __future__ import annotations

import numpy as np
import pytest

from robogs.synth.scenarios.pusher_friction import (
    G,
    PusherFrictionTruth,
    make_pusher_friction,
    motion_cone,
    quasi_static_push,
)


def _body_force(tr) -> tuple[np.ndarray, np.ndarray]:
    """Contact force on the box in box axes (normal, tangential) [K, 2] and the in-contact mask."""
    on = ~np.isnan(tr.y_c)
    c, s = np.cos(tr.pose[:, 2]), np.sin(tr.pose[:, 2])
    fx, fy = tr.force[:, 0], tr.force[:, 1]
    # the force of step k was computed at the pose of step k-1
    c, s = np.roll(c, 1), np.roll(s, 1)
    return np.stack([c * fx + s * fy, -s * fx + c * fy], -1), on


def _push_window(tr) -> np.ndarray:
    """Indices of in-contact steps after the start ramp (pusher at full speed)."""
    on = np.flatnonzero(~np.isnan(tr.y_c))
    return on[len(on) // 4 : 3 * len(on) // 4]


def test_frictionless_push_turns_about_masons_centre_of_rotation():
    truth = PusherFrictionTruth(mu_p=0.0)
    y_c = 0.012
    tr = quasi_static_push(truth, y_c, 0.0, 0.01)
    f, on = _body_force(tr)
    assert np.all(np.abs(f[on, 1]) < 1e-12 * np.abs(f[on, 0]).max())  # normal force only
    k = np.flatnonzero(on)[5]  # early: the contact is still at y_c
    d = tr.pose[k] - tr.pose[k - 1]
    th = tr.pose[k - 1, 2] + 0.5 * d[2]
    dx_body = np.cos(th) * d[0] + np.sin(th) * d[1]
    r_y = dx_body / d[2]  # v = omega x (p - r) at the centre: v_x = omega r_y
    assert r_y == pytest.approx(-(truth.c**2) / tr.y_c[k], rel=1e-3)


def test_central_push_translates_at_the_table_friction():
    truth = PusherFrictionTruth(mu_t=0.42, mu_p=0.3)
    tr = quasi_static_push(truth, 0.0, 0.0, 0.05, box_yaw=0.4)
    f, on = _body_force(tr)
    assert np.abs(tr.pose[:, 2] - 0.4).max() < 1e-12
    assert np.linalg.norm(f[on], axis=1) == pytest.approx(0.42 * truth.mass * G, rel=1e-9)
    travel = np.hypot(*(tr.pose[-1, :2] - tr.pose[0, :2]))
    assert travel == pytest.approx(0.05, abs=1e-6)


def test_push_inside_the_motion_cone_sticks():
    truth = PusherFrictionTruth(mu_p=0.6)
    y_c0 = 0.008
    a = 0.5 * truth.size[0]
    up, lo = motion_cone(-a, y_c0, truth.c, truth.mu_p)
    mid = 0.5 * (np.arctan2(up[1], up[0]) + np.arctan2(lo[1], lo[0]))
    tr = quasi_static_push(truth, y_c0, mid, 0.04)
    f, on = _body_force(tr)
    assert tr.stick[on].all()
    # no slip: the box and the sphere touch at the same material points, so the sphere's
    # centre moves along the face only by the rolling term r * (turn of the face)
    rolled = truth.pusher_radius * (tr.pose[:, 2] - tr.pose[0, 2])
    assert np.abs(tr.y_c[on] - y_c0 - np.roll(rolled, 1)[on]).max() < 2e-6
    assert abs(np.degrees(tr.pose[-1, 2] - tr.pose[0, 2])) > 5  # and it did turn
    assert np.all(np.abs(f[on, 1]) < truth.mu_p * f[on, 0])


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_push_along_a_motion_cone_edge_has_the_cone_angle(side):
    truth = PusherFrictionTruth(mu_p=0.4)
    y_c0 = -0.006
    a = 0.5 * truth.size[0]
    edge = motion_cone(-a, y_c0, truth.c, truth.mu_p)[0 if side > 0 else 1]
    tr = quasi_static_push(truth, y_c0, float(np.arctan2(edge[1], edge[0])), 0.002)
    f, on = _body_force(tr)
    k = np.flatnonzero(on)[:20]
    assert f[k, 1] / f[k, 0] == pytest.approx(side * truth.mu_p, rel=1e-6)
    assert np.abs(tr.y_c[k] - y_c0).max() < 1e-7  # on the edge: no slip yet


@pytest.mark.parametrize("beta", [0.7, -0.7])
def test_push_outside_the_motion_cone_slides_with_the_force_on_the_cone_edge(beta):
    truth = PusherFrictionTruth(mu_p=0.3)
    tr = quasi_static_push(truth, -0.01 if beta > 0 else 0.01, beta, 0.05)
    f, on = _body_force(tr)
    w = _push_window(tr)
    assert not tr.stick[w].any()
    assert f[w, 1] / f[w, 0] == pytest.approx(np.sign(beta) * truth.mu_p, rel=1e-9)
    # the contact slides the way the pusher slips: y_c moves towards the side of beta
    assert np.sign(tr.y_c[w[-1]] - tr.y_c[w[0]]) == np.sign(beta)


def test_contact_wrenches_lie_on_the_limit_surface_and_scale_with_table_friction():
    a = 0.04
    for mu_t in (0.25, 0.5):
        truth = PusherFrictionTruth(mu_t=mu_t, mu_p=0.3)
        tr = quasi_static_push(truth, 0.0, 0.35, 0.06)
        f, on = _body_force(tr)
        moment = -a * f[on, 1] - tr.y_c[on] * f[on, 0]
        ls = f[on, 0] ** 2 + f[on, 1] ** 2 + (moment / truth.c) ** 2
        assert np.sqrt(ls) == pytest.approx(mu_t * truth.mass * G, rel=1e-9)
        if mu_t == 0.25:
            pose_a = tr.pose
    # quasi-static: the poses do not depend on the table friction
    assert np.abs(tr.pose - pose_a).max() < 1e-12


def test_rate_independent():
    truth = PusherFrictionTruth()
    slow = quasi_static_push(truth, 0.005, 0.35, 0.05, speed=0.02)
    fast = quasi_static_push(truth, 0.005, 0.35, 0.05, speed=0.04)
    assert np.abs(slow.pose[-1] - fast.pose[-1]).max() < 2e-5


def test_default_pushes_turn_20_to_60_deg_and_record_the_force():
    rec = make_pusher_friction(seed=1, noise="zero")
    turn = np.abs(rec.meta["truth"]["turn_deg"])
    assert np.all((turn > 20) & (turn < 60))
    tr = rec.trajectories[0]
    assert tr.wrench_force.shape[1] == 3 and len(tr.wrench_t_ns) == len(tr.wrench_force)
    # out of contact the sensor reads its offset only
    first = tr.wrench_force[: int(0.25 * 250)]
    assert np.allclose(first, np.asarray(PusherFrictionTruth().sensor_offset), atol=1e-12)
    stick = [f.stick[~np.isnan(f.y_c)].mean() for f in rec.meta["fine"]]
    assert min(stick) < 0.05 and max(stick) > 0.3  # pushes that slide all along and that stick

"""The spacing the MuJoCo engine smooths its servo targets over (``mujoco_engine``: "Drive
knots" in its docstring).

A drive built from stamps carries their sample interval (``Drive.sample_dt``, the median stamp
spacing per trajectory; ``prepare`` and ``make_drive`` set it) and the engine smooths over
``sample_dt / dt`` steps (``sample_steps``). Oracles: the clock's own spacing; and a constant
deceleration sampled on any clock, linearly interpolated onto 1 ms steps as ``prepare`` does,
whose servo targets must decelerate at that constant on every step (no velocity staircase):
exactly for a whole number of steps at any phase, within the filter's ripple (closed form,
``smooth_knots``) for a fractional one. Without the interval the spacing is read from the
path's second differences (``drive_knot_steps``), which works for stamps on the steps (250 Hz:
4 steps; 500 Hz jittered on whole ms with a dropped sample: 2) and reads 1, no smoothing, for
stamps between them (issue 16, h75)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.format.errors import InputError
from robogs.physics.engines.base import make_drive
from robogs.physics.engines.mujoco_engine import (
    drive_knot_steps,
    sample_steps,
    servo_targets,
    smooth_knots,
)

DT = 1e-3


def _drive(stamps: np.ndarray, t_end: float = 0.6) -> np.ndarray:
    """x = 0.2 sin(3 t) + 0.05 t^2 sampled at ``stamps`` [s], linear onto the 1 ms grid:
    [1, S, 3]."""
    grid = np.arange(0.0, t_end, DT)
    x = 0.2 * np.sin(3.0 * stamps) + 0.05 * stamps**2
    p = np.interp(grid, stamps, x)
    return np.stack([p, 0.5 * p, np.zeros_like(p)], -1)[None]


def test_spacing_of_a_250_hz_clock_is_4_steps():
    assert drive_knot_steps(_drive(np.arange(0.0, 0.7, 0.004))) == 4


def test_spacing_of_a_jittered_500_hz_clock_with_a_gap_is_2_steps():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 0.7, 0.002)
    t = np.round((t + rng.normal(0.0, 5e-5, t.size)) / DT) * DT  # stamps land on the 1 ms grid
    t = np.unique(np.delete(t, 100))  # one dropped sample
    assert drive_knot_steps(_drive(t)) == 2


def test_every_step_a_knot_and_a_straight_path_are_left_alone():
    assert drive_knot_steps(_drive(np.arange(0.0, 0.7, DT))) == 1
    line = np.linspace(0.0, 1.0, 200)[None, :, None] * np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(smooth_knots(line, 4), line, atol=1e-15)
    np.testing.assert_allclose(smooth_knots(line, 8.33), line, atol=1e-15)
    assert drive_knot_steps(line) == 1


def _made(stamps: np.ndarray, path: np.ndarray, every: float | None):
    """``make_drive`` of one trajectory on the 1 ms grid with sample interval ``every``."""
    s = path.shape[1]
    return make_drive(
        DT, path, np.zeros((1, s)), np.zeros((1, 1)), np.zeros((1, 3)), np.zeros(1), every
    )


def test_spacing_of_a_500_hz_clock_off_the_step_grid_is_2_steps():
    """Issue 16 (h75; the strict xfail before): stamps 0.3 ms off the 1 ms grid bend the path
    on every step, so its second differences read 1; the drive carries the clock's interval,
    2 ms, and the engine smooths over 2 steps."""
    t = np.arange(0.0, 0.7, 0.002) + 3e-4
    path = _drive(t)
    assert drive_knot_steps(path) == 1  # the fallback cannot see it
    drive = _made(t, path, float(np.median(np.diff(t))))
    assert sample_steps(drive).tolist() == [2.0]


A = 2.0
"""The constant deceleration of :func:`_brake` [m/s^2]."""


def _brake(stamps: np.ndarray, t_end: float = 0.6) -> np.ndarray:
    """x = 0.6 t - A t^2 / 2 (0.6 m/s braking at :data:`A`) sampled at ``stamps``, linear onto
    the 1 ms grid: [1, S, 3]."""
    grid = np.arange(0.0, t_end, DT)
    p = np.interp(grid, stamps, 0.6 * stamps - 0.5 * A * stamps**2)
    return np.stack([p, -0.5 * p, np.zeros_like(p)], -1)[None]


def _ripple(path: np.ndarray, knot_steps) -> float:
    """Largest |servo deceleration / A - 1| over the steps of ``path`` [1, S, 3] 70 steps from
    its ends, the servo targets from ``servo_targets`` (deceleration: second difference over
    dt^2)."""
    sp, _ = servo_targets(path, np.zeros(path.shape[:2]), knot_steps)
    acc = -np.diff(sp[0, :, 0], 2) / DT**2
    return float(np.max(np.abs(acc[70:-70] / A - 1.0)))


_RNG = np.random.default_rng(11)
CLOCKS = {
    # name: (stamps [s], bound on the smoothed ripple, measured raw ripple floor)
    "500hz-offset-0.3ms": (np.arange(0.0, 0.7, 0.002) + 3e-4, 1e-6, 0.39),
    "500hz-jittered": (
        np.sort(np.arange(0.0, 0.7, 0.002) + _RNG.uniform(-2e-4, 2e-4, 350)),
        0.2,
        1.0,
    ),
    "250hz-offset-0.3ms": (np.arange(0.0, 0.7, 0.004) + 3e-4, 1e-6, 1.7),
    "120hz": (np.arange(0.0, 0.7, 1 / 120) + 1e-4, 0.03, 6.0),
}


@pytest.mark.parametrize("clock", list(CLOCKS))
def test_servo_targets_of_an_off_grid_clock_have_no_velocity_staircase(clock: str):
    """A constant deceleration sampled on a clock whose stamps fall between the steps: through
    the drive's sample interval the servo decelerates at A on every step, exactly (1e-6) on a
    whole number of steps (500 Hz offset 0.3 ms, 250 Hz offset 0.3 ms), within 2.7 % on
    120 Hz's 8.33 steps (closed form over all phases; measured 1.7 %), within 20 % on a 500 Hz
    clock jittered by +-0.2 ms (measured 13 %: the interpolated path's own velocity changes
    vary with the stamp spacing). Without the interval (the path's second differences read 1)
    the servo follows the staircase: A x (1.4, 0.6) on the offset 500 Hz clock, up to
    A x 7.5 at 120 Hz."""
    stamps, bound, raw_floor = CLOCKS[clock]
    path = _brake(stamps)
    drive = _made(stamps, path, float(np.median(np.diff(stamps))))
    assert _ripple(path, sample_steps(drive)) < bound
    assert drive_knot_steps(path) == 1
    assert _ripple(path, None) > raw_floor


def _tri_ripple(n_taps: float, spacing: float) -> float:
    """Largest |servo deceleration / A - 1| of :func:`_brake` sampled every ``spacing`` steps
    at 20 phases, smoothed with ``smooth_knots(., n_taps)``."""
    worst = 0.0
    for phase in np.linspace(0.0, spacing, 20, endpoint=False):
        stamps = np.arange(0.0, 0.7, spacing * DT) + phase * DT
        worst = max(worst, _ripple(_brake(stamps), n_taps))
    return worst


@pytest.mark.parametrize(("spacing", "bound"), [(2.5, 0.1001), (8.333333, 0.027)])
def test_a_fractional_spacing_beats_the_nearest_whole_one(spacing: float, bound: float):
    """A clock that is not a whole number of steps (400 Hz: 2.5, 120 Hz: 8.33 on 1 ms): the
    triangle with a fractional last tap leaves a ripple of at most 10 % / 2.7 % of the
    deceleration over 20 phases (measured 10.000 % / 2.667 %, as the closed form over all
    phases gives: the linear interpolant of the weights summed at the clock's spacing), less
    than the nearest whole spacing's triangle (25.0 % / 4.17 %) and the raw path's (150 % /
    733 %)."""
    frac = _tri_ripple(spacing, spacing)
    whole = _tri_ripple(float(round(spacing)), spacing)
    assert frac < bound < whole
    assert _tri_ripple(1.0, spacing) > spacing - 1.0 - 0.05


def test_a_whole_spacing_keeps_the_triangle_of_two_moving_averages():
    """Stamps on the grid (the generator's 500 Hz on 1 ms) keep h67's weights bit for bit, so
    the friction figures measured with them do not move: n = 2 (and the float quotient
    0.002 / 0.001 = 2.0000000000000004 snapped to it) is 1/4, 1/2, 1/4; n = 4 is
    (1, 2, 3, 4, 3, 2, 1) / 16."""
    x = np.random.default_rng(0).normal(size=(2, 50, 3))
    want = x.copy()
    want[:, 1:-1] = 0.25 * x[:, :-2] + 0.5 * x[:, 1:-1] + 0.25 * x[:, 2:]
    assert np.array_equal(smooth_knots(x, 2), want)
    assert np.array_equal(smooth_knots(x, 0.002 / 0.001), want)
    w = np.array([1, 2, 3, 4, 3, 2, 1]) / 16.0
    want4 = x.copy()
    want4[:, 3:-3] = sum(w[j] * x[:, j : 50 - 6 + j] for j in range(7))
    np.testing.assert_allclose(smooth_knots(x, 4), want4, rtol=0, atol=1e-15)


def test_sample_steps_snaps_clamps_and_falls_back_per_trajectory():
    """The interval over the step, snapped to a whole number within 1e-6, clamped to 1 .. 64;
    a trajectory without one (NaN) gets the spacing read from its own path, the others keep
    theirs; a drive without intervals gives None; a zero interval is refused."""
    s = 200
    grid = np.arange(s) * DT
    paths = np.stack([_brake(np.arange(0.0, 0.3, 0.004))[0][:s]] * 4)
    drive = make_drive(
        DT,
        paths,
        np.zeros((4, s)),
        np.zeros((4, 1)),
        np.zeros((4, 3)),
        np.zeros(4),
        np.array([0.002, 2e-4, 0.2, np.nan]),
    )
    steps = sample_steps(drive)
    assert steps[:3].tolist() == [2.0, 1.0, 64.0]
    assert np.isnan(steps[3])
    sp, _ = servo_targets(drive.pusher.numpy(), np.zeros((4, s)), steps)
    np.testing.assert_array_equal(sp[0], smooth_knots(paths[:1], 2)[0])
    np.testing.assert_array_equal(sp[1], paths[1])
    np.testing.assert_array_equal(sp[3], smooth_knots(paths[3:], 4)[0])  # read: 4 ms on grid
    assert sample_steps(_made(grid, paths[:1], None)) is None
    drive.sample_dt = torch.tensor([0.002, 0.0, 0.002, 0.002], dtype=torch.float64)
    with pytest.raises(InputError, match="not positive"):
        sample_steps(drive)


def test_prepare_carries_each_trajectory_s_encoder_interval():
    """``prepare`` records the median EE stamp spacing per trajectory: the generator's 500 Hz
    on the grid gives 2 ms and 2 steps, which the path's second differences read too (so the
    generator's figures do not move); the same push restamped with +-0.2 ms jitter gives its
    own median (oracle: the stamps' median spacing) while its path reads 1. ``subset`` keeps
    the intervals with their trajectories."""
    from robogs.physics.prepare import prepare
    from robogs.synth.scenarios.generate import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",), noise="zero", n_speeds=1, n_dirs=2)
    tr = rec.trajectories[1]
    rng = np.random.default_rng(4)
    tr.ee_t_ns = np.sort(tr.ee_t_ns + rng.integers(-200_000, 200_000, tr.ee_t_ns.size))
    drive = prepare(rec).drive
    jittered = float(np.median(np.diff(tr.ee_t_ns))) * 1e-9
    np.testing.assert_allclose(drive.sample_dt.numpy(), [0.002, jittered], rtol=1e-12)
    assert jittered != 0.002
    steps = sample_steps(drive)
    assert steps[0] == 2.0 == drive_knot_steps(drive.pusher[:1].numpy())
    assert steps[1] == pytest.approx(jittered / DT, rel=1e-12)
    assert drive_knot_steps(drive.pusher[1:].numpy()) == 1
    assert sample_steps(drive.subset([1])).tolist() == steps[1:].tolist()

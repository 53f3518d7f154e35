"""T015's interval covers the true lag at its stated 95 % level (brute force over seeds).

Each seed draws a cube's path on the table (random phases), a delay of its pose stream (up to
25 ms either way), the pose stamps' phase against the camera frames, and 0.2 mm of pose noise;
the boxes are the cube's projected corners rounded outwards to pixel edges. The projection is
written here (pinhole, camera 1 m above the table looking down), not taken from the check.

Before the fix the pose noise, linearly interpolated, pulled the lag towards the phases where
the box stamps fall midway between poses: with the pose stamps 3.1 ms off the frames and a
12 ms delay the lag came out 0.5 ms late and its interval covered the truth 73 % of the time.
"""

from __future__ import annotations

import numpy as np
import pytest

from robogs.format.checks.lag_pairs import box_centre_lag, smooth_series

T0 = 1_000_000_000
FX, CX, CY, SIZE = 500.0, 320.0, 240.0, 0.05
CORNERS = np.array(np.meshgrid(*[[-SIZE / 2, SIZE / 2]] * 3, indexing="ij")).reshape(3, -1).T
POSE_NS, FRAME_NS = 8_333_333, 33_333_333  # 120 Hz poses, 30 Hz frames


def _path(t_s: np.ndarray, ph: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cube centre [N, 3] m and yaw [N] rad, up to ~0.2 m/s, phases ``ph`` [5]."""
    xyz = np.stack(
        [
            0.5 + 0.10 * np.sin(1.3 * t_s + ph[0]) + 0.03 * np.sin(3.1 * t_s + ph[1]),
            0.08 * np.sin(0.9 * t_s + ph[2]) + 0.02 * np.cos(2.3 * t_s + ph[3]),
            np.full_like(t_s, SIZE / 2),
        ],
        axis=1,
    )
    return xyz, 0.5 * np.sin(0.7 * t_s + ph[4])


def _corner_px(xyz: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[N, 8] u and v (px) of the cube's corners; camera at (0.5, 0, 1) looking down (-z),
    its x along world x and y along world -y."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = c * CORNERS[:, 0] - s * CORNERS[:, 1] + xyz[:, :1]
    y = s * CORNERS[:, 0] + c * CORNERS[:, 1] + xyz[:, 1:2]
    depth = 1.0 - (CORNERS[:, 2] + xyz[:, 2:3])
    return FX * (x - 0.5) / depth + CX, FX * (-y) / depth + CY


def _case(seed: int, delay_ms: float | None = None, phase_ns: int | None = None):
    """(t_p, projected centres, t_b, box centres, true lag of the boxes behind the poses)."""
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, 5)
    delay = rng.uniform(-25.0, 25.0) if delay_ms is None else delay_ms
    off = int(rng.integers(0, POSE_NS)) if phase_ns is None else phase_ns
    t_p = T0 + off + np.arange(720) * POSE_NS
    t_b = T0 + np.arange(180) * FRAME_NS
    xyz, yaw = _path((t_p - T0) * 1e-9 - delay * 1e-3, ph)
    u, v = _corner_px(xyz + rng.normal(0, 2e-4, xyz.shape), yaw)
    c_p = np.stack([u.min(1) + u.max(1), v.min(1) + v.max(1)], 1) / 2
    u, v = _corner_px(*_path((t_b - T0) * 1e-9, ph))
    c_b = np.stack(
        [np.floor(u.min(1)) + np.ceil(u.max(1)), np.floor(v.min(1)) + np.ceil(v.max(1))], 1
    )
    return t_p, c_p, t_b, c_b / 2, -delay


def _runs(cases) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    err, cover, half = [], [], []
    for t_p, c_p, t_b, c_b, truth in cases:
        est = box_centre_lag(t_p, c_p, t_b, c_b)
        assert est is not None
        err.append(est.lag_ms - truth)
        cover.append(est.lo_ms <= truth <= est.hi_ms)
        half.append(0.5 * (est.hi_ms - est.lo_ms))
    return np.array(err), np.array(cover), np.array(half)


def test_t015_interval_covers_the_truth_at_its_level() -> None:
    """100 seeds (random delay, path and phase): at least 90 covered (95 % nominal; the
    binomial chance of 89 or fewer is 1 %; 98 do, the unsmoothed fit 84); intervals stay
    sub-millisecond."""
    err, cover, half = _runs(_case(s) for s in range(100))
    assert cover.sum() >= 90, (cover.mean(), err.mean(), half.mean())
    assert half.mean() < 1.0 and abs(err.mean()) < 0.1


def test_t015_no_phase_pull_in_the_reported_case() -> None:
    """The issue's case (12 ms delay, pose stamps 3.1 ms off the frames), 60 seeds: the mean
    error is within 0.15 ms (it was 0.48 ms) and at least 52 of 60 intervals cover the truth
    (55 do; the unsmoothed fit covered 41)."""
    err, cover, _ = _runs(_case(s, delay_ms=12.0, phase_ns=3_100_000) for s in range(60))
    assert abs(err.mean()) < 0.15, err.mean()
    assert cover.sum() >= 52, cover.mean()


def test_smooth_series_keeps_a_quadratic_and_lowers_noise() -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.integers(6_000_000, 11_000_000, 400))  # irregular stamps (held dropped)
    s = (t - t[0]) * 1e-9
    p = np.stack([0.3 + 2.0 * s - 0.7 * s**2, np.full_like(s, -1.5)], 1)
    np.testing.assert_allclose(smooth_series(t, p, 5), p, atol=1e-9)
    noise = rng.normal(0, 1.0, (t.size, 1))
    ratio = smooth_series(t, noise, 5)[20:-20].std() / noise[20:-20].std()
    assert ratio == pytest.approx(np.sqrt(89 / 429), rel=0.25)  # quadratic SG, 11 points
    np.testing.assert_array_equal(smooth_series(t, noise, 1), noise)  # k < 2: unchanged

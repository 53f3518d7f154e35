"""New and reworked time checks: inter-stream lag (T013), held samples (T014), drops and jitter
that stay right under large jitter (T004-T006).

Fixtures are corrupted by :mod:`robogs.synth.mutations` or built here with numpy and pyarrow;
expected values come from the construction, never from the code under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.format import Dataset
from robogs.format.checks.clock import chunks_with_context
from robogs.format.checks.stale import HeldScan, held_mask
from robogs.format.checks.sync import estimate_stream_lag
from robogs.synth import mutations as mut

from .scope import validate

_POSE = ("x", "y", "z", "qw", "qx", "qy", "qz")


def _found(report, code: str, stream: str | None = None) -> list:
    return [
        f
        for f in report.findings
        if f.code == code and (stream is None or f.location.stream == stream)
    ]


# --------------------------------------------------------------------------- T013 lag


def _motion(t_s: np.ndarray) -> np.ndarray:
    """[N, 3] a smooth 3D path (m): two incommensurate sines per axis, up to ~0.3 m/s."""
    return np.stack(
        [
            0.05 * np.sin(2.1 * t_s) + 0.02 * np.sin(5.3 * t_s),
            0.04 * np.cos(1.7 * t_s) + 0.01 * np.sin(7.1 * t_s),
            0.03 * np.sin(3.3 * t_s + 0.4),
        ],
        axis=1,
    )


@pytest.mark.parametrize("lag_ms", [12.0, -7.5, 0.0])
def test_stream_lag_recovers_a_known_shift(lag_ms: float) -> None:
    rng = np.random.default_rng(0)
    t_ref = 10**9 + np.arange(0, 10_000) * 2_000_000  # 500 Hz, 20 s
    t_obs = 10**9 + 3_000_000 + np.arange(0, 8_000) * 2_500_000  # 400 Hz, other phase
    p_ref = _motion((t_ref - t_ref[0]) * 1e-9)
    p_obs = _motion((t_obs - t_ref[0]) * 1e-9 - lag_ms * 1e-3) + [0.004, -0.002, 0.001]
    p_obs += rng.normal(0, 2e-4, p_obs.shape)  # 0.2 mm noise
    est = estimate_stream_lag(t_ref, p_ref, t_obs, p_obs)
    assert est is not None
    assert est.lag_ms == pytest.approx(lag_ms, abs=0.1)
    assert est.lo_ms <= lag_ms <= est.hi_ms
    assert est.hi_ms - est.lo_ms < 0.5
    if lag_ms:
        assert est.rms_at_lag < 0.5 * est.rms_at_zero


def test_stream_lag_interval_covers_the_truth() -> None:
    """Over 20 noise draws the 95 % jackknife interval holds the true lag at least 16 times."""
    t_ref = 10**9 + np.arange(0, 5_000) * 2_000_000
    t_obs = 10**9 + 1_000_000 + np.arange(0, 4_000) * 2_500_000
    p_ref = _motion((t_ref - t_ref[0]) * 1e-9)
    p_true = _motion((t_obs - t_ref[0]) * 1e-9 - 0.012)
    inside = 0
    for seed in range(20):
        noise = np.random.default_rng(seed).normal(0, 3e-4, p_true.shape)
        est = estimate_stream_lag(t_ref, p_ref, t_obs, p_true + noise)
        inside += est.lo_ms <= 12.0 <= est.hi_ms
    assert inside >= 16


def test_stream_lag_needs_motion() -> None:
    t = 10**9 + np.arange(0, 3000) * 2_000_000
    still = np.zeros((t.size, 3)) + [0.3, 0.1, 0.2]
    assert estimate_stream_lag(t, still, t, still) is None


def test_delayed_ee_poses_are_caught_with_their_lag(clean_copy: Path) -> None:
    mut.delay_ee_poses(clean_copy, ms=12.0)
    report = validate(clean_copy, budgets={"geometry.fk_ee_mm": 1000.0})
    assert report.codes(min_severity="error") == {"T013"}, [f.to_dict() for f in report.findings]
    (f,) = _found(report, "T013")
    assert f.value == pytest.approx(12.0, abs=1.0)
    assert f.location.link


def test_clean_fixture_has_no_lag_and_no_held_samples(clean_root: Path) -> None:
    report = validate(clean_root)
    assert not _found(report, "T013") and not _found(report, "T014")


# --------------------------------------------------------------------------- T014 held samples


def test_half_held_poses_are_caught(clean_copy: Path, clean_root: Path) -> None:
    _ep, _n, st = mut._stream(clean_root, "ee_poses")
    clean = pq.read_table(clean_root / st["path"])
    mut.hold_samples(clean_copy, kind="ee_poses", every=2, run=1)
    report = validate(clean_copy)
    assert report.codes(min_severity="error") == set(), [f.to_dict() for f in report.findings]
    (f,) = _found(report, "T014", "ee_poses")
    assert f.severity == "warning"  # a value held one period (2 ms) stays within time.sync_ms
    # the held rows that fall while the pose moves: odd rows whose clean value differs
    v = np.stack([clean.column(c).to_numpy() for c in _POSE], axis=1)
    odd = np.arange(1, v.shape[0], 2)
    moving = int(np.sum(np.any(v[odd] != v[odd - 1], axis=1)))
    assert f.value * v.shape[0] == pytest.approx(moving, rel=0.15)
    assert f.value > 0.25


def test_long_holds_are_errors(clean_copy: Path) -> None:
    mut.hold_samples(clean_copy, kind="joint_states", every=5, run=3)
    report = validate(clean_copy, budgets={"geometry.fk_ee_mm": 1000.0})
    (f,) = _found(report, "T014", "joint_states")
    assert f.severity == "error"  # a value held 3 periods (6 ms) > time.sync_ms
    assert f.value > 0.3
    assert "longest run 3 samples" in f.message


def test_robot_at_rest_is_not_held(clean_copy: Path) -> None:
    mut.pause_joint_states(clean_copy, start=0.4, length=0.2)
    _ep, _n, st = mut._stream(clean_copy, "joint_states")
    tab = pq.read_table(clean_copy / st["path"])
    q = np.stack([tab.column(c).to_numpy() for c in tab.column_names if "position." in c], 1)
    assert np.sum(np.all(q[1:] == q[:-1], axis=1)) > 0.15 * q.shape[0]  # a long exact rest
    report = validate(clean_copy, ignore=["T012"])  # the video still shows the unpaused motion
    assert not _found(report, "T014"), [f.to_dict() for f in _found(report, "T014")]


def test_held_scan_streams_like_the_whole_series() -> None:
    rng = np.random.default_rng(1)
    for trial in range(300):
        n = int(rng.integers(2, 300))
        t = np.cumsum(rng.integers(1, 5, n)) * 1_000_000
        v = np.cumsum(rng.normal(0.5, 1, (n, 2)), axis=0)
        if trial % 2:
            idx = np.arange(n)
            v = v[idx - idx % 2]
        for _ in range(int(rng.integers(0, 20))):
            a, length = int(rng.integers(0, n)), int(rng.integers(1, 6))
            v[a : a + length] = v[a]
        scan = HeldScan()
        k = int(rng.integers(0, min(n - 1, 12) + 1))
        cuts = np.sort(rng.choice(np.arange(1, n), size=k, replace=False))
        for tt, vv, rr in zip(
            np.split(t, cuts), np.split(v, cuts), np.split(np.arange(n), cuts), strict=True
        ):
            scan.absorb(tt, vv, rr)
        assert (scan.n, scan.held) == (n, int(held_mask(t, v).sum())), trial


def test_held_mask_on_closed_forms() -> None:
    t = np.arange(12) * 1_000_000
    ramp = np.arange(12.0)[:, None]
    held = ramp.copy()
    held[5] = held[4]  # re-sent while moving: caught up at the next sample
    assert held_mask(t, held).tolist() == [i == 5 for i in range(12)]
    rest = np.concatenate([np.arange(5.0), np.full(4, 4.0), 4 + np.arange(1.0, 4.0)])[:, None]
    assert not held_mask(t, rest).any()  # stops, rests, resumes at the same speed
    flicker = np.array([0, 1, 0, 0, 1, 1, 0, 1, 1, 0, 0, 1], float)[:, None]
    assert not held_mask(t, flicker).any()  # noise at rest
    assert not held_mask(t, np.ones((12, 3))).any()


# --------------------------------------------------------------------------- T004-T006 clock


def _stream_dataset(root: Path, t: np.ndarray, rate_hz: float) -> Path:
    """A dataset with one wrench stream stamped ``t`` (values a slow sine)."""
    k = np.arange(t.size)
    cols = {c: np.sin(0.01 * k + i) for i, c in enumerate(("fx", "fy", "fz", "tx", "ty", "tz"))}
    rel = "episodes/ep000/wrenches.parquet"
    with Dataset.create(root) as w:
        w.write_table(
            rel,
            pa.table({"t_ns": pa.array(t, pa.int64()), "frame": ["tool0"] * t.size, **cols}),
            kind="wrenches",
        )
        stream = {
            "kind": "wrenches",
            "path": rel,
            "stamp_source": "synthetic",
            "offset_ns": 0,
            "nominal_rate_hz": rate_hz,
        }
        w.add_episode("ep000", start_ns=int(t[0]), end_ns=int(t[-1]), streams={"wrenches": stream})
        w.commit()
    return root


def test_drops_are_counted_right_under_jitter_a_quarter_of_the_period(tmp_path: Path) -> None:
    period = 1e9 / 120.0
    rng = np.random.default_rng(0)
    n_slots = 40_000
    drop = rng.random(n_slots) < 0.005  # 0.5 % drops, isolated (two in a row would be a gap)
    drop[1:] &= ~drop[:-1]
    drop[[0, -1]] = False
    slot = np.flatnonzero(~drop)
    err = np.clip(
        rng.normal(0, 0.25 * period / np.sqrt(2), slot.size), -0.45 * period, 0.45 * period
    )
    t = (10**9 + np.rint(slot * period + err)).astype(np.int64)
    d = np.diff(t)
    assert np.std(d[np.diff(slot) == 1]) == pytest.approx(0.25 * period, rel=0.05)
    lost_as_drops = int(drop.sum())
    naive = int(np.sum(d > 1.5 * np.median(d)))
    assert naive > 3 * lost_as_drops  # the interval threshold alone over-counts
    report = validate(_stream_dataset(tmp_path / "ds", t, 120.0))
    (f,) = _found(report, "T004")
    assert f.value == pytest.approx(lost_as_drops, rel=0.2)
    # two drops within 10 samples whose longer interval jitters past 2.5 periods read as one gap
    # (a 3-sigma jitter): rare, but not impossible
    assert report.codes(min_severity="error") <= {"T003"}, [x.message for x in report.findings]
    assert len(_found(report, "T003")) <= 2


def test_mocap_jitter_of_6_6_ms_p99_is_not_an_error(tmp_path: Path) -> None:
    """120 Hz, stamped on arrival: 1.25 ms normal jitter plus 1 % late by up to 12 ms (FIFO)."""
    period = 1e9 / 120.0
    rng = np.random.default_rng(1)
    n = 24_000
    late = (rng.random(n) < 0.01) * rng.uniform(0, 12e6, n)
    t = np.arange(n) * period + rng.normal(0, 1.25e6, n) + late
    for k in range(1, n):  # a queue delivers in order
        t[k] = max(t[k], t[k - 1] + 2e5)
    t = (10**9 + np.rint(t)).astype(np.int64)
    dev = np.diff(t) - np.median(np.diff(t))
    assert np.sqrt(np.mean(dev**2)) * 1e-6 == pytest.approx(2.0, abs=0.2)
    assert np.percentile(np.abs(dev), 99) * 1e-6 == pytest.approx(6.6, abs=0.4)
    report = validate(_stream_dataset(tmp_path / "ds", t, 120.0))
    assert report.codes(min_severity="error") == set(), [f.to_dict() for f in report.findings]
    assert not _found(report, "T004")  # no sample was lost


def test_uniform_jitter_beyond_the_budget_is_an_error(tmp_path: Path) -> None:
    """30 Hz stamps off by up to +-9 ms: the stamp error p99 (~8.9 ms) exceeds 5 ms."""
    rng = np.random.default_rng(2)
    period = 1e9 / 30.0
    err = rng.uniform(-9e6, 9e6, 3000)
    t = (10**9 + np.rint(np.arange(3000) * period + err)).astype(np.int64)
    report = validate(_stream_dataset(tmp_path / "ds", t, 30.0))
    (f,) = _found(report, "T005")
    # the local clock (median of 21 stamps) adds its own ~1.4 ms noise to the true error
    assert f.severity == "error"
    assert f.value == pytest.approx(np.percentile(np.abs(err), 99) * 1e-6, rel=0.25)


def test_chunks_with_context_cover_every_sample_once() -> None:
    x = np.arange(1000)
    seen = []
    for g0, (a,), lo, hi in chunks_with_context(((x[i : i + 97],) for i in range(0, 1000, 97)), 40):
        assert np.array_equal(a, x[g0 : g0 + a.size])
        assert lo >= min(40, g0 + lo) and a.size - hi >= min(40, 1000 - (g0 + hi))
        seen.extend(a[lo:hi].tolist())
    assert seen == list(range(1000))


# --------------------------------------------------------------------------- T013 cost bounds


def test_motion_windows_keep_the_runs_that_move() -> None:
    """A series at rest but for three bursts: the windows are exactly the bursts' runs."""
    from robogs.format.checks.sync import motion_windows

    n, per = 20_000, 250
    t = np.arange(n, dtype=np.int64) * 2_000_000
    p = np.zeros((n, 3))
    moving = [3, 41, 77]  # run indices
    for k in moving:
        p[k * per : (k + 1) * per, 0] = np.sin(np.linspace(0, 3, per))
    idx = motion_windows(t, p, windows=3, per=per)
    assert np.array_equal(idx, np.concatenate([np.arange(k * per, (k + 1) * per) for k in moving]))
    short = np.arange(100)
    assert np.array_equal(motion_windows(t[:100], p[:100], windows=3, per=per), short)


def test_reference_near_the_runs_brackets_every_query() -> None:
    """Brute force: every reference sample within the margin of an observed stamp is kept,
    plus one on each side; nothing farther than one sample beyond the margin."""
    from robogs.format.checks.sync import _near

    rng = np.random.default_rng(3)
    t_ref = np.cumsum(rng.integers(1_000_000, 3_000_000, 5_000)).astype(np.int64)
    t_obs = np.sort(rng.choice(t_ref, 40, replace=False)) + 500_000
    margin = 10_000_000
    keep = _near(t_ref, t_obs, margin)
    dist = np.min(np.abs(t_ref[:, None] - t_obs[None, :]), axis=1)
    inside = dist <= margin
    assert keep[inside].all()
    grown = inside.copy()
    grown[1:] |= inside[:-1]
    grown[:-1] |= inside[1:]
    assert not keep[~grown].any()


def test_delayed_poses_on_a_long_episode_are_timed_on_the_runs_of_most_motion(
    tmp_path: Path,
) -> None:
    """60 s of the synthetic scene played back and forth (the bench's episode): the fit uses
    16 runs and forward kinematics near them only, and still finds the 12 ms within 1 ms."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
    try:
        import time_lag
    finally:
        sys.path.pop(0)
    root = time_lag.build(tmp_path / "long", 60.0, 12.0)
    (f,) = _found(validate(root, select=["T013"]), "T013")
    assert f.value == pytest.approx(12.0, abs=1.0)

"""The gate's opt-in parametric null (``gate.calibrate(method="parametric")``, h76) and the drive
error it simulates (robogs.physics.drive_noise).

Oracles: (1) on a linear model whose data carry a shared input error of known covariance, the
family-wise false-positive rate measured by brute force on fresh data sits at 5 % within its
binomial band, while the white-noise null over-rejects the same data (a mutated fixture: the
input error is what white noise lacks); (2) without an input model the null is the white one
draw for draw; (3) the coefficients' covariance is reproduced exactly; (4) the drive-error draws
are the smoother's response to white noise at the path's own noise (closed form from the
smoother's weights); (5) the batched evaluation is the one-by-one evaluation.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_gate import _stats  # the held-out statistic of each candidate on draws [D, T, K]

from robogs.physics import gate
from robogs.physics.gate import LinearCandidate, calibrate

T_N, K = 9, 160


def _toy(seed: int = 0):
    """Base: 2 global columns + 3 nuisance columns per trajectory; the input error moves each
    trajectory along 2 smooth directions (a shift after a 'release' and a bump) with a known
    covariance; candidates: one that fits those directions alike on every trajectory (what a
    shared input error fakes), and two unrelated ones."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, K)
    base = np.stack([np.tile(s, (T_N, 1)), np.tile(s**2, (T_N, 1))], axis=-1)
    loc = np.stack([np.ones((T_N, K)), np.tile(s, (T_N, 1)), np.tile(np.cos(3 * s), (T_N, 1))], -1)
    rel = 0.3 + 0.4 * rng.uniform(size=T_N)  # each trajectory's own release
    shift = np.clip(s[None] - rel[:, None], 0, None) * 4.0
    bump = np.exp(-(((s[None] - rel[:, None]) / 0.05) ** 2))
    j_in = np.stack([shift, bump], axis=-1)  # [T, K, 2]
    a = rng.normal(size=(T_N, 2, 2))
    cov = 6.0 * (a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(2))  # [T, 2, 2], tens of sigma^2
    extra = {
        "common": (shift + 0.5 * bump)[..., None],
        "wavy": np.stack([np.sin(7 * s + t) for t in range(T_N)])[..., None],
        "random": rng.normal(size=(T_N, K, 2)),
    }
    cands = [
        LinearCandidate(n, np.concatenate([base, e], axis=-1), loc, base.shape[-1])
        for n, e in extra.items()
    ]
    folds = [np.arange(T_N) % 5 == f for f in range(5)]
    return cands, folds, j_in, cov


def _data(j_in, cov, sigma, n, rng):
    """``n`` datasets [n, T, K]: white noise ``sigma`` plus ``j_in delta``, ``delta ~ N(0, cov)``."""
    low = np.linalg.cholesky(cov)
    delta = (low[None] @ rng.normal(size=(n, T_N, cov.shape[-1], 1)))[..., 0]
    return rng.normal(0, sigma, (n, T_N, K)) + (j_in[None] @ delta[..., None])[..., 0]


def test_parametric_null_keeps_five_percent_where_white_noise_over_rejects(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, j_in, cov = _toy()
    sigma = 1.3
    valid = np.ones((T_N, K), bool)
    base_resid = _data(j_in, cov, sigma, 1, np.random.default_rng(3))[0]  # sets the scale
    kw = dict(draws=1000, seed=1)
    par = calibrate(
        cands, base_resid, valid, folds, method="parametric", inputs=j_in, input_cov=cov, **kw
    )
    white = calibrate(cands, base_resid, valid, folds, method="white", **kw)
    assert par.method.startswith("parametric (white noise + 2 input-error directions")
    st = _stats(cands, folds, _data(j_in, cov, sigma, 3000, np.random.default_rng(99)))

    def fwer(cal):
        thr = np.array([cal.thresholds[c.name] for c in cands])
        return float(np.mean((st > thr).any(axis=1)))

    # binomial band of 5 % over 3000 fresh datasets (+-3 sd) plus the calibration's own error
    assert 0.025 <= fwer(par) <= 0.075, fwer(par)
    # the mutated fixture: white noise alone has no shared error, and the common-mode candidate
    # fits the input error as if it were an effect
    assert fwer(white) > 0.3, fwer(white)
    assert par.thresholds["common"] > 5 * white.thresholds["common"]


def test_parametric_without_an_input_model_is_the_white_null_draw_for_draw():
    cands, folds, _, _ = _toy()
    rng = np.random.default_rng(4)
    r = rng.normal(0, 0.8, (T_N, K))
    valid = rng.uniform(size=(T_N, K)) > 0.1  # drops
    a = calibrate(cands, r, valid, folds, draws=200, seed=7, method="parametric")
    b = calibrate(cands, r, valid, folds, draws=200, seed=7, method="white")
    assert a.thresholds == b.thresholds
    np.testing.assert_array_equal(a.null, b.null)
    assert "no input model" in a.method


def test_input_covariance_square_root_is_exact():
    cov = np.array([[2.0, 0.6, 0.0], [0.6, 1.0, 0.0], [0.0, 0.0, 0.0]])  # semi-definite
    j = np.zeros((T_N, K, 3))
    j_in, low = gate._input_chol(j, cov, (T_N, K))
    np.testing.assert_allclose(
        low @ np.swapaxes(low, 1, 2), np.broadcast_to(cov, (T_N, 3, 3)), atol=1e-12
    )
    _, low = gate._input_chol(j, None, (T_N, K))  # responses to 3 draws: I / 3
    np.testing.assert_allclose(low[0] @ low[0].T, np.eye(3) / 3, atol=1e-12)


def test_parametric_inputs_are_checked():
    cands, folds, j_in, _ = _toy()
    r = np.ones((T_N, K))
    valid = np.ones((T_N, K), bool)
    with pytest.raises(ValueError, match="method='parametric'"):
        calibrate(cands, r, valid, folds, method="white", inputs=j_in)
    with pytest.raises(ValueError, match=r"inputs must be \[T, K, M\]"):
        calibrate(cands, r, valid, folds, method="parametric", inputs=j_in[:, :5])
    with pytest.raises(ValueError, match="input_cov must be"):
        calibrate(cands, r, valid, folds, method="parametric", inputs=j_in, input_cov=np.eye(3))
    with pytest.raises(ValueError, match="semi-definite"):
        calibrate(cands, r, valid, folds, method="parametric", inputs=j_in, input_cov=-np.eye(2))


def _fake_rec(s_true: float, seed: int = 0):
    """Two straight pusher paths at 250 Hz with white noise ``s_true`` per axis."""
    rng = np.random.default_rng(seed)
    trs = []
    for i in range(2):
        t = np.arange(0.0, 1.2, 1 / 250.0)
        pos = np.stack([0.3 * t, 0.1 * t * (i + 1), np.full_like(t, 0.05)], axis=-1)
        trs.append(
            SimpleNamespace(
                ee_t_ns=(np.round(t * 1e9) + i * 5e9).astype(np.int64),
                ee_pos=pos + rng.normal(0, s_true, pos.shape),
            )
        )
    return SimpleNamespace(trajectories=trs)


def test_drive_error_draws_are_the_smoother_on_the_paths_own_noise():
    from robogs.physics import drive_noise as dn
    from robogs.physics.smoothing import local_polynomial

    s_true = 1.2e-4
    rec = _fake_rec(s_true)
    t0 = np.array([int(tr.ee_t_ns[0]) for tr in rec.trajectories])
    dt, n_steps, n = 1e-3, 1300, 400
    dpos, dcar, info = dn.drive_error_draws(rec, t0, dt, n_steps, n, seed=3)
    assert abs(info["path_noise_m"] / s_true - 1) < 0.1  # the path's own noise, estimated
    s = info["path_noise_m"]
    te = (rec.trajectories[0].ee_t_ns - t0[0]) * 1e-9
    # closed form: the smoother is linear, so a smoothed sample's variance is s^2 ||l_k||^2
    # with l_k the smoother's weights (its response to each unit impulse)
    weights = local_polynomial(te, np.eye(len(te)), info["window_s"])  # [E, E]
    k = 150  # a path sample inside the trajectory, on the grid at step 600
    step = int(round(te[k] / dt))
    want = s * np.sqrt(np.sum(weights[k] ** 2))
    got = dpos[:, 0, step, :].std(axis=0)
    # 400 draws: the std's relative standard error is 1 / sqrt(800) = 3.5 %
    np.testing.assert_allclose(got, want, rtol=0.12)
    vel = local_polynomial(te, np.eye(len(te)), info["carry_window_s"], deriv=1)
    np.testing.assert_allclose(
        dcar[:, 0, step, :].std(axis=0), s * np.sqrt(np.sum(vel[k] ** 2)), rtol=0.12
    )
    # a path twice as noisy gives draws twice as large (same seed: the same unit draws)
    d2, _, _ = dn.drive_error_draws(_fake_rec(2 * s_true), t0, dt, n_steps, n, seed=3)
    ratio = np.linalg.norm(d2) / np.linalg.norm(dpos)
    assert abs(ratio - 2.0) < 0.2


def test_tiled_evaluation_is_the_one_by_one_evaluation():
    from dataclasses import replace

    import torch

    from robogs.physics import drive_noise as dn
    from robogs.physics.engine import Engine
    from robogs.physics.residuals import residual_fn
    from robogs.synth.scenarios.design_b import make_design_b

    torch.set_num_threads(1)
    rec = make_design_b("none", seed=0, trajectories=(0, 6))
    eng = Engine(rec, backend="planar")
    prep = eng.prep
    space = eng.space([])
    th = eng.start(space)
    lo = np.zeros((prep.n_traj, 3))
    dpos, dcar, _ = dn.drive_error_draws(
        prep.rec, prep.t0_ns, prep.drive.dt, int(prep.drive.pusher.shape[1]), 3, seed=0
    )

    def one_by_one(drives):
        out = []
        for d in drives:
            fn = residual_fn(replace(prep, drive=d), space)
            with torch.no_grad():
                out.append(fn(torch.as_tensor(th)[None], torch.as_tensor(lo)[None]).numpy()[0])
        return np.stack(out)

    tiled = dn.tiled_evaluator(prep, space, th, lo)
    a = dn.drive_response(tiled, prep.drive, dpos, dcar, batch=3)
    b = dn.drive_response(one_by_one, prep.drive, dpos, dcar)
    assert a.shape == (prep.n_traj, b.shape[1], 3)
    assert np.abs(b).max() > 1e-3  # the drive error moves the residual
    np.testing.assert_allclose(a, b, atol=1e-10)


def test_gate_method_from_the_environment(monkeypatch):
    from robogs.format.errors import InputError
    from robogs.physics.diagnose import GATE_METHOD_ENV, gate_method

    monkeypatch.delenv(GATE_METHOD_ENV, raising=False)
    assert gate_method() == "parametric"
    monkeypatch.setenv(GATE_METHOD_ENV, " ")
    assert gate_method() == "parametric"
    monkeypatch.setenv(GATE_METHOD_ENV, "both")
    assert gate_method() == "both"
    monkeypatch.setenv(GATE_METHOD_ENV, "bootstrap")
    with pytest.raises(InputError, match="unknown gate method"):
        gate_method()


def test_method_line_says_the_drive_path_noise_it_used(tmp_path, monkeypatch):
    """The calibration's method line (and the diagnosis report's ``gate.method``) gives the
    path noise the drive model drew: value, unit, how estimated, rate and windows."""
    from robogs.physics import drive_noise as dn

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    s_true = 1.2e-4
    rec = _fake_rec(s_true)
    t0 = np.array([int(tr.ee_t_ns[0]) for tr in rec.trajectories])
    _, _, info = dn.drive_error_draws(rec, t0, 1e-3, 1300, 2, seed=0)
    # the brute-force oracle: the noise put on the path; 1.4826 MAD of ~600 deviates a path
    assert abs(info["path_noise_m"] / s_true - 1) < 0.1
    note = dn.describe_path_noise(info)
    um = round(info["path_noise_m"] * 1e6)
    assert f"drive path noise {um} um per axis at 250 Hz" in note
    assert "MAD" in note and "second differences" in note
    cands, folds, j_in, cov = _toy()
    cols = j_in.view(dn.InputColumns)
    cols.note = note
    r = np.random.default_rng(2).normal(size=(T_N, K))
    valid = np.ones((T_N, K), bool)
    kw = dict(method="parametric", draws=100, seed=1, fingerprint="toy")
    cal = calibrate(cands, r, valid, folds, inputs=cols, input_cov=cov, **kw)
    assert cal.method.endswith(f"input-error directions per trajectory; {note})")
    assert note in cal.to_dict()["method"]
    again = calibrate(cands, r, valid, folds, inputs=cols, input_cov=cov, **kw)
    assert again.cached and again.method == cal.method  # the cache keeps the line
    # an explicit note wins over the columns' own; a plain array carries none
    other = calibrate(cands, r, valid, folds, inputs=cols, input_note="tool path 5 um", **kw)
    assert other.method.endswith("per trajectory; tool path 5 um)")
    plain = calibrate(cands, r, valid, folds, inputs=np.asarray(j_in), **kw)
    assert plain.method.endswith("input-error directions per trajectory)")
    with pytest.raises(ValueError, match="method='parametric'"):
        calibrate(cands, r, valid, folds, method="white", input_note=note)


def test_noise_free_path_is_not_a_silent_white_null(tmp_path, monkeypatch):
    """A noise-free EE path: zero drive error, no rollout, and the parametric null (white noise
    only) says so in its method line and warns, from the cache as well."""
    from robogs.physics import drive_noise as dn
    from robogs.physics.diagnose import sign_flip_floor

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    rec = _fake_rec(0.0)
    t0 = np.array([int(tr.ee_t_ns[0]) for tr in rec.trajectories])
    # no rollout may run: the engine's residual pieces are absent, so one would raise
    prep = SimpleNamespace(
        rec=rec, t0_ns=t0, drive=SimpleNamespace(dt=1e-3, pusher=np.zeros((2, 1300, 3)))
    )
    eng = SimpleNamespace(prep=prep, _mujoco=None)
    valid = np.ones((2, 40), bool)
    cols = dn.drive_inputs(eng, None, None, valid, "fp")
    assert isinstance(cols, dn.InputColumns) and cols.shape == (2, 40, dn.N_INPUT_DRAWS)
    assert not np.any(cols)
    assert "drive path noise 0 um" in cols.note and "noise-free" in cols.note
    cands, folds, _, _ = _toy()
    r = np.random.default_rng(5).normal(size=(T_N, K))
    zero = np.zeros((T_N, K, 4)).view(dn.InputColumns)
    zero.note = cols.note
    kw = dict(method="parametric", draws=100, seed=1, fingerprint="clean", inputs=zero)
    for cached in (False, True):
        with pytest.warns(gate.ParametricNullWarning, match="white noise only") as rec_w:
            cal = calibrate(cands, r, np.ones((T_N, K), bool), folds, **kw)
        assert cal.cached == cached
        assert "drive path noise 0 um" in str(rec_w[0].message)
        assert "white noise only: all 4 input-error columns are zero" in cal.method
        assert "noise-free" in cal.to_dict()["method"]
        # not mistaken for the few-trajectory white null, nor for a sign-flip null
        assert "white-noise null only" not in cal.method
        assert sign_flip_floor(cal.method, 6) is None

"""The gate's opt-in in-sample statistic (``gate.calibrate(insample=True)``, h94): every
candidate's in-sample chi^2 fall of the linear model, simulated on the parametric null's own
draws, with the single-step min-P over both statistics of every candidate.

Oracles: (1) brute force on fresh null datasets of the linear model (white noise plus a shared
input error of known covariance): the family-wise rate over all 2C statistics sits at 5 %
within its binomial band, while the mutation that leaves the in-sample statistics out of the
min-P (each at its own 95 % quantile) over-rejects; (2) a planted effect that one trajectory
carries (the others see it at 3 % of its size, so a fold that holds the carrier out hardly
determines it) is found by the in-sample statistic and mostly missed by the held-out one; (3) the held-out null is the default's draw
for draw and its thresholds are only raised; (4) the data's statistic is the smaller of the fit
gain and the linear model's closed-form gain.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_gate import _stats  # the held-out statistic of each candidate on draws [D, T, K]
from test_gate_parametric import T_N, K, _data, _toy

from robogs.physics import gate
from robogs.physics.gate import LinearCandidate, calibrate

SIGMA = 1.3


def _insample(cands, e):
    """The in-sample chi^2 fall of each candidate's linear model on draws ``e`` [D, T, K]
    (ordinary least squares refits, nuisance columns profiled out) [D, C]."""
    valid = np.ones(e.shape[1:], bool)
    out = []
    for c in cands:
        q = gate._profile(c.jac_local, valid)
        r_b, _ = gate._linear_heldout(c.jac[..., : c.n_base], q, e, [])
        r_c, _ = gate._linear_heldout(c.jac, q, e, [])
        out.append(np.sum(r_b**2, axis=(1, 2)) - np.sum(r_c**2, axis=(1, 2)))
    return np.stack(out, axis=1)


def _one_trajectory_shape():
    """The planted effect's shape [K] (a wavelet in the slide's second half)."""
    s = np.linspace(0, 1, K)
    return np.sin(9 * s) * np.exp(-(((s - 0.6) / 0.2) ** 2))


def _cands():
    """test_gate_parametric's candidates plus one that trajectory 0 carries (3 % elsewhere)."""
    cands, folds, j_in, cov = _toy()
    g = _one_trajectory_shape()
    col = np.tile(g, (T_N, 1)) * 0.03
    col[0] = g
    c0 = cands[0]
    one = LinearCandidate(
        "one", np.concatenate([c0.jac[..., : c0.n_base], col[..., None]], -1), c0.jac_local, 2
    )
    return [*cands, one], folds, j_in, cov


def _calibrate(cands, folds, j_in, cov, insample):
    base_resid = _data(j_in, cov, SIGMA, 1, np.random.default_rng(3))[0]  # sets the scale
    valid = np.ones((T_N, K), bool)
    return calibrate(
        cands,
        base_resid,
        valid,
        folds,
        method="parametric",
        inputs=j_in,
        input_cov=cov,
        draws=1000,
        seed=1,
        insample=insample,
    )


def test_family_wise_rate_over_both_statistics_is_five_percent(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, j_in, cov = _cands()
    cal = _calibrate(cands, folds, j_in, cov, insample=True)
    names = [c.name for c in cands]
    assert list(cal.insample) == names and cal.insample_null.shape == (cal.draws, len(names))
    e = _data(j_in, cov, SIGMA, 3000, np.random.default_rng(99))
    held, ins = _stats(cands, folds, e), _insample(cands, e)
    thr = np.array([cal.thresholds[n] for n in names])
    thr_in = np.array([cal.insample[n] for n in names])
    fwer = float(np.mean((held > thr).any(axis=1) | (ins > thr_in).any(axis=1)))
    # binomial band of 5 % over 3000 fresh datasets (+-3 sd) plus the calibration's own error
    assert 0.025 <= fwer <= 0.075, fwer
    # the mutation: the in-sample statistics left out of the min-P (each at its own 95 %
    # quantile) over-reject
    q95_in = np.array([cal.insample_q95[n] for n in names])
    naive = float(np.mean((held > thr).any(axis=1) | (ins > q95_in).any(axis=1)))
    assert naive > 0.075, naive


def test_one_trajectory_effect_is_found_in_sample_not_held_out(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, j_in, cov = _cands()
    cal = _calibrate(cands, folds, j_in, cov, insample=True)
    cal0 = _calibrate(cands, folds, j_in, cov, insample=False)
    g = _one_trajectory_shape()
    y = _data(j_in, cov, SIGMA, 200, np.random.default_rng(7))
    y[:, 0] += 60.0 * SIGMA * g / np.linalg.norm(g)  # z = 60 on trajectory 0, 1.8 elsewhere
    one = len(cands) - 1
    held, ins = _stats(cands, folds, y)[:, one], _insample(cands, y)[:, one]
    found_in = float(np.mean(ins > cal.insample["one"]))
    found_held = float(np.mean(held > cal.thresholds["one"]))
    found_default = float(np.mean(held > cal0.thresholds["one"]))
    # the folds that hold trajectory 0 out step the effect to a training estimate that 3 % of
    # its size elsewhere hardly determines: its held-out fall is mostly noise
    assert found_in >= 0.9, found_in
    assert found_held <= 0.6 and found_default <= 0.6, (found_held, found_default)


def test_held_out_null_is_the_default_draw_for_draw(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, j_in, cov = _cands()
    cal = _calibrate(cands, folds, j_in, cov, insample=True)
    cal0 = _calibrate(cands, folds, j_in, cov, insample=False)
    np.testing.assert_array_equal(cal.null, cal0.null)
    assert not cal0.insample and cal0.insample_null is None
    assert cal.alpha_adj <= cal0.alpha_adj
    assert all(cal.thresholds[n] >= cal0.thresholds[n] for n in cal0.thresholds)
    assert "insample" in cal.to_dict() and "insample" not in cal0.to_dict()


def test_insample_entries_are_cached_apart(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, j_in, cov = _cands()
    base_resid = _data(j_in, cov, SIGMA, 1, np.random.default_rng(3))[0]
    valid = np.ones((T_N, K), bool)
    kw = dict(method="parametric", inputs=j_in, input_cov=cov, draws=200, seed=1)
    a = calibrate(cands, base_resid, valid, folds, fingerprint="fp", insample=True, **kw)
    b = calibrate(cands, base_resid, valid, folds, fingerprint="fp", insample=True, **kw)
    c = calibrate(cands, base_resid, valid, folds, fingerprint="fp", **kw)
    assert b.cached and b.insample == a.insample and b.thresholds == a.thresholds
    assert not c.cached and c.key != a.key and not c.insample
    s = 1.0e3
    _, _, p = b.judge_insample("one", s)
    assert np.isnan(p)  # no null kept in a cached entry
    thr, _, p = a.judge_insample("one", s)
    assert thr == a.insample["one"] and 0.0 < p <= 1.0


def test_data_statistic_is_the_smaller_of_fit_and_linear_gain():
    cands, folds, j_in, cov = _cands()
    y = _data(j_in, cov, SIGMA, 1, np.random.default_rng(11))[0]
    valid = np.ones((T_N, K), bool)
    for c, lin in zip(cands, _insample(cands, y[None])[0], strict=True):
        assert gate.insample_statistic(c, y, valid, np.inf) == pytest.approx(lin, rel=1e-9)
        assert gate.insample_statistic(c, y, valid, lin - 1.0) == pytest.approx(lin - 1.0)


def test_insample_needs_the_parametric_held_out_fall():
    cands, folds, j_in, _ = _cands()
    r = np.ones((T_N, K))
    valid = np.ones((T_N, K), bool)
    with pytest.raises(ValueError, match="insample=True needs"):
        calibrate(cands, r, valid, folds, method="white", insample=True)
    with pytest.raises(ValueError, match="insample=True needs"):
        calibrate(
            cands, r, valid, folds, method="parametric", inputs=j_in, statistic="t", insample=True
        )


def test_insample_from_the_environment(monkeypatch):
    from robogs.format.errors import InputError
    from robogs.physics.diagnose import GATE_INSAMPLE_ENV, gate_insample

    monkeypatch.delenv(GATE_INSAMPLE_ENV, raising=False)
    assert not gate_insample("parametric") and not gate_insample("both")
    monkeypatch.setenv(GATE_INSAMPLE_ENV, "1")
    assert gate_insample("parametric")
    with pytest.raises(InputError, match="parametric null"):
        gate_insample("both")
    monkeypatch.setenv(GATE_INSAMPLE_ENV, "maybe")
    with pytest.raises(InputError, match="unknown value"):
        gate_insample("parametric")

"""Design B's detectability against white plus drive-path noise (issue 17, h100).

Oracles: closed forms of the scaled chi^2 (no drive noise: the white chi^2_k power; drive noise
``c I``: a chi^2 scaled by ``1 + c``), a drive response planted in the nuisance columns (profiled
out exactly) plus a known part along the effect (kept exactly), and the generator's own noisy
recordings: the path noise ``make_design_b`` writes is the one modelled, and fresh noisy
simulations of it spread along the effect as the drive covariance says.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2, ncx2, norm

from robogs.synth.scenarios import design_b as db
from robogs.synth.scenarios.generate import _sample

LEVEL = db.ALPHA_FAMILY / db.N_CANDIDATES


def test_without_drive_noise_the_power_is_the_white_chi2_power():
    for k, lam in ((1, 9.0), (1, 29.3), (2, 20.0), (3, 25.0), (2, 0.0)):
        power, crit = db.design_power_full(lam, k, LEVEL, np.zeros((k, k)))
        assert power == pytest.approx(db.design_power(lam, k, LEVEL), abs=1e-9)
        assert crit == pytest.approx(chi2.isf(LEVEL, k), rel=1e-9)


def test_isotropic_drive_noise_scales_the_chi2():
    """``e ~ N(0, (1 + c) I_k)``: the null is ``(1 + c) chi^2_k``, the statistic over ``1 + c``
    a ``chi^2_k(lambda / (1 + c))``; k = 1 in closed form with the normal distribution."""
    c = 6.9
    lam = 29.3
    z = norm.isf(LEVEL / 2)
    r = np.sqrt(lam / (1 + c))
    closed = norm.cdf(r - z) + norm.cdf(-r - z)
    power, crit = db.design_power_full(lam, 1, LEVEL, np.array([[c]]))
    assert crit == pytest.approx((1 + c) * chi2.isf(LEVEL, 1), rel=1e-9)
    assert power == pytest.approx(closed, abs=1e-9)
    power2, crit2 = db.design_power_full(lam, 2, LEVEL, c * np.eye(2))
    assert crit2 == pytest.approx((1 + c) * chi2.isf(LEVEL, 2), rel=1e-9)
    assert power2 == pytest.approx(ncx2.sf(chi2.isf(LEVEL, 2), 2, lam / (1 + c)), abs=1e-9)
    power3 = db.design_power_full(lam, 3, LEVEL, c * np.eye(3))[0]
    assert power3 == pytest.approx(ncx2.sf(chi2.isf(LEVEL, 3), 3, lam / (1 + c)), abs=1e-9)


def test_anisotropic_drive_noise_against_brute_force():
    """Correlated drive noise, k = 2 and 3: the null quantile and the power against Monte Carlo
    of the linear model (10^6 draws; quantile within 2 %, power within 5 binomial SE)."""
    rng = np.random.default_rng(0)
    for lam, cov in (
        (40.0, np.array([[6.0, 1.5], [1.5, 0.5]])),
        (157.3, np.array([[8.3, 0.67], [0.67, 6.96]])),
        (60.0, np.diag([20.0, 0.0, 3.0])),
    ):
        k = len(cov)
        power, crit = db.design_power_full(lam, k, LEVEL, cov)
        e = rng.standard_normal((1_000_000, k)) @ np.linalg.cholesky(np.eye(k) + cov).T
        null = np.sum(e**2, axis=1)
        assert crit == pytest.approx(np.quantile(null, 1 - LEVEL), rel=0.02)
        e[:, 0] += np.sqrt(lam)
        brute = np.mean(np.sum(e**2, axis=1) > crit)
        assert power == pytest.approx(brute, abs=5 * np.sqrt(brute * (1 - brute) / 1e6) + 1e-4)
        assert crit > chi2.isf(LEVEL, k) and power < db.design_power(lam, k, LEVEL)


def test_consumer_smoother_keeps_quartics_and_passes_white_noise_as_its_weights_say():
    """A local degree-4 fit reproduces any quartic and its derivative exactly (ends included);
    on white noise each output's variance is its row's squared norm (brute force, 4000 draws)."""
    n, period = 120, 1 / db.ENCODER_HZ_B
    t = np.arange(n) * period
    x = 0.01 + 0.3 * t - 2.0 * t**2 + 5.0 * t**3 - 7.0 * t**4
    dx = 0.3 - 4.0 * t + 15.0 * t**2 - 28.0 * t**3
    pos = db._local_poly_operator(n, period, db.DRIVE_WINDOWS_B[0])
    vel = db._local_poly_operator(n, period, db.DRIVE_WINDOWS_B[1], deriv=1)
    np.testing.assert_allclose(pos @ x, x, atol=1e-12)
    np.testing.assert_allclose(vel @ x, dx, atol=1e-8)
    w = np.random.default_rng(0).standard_normal((n, 4000))
    np.testing.assert_allclose(np.var(pos @ w, axis=1), np.sum(pos**2, axis=1), rtol=0.1)
    assert np.sum(pos[60] ** 2) < 0.5  # the interior row passes under half the white variance


def _unwhiten(w: np.ndarray, sig: np.ndarray, sig_y: np.ndarray) -> np.ndarray:
    """Whitened residual vectors [M, T, 4 N_t] back to observation changes [M, T, N_t, 4]."""
    m, n_t = w.shape[:2]
    n = sig.shape[1]
    p = w[..., : 3 * n].reshape(m, n_t, n, 3) * sig
    y = w[..., 3 * n :] * sig_y
    return np.concatenate([p, y[..., None]], axis=-1)


@pytest.mark.slow
def test_drive_noise_in_nuisance_columns_is_profiled_out(monkeypatch):
    """A drive response made of the plain fit's own nuisance columns (friction, start poses)
    plus ``b u`` (``u`` the profiled effect direction) leaves exactly ``keep E[b^2]`` along the
    effect; with ``b = 0`` the power is the white chi^2 power."""
    eff = "viscous_damping"
    fit = db._profile(eff, False, None)
    sub = db._effect_subspace(eff, False, None)
    u = sub["q"][:, 0]
    rng = np.random.default_rng(1)
    m = 40
    n_t = fit["resid"].shape[0]
    coef = rng.normal(0.0, 5.0, (fit["jac"].shape[1], m))
    nuis = (fit["jac"] @ coef).T  # [M, T N]: large, all in the nuisance columns
    keep = 1.0 - db.NOISE_B["drop"]
    for b in (np.zeros(m), rng.normal(0.0, 2.0, m)):
        w = (nuis + b[:, None] * u[None]).reshape(m, n_t, -1)
        resp = _unwhiten(w, fit["sig"], fit["sig_y"])
        monkeypatch.setattr(db, "_drive_response", lambda qs=False, subset=None, r=resp: r)
        got = db._effect_subspace.__wrapped__(eff, False, None)["drive_cov"]
        assert got[0, 0] == pytest.approx(keep * np.mean(b**2), abs=1e-6 * np.mean(nuis**2))
    lam = db.profiled_chi2(eff)
    zero = db.design_power_full(lam, 1, LEVEL, np.zeros((1, 1)))[0]
    assert zero == pytest.approx(db.design_power(lam, 1, LEVEL), abs=4e-3)


@pytest.mark.slow
def test_modelled_drive_noise_is_what_the_recordings_carry():
    """The path noise ``make_design_b`` writes (EE positions minus the commanded path at the
    encoder stamps) is white with the modelled deviation; the encoder stamps are the modelled
    ones; the EE yaw carries no noise."""
    motions = db._motions(db.BOX_B, False)
    path = db._path(motions)
    _, _, enc_t = db._drive_operators(path.pos.shape[1])
    noise = []
    for seed in (0, 1):
        rec = db.make_design_b("none", seed=seed)
        for i, tr in enumerate(rec.trajectories):
            te = (tr.ee_t_ns - tr.ee_t_ns[0]) * 1e-9
            np.testing.assert_allclose(te, enc_t, atol=1e-9)
            noise.append(tr.ee_pos - _sample(path.pos[i], enc_t))
            yaw = 2 * np.arctan2(tr.ee_quat[:, 3], tr.ee_quat[:, 0])
            dyaw = np.angle(np.exp(1j * (yaw - _sample(path.yaw[i], enc_t))))
            np.testing.assert_allclose(dyaw, 0.0, atol=1e-9)
    e = np.concatenate(noise)
    assert np.std(e) == pytest.approx(db.DRIVE_NOISE_B, rel=0.02)  # 25 000 samples: 0.45 % SE
    lag1 = np.mean(e[1:] * e[:-1]) / np.var(e)
    assert abs(lag1) < 0.03


@pytest.mark.slow
def test_drive_covariance_against_fresh_noisy_simulations():
    """Brute force: fresh noisy drives through the generator's simulator (another seed than the
    covariance's draws) project onto the viscous damping's direction with a variance that the
    drive covariance predicts (ratio within a chi^2_24 interval: 0.33-2.1 at 99.9 %), and the
    response is linear enough: ``-n`` gives minus the response of ``n`` (correlation < -0.9)."""
    eff = "viscous_damping"
    fit = db._profile(eff, False, None)
    u = db._effect_subspace(eff, False, None)["q"][:, 0]
    pred = db.detectability(eff)["drive_variance"]
    motions = db._motions(db.BOX_B, False)
    n_t = len(motions)
    n_fine = db._path(motions).pos.shape[1]
    _, _, enc_t = db._drive_operators(n_fine)
    m = 24
    n = np.random.default_rng(123).normal(0.0, db.DRIVE_NOISE_B, (m, n_t, len(enc_t), 3))
    noise = np.concatenate([np.zeros((1, *n.shape[1:])), n, -n])
    p, y = db._simulate(
        "none",
        False,
        None,
        None,
        np.zeros((len(noise), n_t, 3)),
        drive=db._consumer_drives(False, None, noise),
    )
    t = fit["t"]
    obs = np.stack(
        [
            np.concatenate(
                [
                    np.stack([_sample(p[j, i], t) for i in range(n_t)]),
                    np.stack([_sample(y[j, i], t) for i in range(n_t)])[..., None],
                ],
                axis=-1,
            )
            for j in range(len(noise))
        ]
    )
    w = db._whiten(obs[1:] - obs[0], fit["sig"], fit["sig_y"]).reshape(2 * m, -1)
    proj = w @ u
    keep = 1.0 - db.NOISE_B["drop"]
    ratio = keep * np.mean(proj[:m] ** 2) / pred
    corr = np.corrcoef(proj[:m], proj[m:])[0, 1]
    print(f"fresh / modelled drive variance {ratio:.3f}, corr(+n, -n) {corr:.3f}")
    assert 0.33 < ratio < 2.1, ratio
    assert corr < -0.9

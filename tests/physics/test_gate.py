"""The object model's gate from the data (robogs.physics.gate), on linear problems.

Oracles: (1) the family-wise false-positive rate, measured by brute force on fresh null data
(independent draws, another seed) pushed through the same held-out procedure, must sit at the
nominal 5 % within its binomial band, for candidates of very different sizes; (2) the noise
scale of white noise under a smooth misfit is known; (3) a planted effect must pass; (4) the
cache returns the same thresholds and is keyed by the candidate list.
"""

from __future__ import annotations

import numpy as np
import pytest

from robogs.physics import gate
from robogs.physics.gate import LinearCandidate, calibrate, diff_scale


def _problem(seed: int = 0, t_n: int = 7, k: int = 160):
    """Base: 2 global columns + 3 nuisance columns per trajectory; candidates add 1-3 columns."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, k)
    base = np.stack([np.tile(s, (t_n, 1)), np.tile(s**2, (t_n, 1))], axis=-1)
    loc = np.stack([np.ones((t_n, k)), np.tile(s, (t_n, 1)), np.tile(np.cos(3 * s), (t_n, 1))], -1)
    extra = {
        "one": rng.normal(size=(t_n, k, 1)) * np.exp(-5 * s)[None, :, None],
        "two": np.stack([np.sin(7 * s + t) for t in range(t_n)])[..., None]
        * np.array([1.0, 0.3])[None, None, :],
        "three": rng.normal(size=(t_n, k, 3)),
    }
    extra["two"][..., 1] += rng.normal(size=(t_n, k)) * 0.2
    cands = [
        LinearCandidate(n, np.concatenate([base, e], axis=-1), loc, base.shape[-1])
        for n, e in extra.items()
    ]
    folds = [np.arange(t_n) % 5 == f for f in range(5)]
    return cands, folds, t_n, k


def _stats(cands, folds, e):
    """The held-out statistic of each candidate on noise draws ``e`` [D, T, K]."""
    valid = np.ones(e.shape[1:], bool)
    out = []
    for c in cands:
        q = gate._profile(c.jac_local, valid)
        r_b, h_b = gate._linear_heldout(c.jac[..., : c.n_base], q, e, folds)
        r_c, h_c = gate._linear_heldout(c.jac, q, e, folds)
        out.append(gate.heldout_statistic(h_b, h_c, r_b - r_c))
    return np.stack(out, axis=1)


def test_family_wise_rate_is_five_percent_on_fresh_null_data(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, t_n, k = _problem()
    sigma = 1.7  # the dataset's noise scale, recovered from the base residual
    rng = np.random.default_rng(5)
    base_resid = rng.normal(0, sigma, (t_n, k))
    cal = calibrate(
        cands, base_resid, np.ones((t_n, k), bool), folds, draws=1000, seed=1, method="white"
    )
    assert cal.alpha_adj < 0.05  # three candidates: each is tested below 5 %
    thr = np.array([cal.thresholds[c.name] for c in cands])
    # brute force: 3000 fresh null datasets at the true scale
    e = np.random.default_rng(99).normal(0, sigma, (3000, t_n, k))
    st = _stats(cands, folds, e)
    fwer = float(np.mean((st > thr).any(axis=1)))
    # binomial band of a 5 % rate over 3000 draws (+-3 sd) plus the calibration's own error
    assert 0.025 <= fwer <= 0.075, fwer
    # per-candidate levels are alike: the many-parameter candidate does not take the whole 5 %
    each = (st > thr).mean(axis=0)
    assert each.max() < 3 * max(each.min(), 1e-3)


def _fit_resids(cands, folds, y):
    """Base and per-candidate full-fit residuals of one dataset ``y`` [T, K]."""
    valid = np.ones(y.shape, bool)
    q = gate._profile(cands[0].jac_local, valid)
    r_b, _ = gate._linear_heldout(cands[0].jac[..., : cands[0].n_base], q, y[None], folds)
    out = []
    for c in cands:
        r_c, _ = gate._linear_heldout(c.jac, q, y[None], folds)
        out.append(LinearCandidate(c.name, c.jac, c.jac_local, c.n_base))
    return r_b[0], out


def _held(cands, folds, y):
    """Per candidate: base and effect held-out chi^2 per trajectory and the change [T, K]."""
    valid = np.ones(y.shape, bool)
    out = []
    for c in cands:
        q = gate._profile(c.jac_local, valid)
        r_b, h_b = gate._linear_heldout(c.jac[..., : c.n_base], q, y[None], folds)
        r_c, h_c = gate._linear_heldout(c.jac, q, y[None], folds)
        out.append((h_b[0], h_c[0], (r_b - r_c)[0]))
    return out


VARIANTS = {
    "both": {},  # the default
    "white": {"method": "white"},
    "wild": {"method": "wild"},  # Webb's weights under 8 trajectories, the fall not studentised
    "t": {"statistic": "t"},  # studentised, white and wild nulls
}


def _hits(
    t_n: int,
    seed: int,
    n_sets: int = 120,
    variants: tuple[str, ...] = ("both", "white"),
    amp: float = 0.0,
    draws: int = 200,
) -> dict[str, tuple[float, float]]:
    """Share of ``n_sets`` fresh datasets on which any candidate passes, and on which candidate
    ``one`` passes, per gate variant (:data:`VARIANTS`). Each trajectory carries its own smooth
    error; ``amp`` plants the effect ``one`` at that multiple of its unit size (0: null)."""
    cands, folds, t_n, k = _problem(t_n=t_n)
    s = np.linspace(0, 1, k)
    shape = np.sin(9 * s) * s  # in no base or nuisance column
    rng = np.random.default_rng(seed)
    hits = {m: [0, 0] for m in variants}
    for i in range(n_sets):
        y = rng.normal(size=(t_n, k)) + rng.normal(0, 4.0, (t_n, 1)) * shape[None]
        y = y + amp * cands[0].jac[..., -1]
        r_b, lin = _fit_resids(cands, folds, y)
        obs = _held(cands, folds, y)
        for m in hits:
            cal = calibrate(
                lin, r_b, np.ones((t_n, k), bool), folds, draws=draws, seed=i, **VARIANTS[m]
            )
            ok = [
                gate.heldout_statistic(*o) > cal.judge(c.name, *o)[0]
                for c, o in zip(cands, obs, strict=True)
            ]
            hits[m][0] += bool(any(ok))
            hits[m][1] += bool(ok[0])
    return {m: (h[0] / n_sets, h[1] / n_sets) for m, h in hits.items()}


def _null_hits(t_n: int, seed: int, **kw) -> dict[str, float]:
    """Family-wise false-positive share per variant over fresh null datasets (:func:`_hits`)."""
    return {m: h[0] for m, h in _hits(t_n, seed, **kw).items()}


def test_wild_null_holds_under_trajectory_level_errors_where_white_noise_fails(
    tmp_path, monkeypatch
):
    """Null data whose trajectories each carry their own smooth error (a release speed off by
    encoder noise): the white-noise null lets candidates through far above 5 %, the gate's
    default (white and wild cluster bootstrap) keeps near the nominal rate. Brute force over
    120 fresh datasets."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    hits = _null_hits(t_n=9, seed=11)
    assert hits["both"] <= 0.10, hits
    assert hits["white"] >= 0.2, hits


def test_five_trajectories_studentised_null_keeps_its_size_and_finds_a_planted_effect(
    tmp_path, monkeypatch
):
    """Five trajectories (16 sign patterns cannot reach a 5 % family-wise level; Webb's
    six-point weights can). Brute force under trajectory-level errors (as above): over 120
    fresh null datasets the white-noise null lets candidates through far above 5 %; the
    studentised held-out fall (``statistic="t"``, nulls from white noise and Webb's weights)
    keeps near the nominal rate. Over 30 datasets with the effect ``one`` planted at 4x its unit
    size (about 13 sigma per trajectory, as large as each trajectory's own error) ``t`` finds it
    in >= 90 %, Webb's null of the unstudentised fall in far fewer (the base residuals carry
    the effect). The default under 8 trajectories stays the white-noise null with strong
    in-sample evidence (the diagnosis's ``DBIC_MAX``): ``t`` loses a hidden tilt whose
    contributions differ between push directions (bench/RESULTS.md, issue 17, h21)."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    w, note = gate.wild_weights(5, 400, np.random.default_rng(0))
    assert "Webb" in note and w.shape == (400, 5)
    assert np.mean(w) == pytest.approx(0.0, abs=0.05) and np.mean(w**2) == pytest.approx(1, 0.05)
    hits = _null_hits(t_n=5, seed=12, variants=("t", "white"))
    assert hits["t"] <= 0.10, hits
    assert hits["white"] >= 0.2, hits
    found = _hits(t_n=5, seed=13, n_sets=30, variants=("t", "wild"), amp=4.0)
    assert found["t"][1] >= 0.9, found
    assert found["wild"][1] <= found["t"][1] - 0.3, found
    # the default: white noise only, and an effect planted at 8x its unit size passes it
    cands, folds, t_n, k = _problem(t_n=5)
    y = np.random.default_rng(4).normal(size=(t_n, k)) + 8.0 * cands[0].jac[..., -1]
    r_b, lin = _fit_resids(cands, folds, y)
    cal = calibrate(lin, r_b, np.ones((t_n, k), bool), folds, draws=400)
    assert "white-noise null only" in cal.method and cal.statistic == "fall"
    st = _stats(cands, folds, y[None])[0]
    assert st[0] > cal.thresholds["one"], (st, cal.thresholds)


def test_studentised_statistic_and_its_thresholds_in_sigma2():
    """``S`` and ``se`` against the sample formula; one trajectory acted on gives ``t = 1``;
    a studentised calibration's threshold in sigma^2 decides exactly as its ``t`` threshold."""
    hb = np.array([[10.0, 12.0, 9.0, 5.0], [3.0, 1.0, 2.0, 8.0]])
    hc = np.array([[4.0, 5.0, 6.0, 5.0], [1.0, 2.0, 2.5, 0.0]])
    delta = np.zeros((2, 4, 3))
    delta[0, :3, 0] = 5.0  # trajectory 3 not acted on (||delta_t|| < AFFECTED_Z)
    delta[1, 1, 2] = 4.0  # one trajectory acted on
    s, se = gate.studentised_statistic(hb, hc, delta)
    g = np.array([6.0, 7.0, 3.0])
    assert s[0] == pytest.approx(16.0)
    assert se[0] == pytest.approx(np.sqrt(3 * np.var(g, ddof=1)))
    assert s[1] == pytest.approx(-1.0) and s[1] / se[1] == pytest.approx(-1.0)
    null = np.linspace(-3, 6, 200)[:, None]
    cal = gate.Calibration({"x": 2.5}, {"x": 1.5}, 0.05, 0.05, 200, 0.0, 0.0, null=null)
    cal.statistic = "t"
    for h_eff in (hc[0], hc[0] + np.array([0.0, 9.0, 0.0, 0.0])):  # t = 4.4, then 1.0
        thr, q95, p = cal.judge("x", hb[0], h_eff, delta[0])
        s_x, se_x = gate.studentised_statistic(hb[0], h_eff, delta[0])
        assert thr == pytest.approx(2.5 * se_x) and q95 == pytest.approx(1.5 * se_x)
        assert (s_x > thr) == (s_x / se_x > 2.5)
        assert p == pytest.approx((1 + np.sum(null >= s_x / se_x)) / 201)
    assert cal.to_dict()["thresholds_sigma2"] == {"x": thr}
    # the held-out gain's divisor: the base held-out chi^2 of the trajectories acted on
    s_g, d_g = gate.normaliser(hb[0], hc[0], delta[0], "gain")
    assert s_g == pytest.approx(16.0) and d_g == pytest.approx(31.0)
    # the noise se: 2 sqrt(sum s_t^2 ||delta_t||^2) over the trajectories acted on
    sc = np.array([1.0, 2.0, 0.5, 3.0])
    s_n, d_n = gate.normaliser(hb[0], hc[0], delta[0], "tn", sc)
    assert s_n == pytest.approx(16.0) and d_n == pytest.approx(2 * np.sqrt(25 * (1 + 4 + 0.25)))
    for kind in ("t", "gain", "tn"):  # unchanged when the data are scaled by 2
        s1, d1 = gate.normaliser(hb, hc, delta, kind, sc)
        s2, d2 = gate.normaliser(4 * hb, 4 * hc, 2 * delta, kind, 2 * sc)
        np.testing.assert_allclose(s1 / d1, s2 / d2)


def test_planted_effect_passes_and_scale_is_read_from_the_data(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, t_n, k = _problem()
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 1.0, (t_n, k))
    cal = calibrate(cands, noise, np.ones((t_n, k), bool), folds, draws=400)
    one = cands[0]
    signal = 6.0 * one.jac[..., -1]  # the effect "one" at 6x its unit size
    st = _stats(cands, folds, (noise + signal)[None])[0]
    assert st[0] > cal.thresholds["one"]
    assert st[2] < st[0]


def test_difference_scale_ignores_a_smooth_misfit():
    rng = np.random.default_rng(0)
    k = 4 * 200
    t = np.repeat(np.linspace(0, 1, 200), 4)
    r = 2.5 * rng.normal(size=(3, k)) + 40 * np.sin(2 * np.pi * t)[None]  # misfit >> noise
    valid = rng.uniform(size=(3, k)) > 0.1  # dropped samples
    s = diff_scale(r, valid)
    assert s == pytest.approx(2.5, rel=0.12)


def test_cache_round_trip_keyed_by_candidates(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cands, folds, t_n, k = _problem()
    r = np.random.default_rng(1).normal(size=(t_n, k))
    v = np.ones((t_n, k), bool)
    a = calibrate(cands, r, v, folds, fingerprint="rev1", draws=200)
    b = calibrate(cands, r, v, folds, fingerprint="rev1", draws=200)
    assert not a.cached and b.cached and a.key == b.key
    assert b.thresholds == pytest.approx(a.thresholds)
    c = calibrate(cands[:2], r, v, folds, fingerprint="rev1", draws=200)
    assert not c.cached and c.key != a.key
    d = calibrate(cands, r, v, folds, fingerprint="rev2", draws=200)
    assert not d.cached
    assert len(list((tmp_path / "null").glob("*.json"))) == 3


def _clustered(t_n: int = 9, k: int = 120):
    """Candidates acted on by 1, 5 and all 9 trajectories (an effect carried by few trajectories,
    like viscous damping or camera extrinsics on design B), 2 base columns and 3 nuisance
    columns per trajectory."""
    s = np.linspace(0, 1, k)
    base = np.stack([np.tile(s, (t_n, 1)), np.tile(s**2, (t_n, 1))], -1)
    loc = np.stack([np.ones((t_n, k)), np.tile(s, (t_n, 1)), np.tile(np.cos(3 * s), (t_n, 1))], -1)
    extra = {"one": (23, 1), "five": (17, 5), "all": (13, t_n)}
    cands = [
        LinearCandidate(
            n,
            np.concatenate(
                [base, (np.sin(f * s + 0.3)[None] * (np.arange(t_n) < m)[:, None])[..., None]], -1
            ),
            loc,
            2,
        )
        for n, (f, m) in extra.items()
    ]
    folds = [np.arange(t_n) % 5 == f for f in range(5)]
    return cands, folds, s


def _cluster_hits(freqs, n_sets: int, seed: int, variants: dict, amp: float = 0.0):
    """Share of ``n_sets`` fresh datasets on which any candidate passes and on which ``five``
    passes, per gate variant. Each trajectory carries its own error, a random mix (3 sigma per
    shape) of the smooth shapes ``sin(f s + ph)`` in ``freqs``; ``amp`` plants ``five``."""
    cands, folds, s = _clustered()
    t_n, k = 9, s.size
    shapes = np.stack([np.sin(f * s + ph) for f, ph in freqs])
    rng = np.random.default_rng(seed)
    hits = {v: [0, 0] for v in variants}
    for i in range(n_sets):
        y = rng.normal(size=(t_n, k)) + 3.0 * rng.normal(size=(t_n, len(freqs))) @ shapes
        y = y + amp * cands[1].jac[..., 2]
        obs = _held(cands, folds, y)
        r_b = _fit_resids(cands, folds, y)[0]
        for v, kw in variants.items():
            cal = calibrate(cands, r_b, np.ones((t_n, k), bool), folds, draws=200, seed=i, **kw)
            ok = [
                gate.heldout_statistic(*o) > cal.judge(c.name, *o)[0]
                for c, o in zip(cands, obs, strict=True)
            ]
            hits[v][0] += bool(any(ok))
            hits[v][1] += bool(ok[1])
    return {v: (h[0] / n_sets, h[1] / n_sets) for v, h in hits.items()}


WCU_T = {"method": "wcu", "statistic": "t"}


def test_unrestricted_wild_null_studentised_keeps_its_size_and_passes_a_five_of_nine_effect(
    tmp_path, monkeypatch
):
    """``method="wcu"`` (each candidate's own residual, sign per trajectory; MacKinnon & Webb
    2017) with the studentised fall. Size, brute force over 100 fresh null datasets whose
    trajectories carry errors along the candidates' own shapes (the hardest case for a null
    without the effect): the family-wise rate is within the binomial band of 5 %, while the
    unstudentised fall on the same null (the mutation) lets the one-trajectory candidate
    through far more often. Power: an effect carried by 5 of 9 trajectories (6x its unit size)
    ties the default (restricted) null's top sign patterns (p >= 2^-4, above the level of about
    0.02 of three candidates) and passes it at most by chance; the studentised unrestricted
    null passes it on >= 90 % of 20 datasets."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    adversarial = ((17, 0.3), (13, 0.3), (23, 0.3), (9, 2.0), (4, 2.5))
    size = _cluster_hits(adversarial, 100, 7, {"wcu_t": WCU_T, "wcu": {"method": "wcu"}})
    assert size["wcu_t"][0] <= 0.10, size  # 5 % + 2.3 binomial sd over 100 sets
    assert size["wcu"][0] >= 0.3, size
    smooth = ((7, 1.0), (9, 2.0), (11, 0.5), (3, 2.5))
    power = _cluster_hits(smooth, 20, 8, {"both": {}, "wcu_t": WCU_T}, amp=6.0)
    assert power["wcu_t"][1] >= 0.9, power
    assert power["both"][1] <= power["wcu_t"][1] - 0.3, power


def test_unrestricted_residual_holds_none_of_the_effect():
    """The WCU residual is the candidate's fit residual: orthogonal to its columns and each
    trajectory's nuisance columns, and equal to the base residual where the effect is absent."""
    cands, folds, s = _clustered()
    rng = np.random.default_rng(2)
    y = rng.normal(size=(9, s.size)) + 5.0 * cands[1].jac[..., 2]
    r_b = _fit_resids(cands, folds, y)[0]
    v = np.ones(y.shape, bool)
    u = gate.unrestricted_resid(cands[1], r_b, v)
    assert abs(np.sum(u * cands[1].jac[..., 2])) < 1e-8 * np.sum(r_b * cands[1].jac[..., 2])
    assert np.abs(np.einsum("tk,tkl->tl", u, cands[1].jac_local)).max() < 1e-8
    # oracle: one dense least-squares fit of every global and nuisance column at once
    t_n, k = y.shape
    a = np.zeros((t_n * k, 3 + 3 * t_n))
    a[:, :3] = cands[1].jac.reshape(t_n * k, 3)
    for t in range(t_n):
        a[t * k : (t + 1) * k, 3 + 3 * t : 6 + 3 * t] = cands[1].jac_local[t]
    x = np.linalg.lstsq(a, r_b.reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(u.reshape(-1), r_b.reshape(-1) - a @ x, atol=1e-8)
    assert np.sum(u**2) < 0.5 * np.sum(r_b**2)  # the planted effect was in r_b, not in u
    with pytest.raises(ValueError, match="method"):
        calibrate(cands, r_b, v, folds, method="nope")


def test_sign_flip_needs_against_the_gate_null_by_enumeration(tmp_path, monkeypatch):
    """A one-parameter effect carried by ``m`` of 9 trajectories, orthogonal to the base and
    nuisance columns, in noise-free data: the gate's restricted wild null (all 256 sign
    patterns) ties ``2^(9-m)`` patterns with the data's statistic, and the ``1 - a`` quantile
    lies below the tie exactly when ``m >= sign_flip_needs(9, a)`` (design B's restated rule)."""
    from robogs.synth.scenarios.design_b import sign_flip_needs

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    t_n, k = 9, 60
    s = np.linspace(0, 1, k)
    base = np.stack([np.tile(s, (t_n, 1)), np.tile(s**2, (t_n, 1))], -1)
    loc = np.ones((t_n, k, 1))
    shape = np.sin(11 * s)
    q = np.linalg.qr(np.stack([np.ones(k), s, s**2], 1))[0]
    shape = shape - q @ (q.T @ shape)  # orthogonal to every base and nuisance column
    folds = [np.arange(t_n) % 5 == f for f in range(5)]
    assert sign_flip_needs(9, 0.005) == sign_flip_needs(9, 0.0075) == 8
    for m in range(1, t_n + 1):
        col = shape[None] * (np.arange(t_n) < m)[:, None] * np.linspace(1, 2, t_n)[:, None]
        c = LinearCandidate("x", np.concatenate([base, col[..., None]], -1), loc, 2)
        y = 3.0 * col
        cal = calibrate([c], y, np.ones((t_n, k), bool), folds, method="wild", draws=256)
        stat = float(_stats([c], folds, y[None])[0, 0])
        assert cal.null.shape[0] == 256
        for a in (0.005, 0.0075, 0.02):
            passes = stat > float(np.quantile(cal.null[:, 0], 1.0 - a)) * (1 + 1e-9)
            assert passes == (m >= sign_flip_needs(9, a)), (m, a)

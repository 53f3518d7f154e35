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


def _null_hits(
    t_n: int, seed: int, n_sets: int = 120, methods: tuple[str, ...] = ("both", "white")
) -> dict[str, float]:
    """Family-wise false-positive share of the gate (``both``) and of white noise alone over
    ``n_sets`` fresh null datasets whose trajectories each carry their own smooth error."""
    cands, folds, t_n, k = _problem(t_n=t_n)
    s = np.linspace(0, 1, k)
    shape = np.sin(9 * s) * s  # in no base or nuisance column
    rng = np.random.default_rng(seed)
    hits = {m: 0 for m in methods}
    for i in range(n_sets):
        y = rng.normal(size=(t_n, k)) + rng.normal(0, 4.0, (t_n, 1)) * shape[None]
        r_b, lin = _fit_resids(cands, folds, y)
        st = _stats(cands, folds, y[None])[0]
        for m in hits:
            cal = calibrate(lin, r_b, np.ones((t_n, k), bool), folds, draws=200, seed=i, method=m)
            hits[m] += bool(np.any(st > np.array([cal.thresholds[c.name] for c in cands])))
    return {m: h / n_sets for m, h in hits.items()}


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


def test_five_trajectories_webb_null_holds_and_a_planted_effect_passes(tmp_path, monkeypatch):
    """Five trajectories: 16 sign patterns cannot reach a 5 % family-wise level, Webb's
    six-point weights (``method="wild"``) can. Under trajectory-level errors (as above) the
    white-noise null lets candidates through far above 5 %, Webb's null keeps near the nominal
    rate (brute force over 120 fresh datasets); an effect planted at 8x its unit size passes the
    default gate."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    w, note = gate.wild_weights(5, 400, np.random.default_rng(0))
    assert "Webb" in note and w.shape == (400, 5)
    assert np.mean(w) == pytest.approx(0.0, abs=0.05) and np.mean(w**2) == pytest.approx(1, 0.05)
    hits = _null_hits(t_n=5, seed=12, methods=("wild", "white"))
    assert hits["wild"] <= 0.10, hits
    assert hits["white"] >= 0.2, hits
    # power: the effect "one" planted at 8x its unit size on white noise
    cands, folds, t_n, k = _problem(t_n=5)
    noise = np.random.default_rng(4).normal(size=(t_n, k))
    y = noise + 8.0 * cands[0].jac[..., -1]
    r_b, lin = _fit_resids(cands, folds, y)
    # the default under 8 trajectories: white noise only (Webb's null is opt-in, method="wild":
    # its held-out fall is not studentised, so a large effect can stay under it)
    cal = calibrate(lin, r_b, np.ones((t_n, k), bool), folds, draws=400)
    assert "white-noise null only" in cal.method
    st = _stats(cands, folds, y[None])[0]
    assert st[0] > cal.thresholds["one"], (st, cal.thresholds)


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

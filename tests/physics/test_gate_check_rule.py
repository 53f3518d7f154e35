"""The linearisation check that picks its rule from the measured roughness of the objective
(issue 17, h49: ``gate.auto_factor``, ``gate.CHECK_RULE = "auto"``).

Oracles:
- a linear model (exact least-squares fits): the antithetic pair's odd part equals the envelope
  theorem's slope to rounding, so the roughness is 0, the antithetic share is chosen and the
  factor is 1, whatever the size of the change (where the pair's odd part itself is large);
- a smooth nonlinear toy (``S sin(a z)``) and the same toy with 1-sigma jumps in the parameter
  (h38's rough residual, here with an effect planted so that the antithetic pair is fitted):
  smooth -> roughness near 0, antithetic, factor ~1; rough -> the draw rule;
- a mutated fit: one fitted chi^2 of the pair moved by ``Delta`` (a fit landing off its
  minimum, as on a rough objective) is measured as roughness ``Delta / 2`` exactly, and the
  rule flips to the draw exactly where ``sqrt(3) Delta / 2`` passes the factor's denominator.
"""

from __future__ import annotations

import numpy as np
import pytest
from rough_toy import K_N, T_N, make_toy

from robogs.physics import gate as G

# ---- a linear model: exact fits ---------------------------------------------------------------


def _linear(amp: float, seed: int = 2, t_n: int = 9, k: int = 50):
    """1 base + 2 effect columns, 3 nuisance columns per trajectory, a drop; the effect planted
    at ``amp``. Returns what :func:`gate.auto_factor` takes, a call log and the effect's
    linear model."""
    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((t_n, k, 3))
    jl = rng.standard_normal((t_n, k, 3))
    valid = np.ones((t_n, k), bool)
    valid[4, -9:] = False
    y = (jac[..., 1:] @ np.array([amp, 0.6 * amp]) + rng.standard_normal((t_n, k))) * valid
    m = valid.reshape(-1)
    loc = np.zeros((t_n * k, 3 * t_n))
    for t in range(t_n):
        loc[t * k : (t + 1) * k, 3 * t : 3 * t + 3] = jl[t]
    full = np.concatenate([jac.reshape(t_n * k, 3), loc], 1)

    def lsq(target: np.ndarray, cols: int) -> tuple[np.ndarray, np.ndarray]:
        a = np.concatenate([jac[..., :cols].reshape(t_n * k, cols), loc], 1)
        x, *_ = np.linalg.lstsq(a[m], target.reshape(-1)[m], rcond=None)
        return x, (target.reshape(-1) - a @ x).reshape(t_n, k) * valid

    x_b, r_b = lsq(y, 1)
    x_c, r_c = lsq(y, 3)
    x_b = np.concatenate([x_b[:1], np.zeros(2), x_b[1:]])
    cand = G.LinearCandidate("c", jac, jl, 1)
    calls: list[tuple[np.ndarray, float | None]] = []
    bump: dict[int, float] = {}

    def path(mus: np.ndarray) -> np.ndarray:
        return np.stack(
            [
                (y.reshape(-1) - full @ ((1 - u) * x_b + u * x_c)).reshape(t_n, k) * valid
                for u in mus
            ]
        )

    def fit(off: np.ndarray, mu: float | None):
        """Exact fits of ``y + off``; ``bump[i]`` lowers the i-th call's candidate chi^2."""
        _, rb = lsq(y + off, 1)
        _, rc = lsq(y + off, 3)
        c_c = float(np.sum(rc**2)) - bump.get(len(calls), 0.0)
        calls.append((off, mu))
        return float(np.sum(rb**2)), c_c, cand, rb, rc

    base = G.LinearCandidate("base", jac[..., :1], jl, 1)
    gain = float(np.sum(r_b**2) - np.sum(r_c**2))
    # the draws' noise: the candidate's residual plus a part along the columns (an exact fit's
    # own residual is orthogonal to them, which would make the pair's odd part and share 0)
    e = (r_c + jac @ np.array([0.3, 0.2, -0.25])) * valid
    return dict(r_b=r_b, r_c=e, valid=valid, fit=fit, path=path, base=base, gain=gain), calls, bump


def _run(p: dict, thr: float, signs: np.ndarray | None = None) -> G.LinearisationCheck:
    lam = G.draw_scale(p["gain"], thr)
    signs = G.check_signs(p["r_b"].shape[0], "h49") if signs is None else signs
    return G.auto_factor(
        p["r_b"], p["r_c"], p["valid"], p["fit"], p["path"], p["base"], lam, thr, 1.5, 2, signs
    )


def test_linear_model_has_no_roughness_and_keeps_the_antithetic_share():
    """Exact fits: the pair's odd part is the envelope slope ``2 <rho_B0 - rho_C0, e>`` to
    rounding (roughness 0), the share is ``||P e||^2`` (factor 1), no draw fit is added; at
    ``amp = 30`` the odd part itself is far above the factor's denominator, so a rule that
    skipped the slope would call this smooth model rough."""
    for amp in (1.0, 30.0):
        p, calls, _ = _linear(amp)
        chk = _run(p, 0.2 * p["gain"])
        odd = 0.5 * (chk.gains[1] - chk.gains[2])
        assert chk.rule == "auto" and chk.branch == "antithetic" and chk.chosen == "antithetic"
        assert chk.roughness == pytest.approx(0.0, abs=1e-8 * max(1.0, abs(odd)))
        assert chk.factor == pytest.approx(1.0, abs=1e-9)
        assert len(calls) == 3 and np.isnan(chk.other)
        assert chk.share == pytest.approx(chk.linears[0], abs=1e-8)
        if amp == 30.0:
            assert abs(odd) > 10.0 * (max(chk.linears[0], chk.precision) + 2)


def test_envelope_slope_is_the_gain_s_derivative():
    """On the linear model the gain of ``y + off + s e`` is a quadratic in ``s`` whose slope at 0
    is :func:`gate.envelope_slope` of the two fitted residuals (central difference, exact for a
    quadratic)."""
    p, _, _ = _linear(3.0, seed=7)
    e = p["r_c"] + 0.5 * np.random.default_rng(1).standard_normal(p["r_c"].shape)
    e = e * p["valid"]
    off0 = -p["path"](np.array([0.4]))[0]

    def gain(s: float) -> float:
        c_b, c_c, _, _, _ = p["fit"](off0 + s * e, None)
        return c_b - c_c

    _, _, _, rb, rc = p["fit"](off0, None)
    h = 0.3
    fd = (gain(h) - gain(-h)) / (2 * h)
    assert G.envelope_slope(rb, rc, e, p["valid"]) == pytest.approx(fd, rel=1e-9, abs=1e-9)


def test_a_mutated_fit_is_measured_as_roughness_and_flips_the_rule():
    """One fit of the pair (the ``+`` draw's candidate) lands ``Delta`` below its minimum: the
    roughness is ``Delta / 2`` exactly, the share moves by ``Delta / 2``; the rule stays
    antithetic while ``sqrt(3) Delta / 2 <= D + k`` and becomes h38's draw (one more fit, the
    data's offset shrunk by ``lambda``, no start on the path) just above it, with the antithetic
    factor kept as ``other``."""
    p0, _, _ = _linear(1.0)
    clean = _run(p0, 0.2 * p0["gain"])
    room = max(clean.linears[0], clean.precision) + 2  # the factor's denominator D + k
    edge = 2.0 * room / np.sqrt(3.0)
    for delta, rule in ((0.98 * edge, "antithetic"), (1.02 * edge, "draw")):
        p, calls, bump = _linear(1.0)
        bump[1] = delta
        thr = 0.2 * p["gain"]
        signs = G.check_signs(p["r_b"].shape[0], "h49")
        chk = _run(p, thr, signs)
        assert chk.roughness == pytest.approx(delta / 2, rel=1e-9)
        assert chk.share == pytest.approx(clean.share + delta / 2, rel=1e-9, abs=1e-9)
        assert chk.chosen == rule, (delta, edge, chk)
        if rule == "draw":
            lam = G.draw_scale(p["gain"], thr)
            assert len(calls) == 4 and calls[3][1] is None
            np.testing.assert_allclose(
                calls[3][0], G.draw_offset(p["r_b"], p["r_c"], signs[0], lam)
            )
            anti = max(1.0, (chk.share + 2) / room)
            assert chk.other == pytest.approx(anti) and chk.factor == pytest.approx(
                max(1.0, chk.ratios[-1])
            )
            assert len(chk.gains) == 4
        else:
            assert len(calls) == 3 and chk.factor == pytest.approx(max(1.0, (chk.share + 2) / room))


def test_both_measures_the_draw_without_changing_the_verdict():
    """``both=True`` (a measurement): where the antithetic share is chosen the draw rule runs
    too (one more fit, the data's offset shrunk by ``lambda``) and its factor is kept as
    ``other``; the factor and the rule chosen are those of ``both=False``."""
    p, calls, _ = _linear(1.0)
    thr = 0.2 * p["gain"]
    lam = G.draw_scale(p["gain"], thr)
    signs = G.check_signs(p["r_b"].shape[0], "h49")
    one = _run(p, thr, signs)
    calls.clear()
    chk = G.auto_factor(
        p["r_b"],
        p["r_c"],
        p["valid"],
        p["fit"],
        p["path"],
        p["base"],
        lam,
        thr,
        1.5,
        2,
        signs,
        both=True,
    )
    assert (chk.chosen, chk.factor) == (one.chosen, one.factor) and len(calls) == 4
    drew = G.null_draw_factor(
        p["r_b"], p["r_c"], p["valid"], lambda o: p["fit"](o, None)[:4], signs, lam, 1.5
    )
    assert chk.other == pytest.approx(drew.factor, rel=1e-12)


def test_fall_backs_keep_the_antithetic_result():
    """``lambda = 1`` (no fit) and a shrunk change the base absorbs (the ``+`` draw) are
    :func:`gate.antithetic_factor`'s own branches: no roughness is measured (nan), the rule
    chosen is the antithetic check's."""
    p, calls, _ = _linear(1.0)
    chk = _run(p, 2.0 * p["gain"])  # the gain is under the threshold: lambda = 1
    assert (chk.branch, chk.chosen, len(calls)) == ("data", "antithetic", 0)
    assert chk.factor == 1.5 and np.isnan(chk.roughness)


def test_auto_record_round_trips():
    chk = G.LinearisationCheck(
        2.1,
        1.8,
        [1.0, 1.1, 1.0, 2.1],
        [9.0, 12.0, 7.0, 20.0],
        [0.5, 3.0, 2.0, 8.0],
        scale=0.7,
        rule="auto",
        branch="antithetic",
        mu=0.8,
        share=1.5,
        precision=0.2,
        roughness=6.25,
        chosen="draw",
        other=1.3,
    )
    d = chk.to_dict()
    assert d["roughness_sigma2"] == 6.25 and d["chosen_rule"] == "draw"
    assert G.LinearisationCheck.from_dict(d) == chk
    plain = G.LinearisationCheck(1.2, 1.3, [1.2], [5.0], [3.0])
    assert "roughness_sigma2" not in plain.to_dict()
    assert np.isnan(G.LinearisationCheck.from_dict(plain.to_dict()).roughness)


# ---- a nonlinear toy, smooth and rough (numpy, no engine) -------------------------------------
# pred = beta x + l_t + S sin(a z) (+ jumps of 1 sigma in norm every 0.4 % of ``a``), unit noise;
# beta and l_t by linear least squares, ``a`` by a dense grid (the fit finds what a rough
# residual offers), the effect's column by a 1 % forward difference as the engines'.
_TOY = make_toy(11)
X, Z, XC, TAU, JUMPS = _TOY.x, _TOY.z, _TOY.xc, _TOY.tau, _TOY.jumps
VALID = np.ones((T_N, K_N), bool)
THR = 10.0
BASE = G.LinearCandidate("base", X[..., None], np.ones((T_N, K_N, 1)), 1)
_effect, _profile = _TOY.effect, _TOY.profile


def _toy(amp: float, seed: int, rough: bool) -> G.LinearisationCheck:
    grid = np.linspace(-0.4, 0.4, 801)
    obs = _effect(amp, False) + 0.3 * X + np.random.default_rng(seed).standard_normal(X.shape)

    def fit(off: np.ndarray, mu: float | None = None):
        r_b = _profile(off - obs)
        cs = [np.sum(_profile(_effect(a, rough) + off - obs) ** 2) for a in grid]
        a = float(grid[int(np.argmin(cs))])
        r_c = _profile(_effect(a, rough) + off - obs)
        col = (_effect(a + 0.01, rough) - _effect(a, rough)) / 0.01
        lin = G.LinearCandidate("e", np.stack([X, col], -1), np.ones((T_N, K_N, 1)), 1)
        c_b = float(np.sum(r_b**2))
        return c_b, min(float(np.sum(r_c**2)), c_b), lin, r_b, r_c, a

    c_b, c_c, lin, r_b, r_c, a_hat = fit(np.zeros_like(obs))
    data = G.linear_ratio(c_b - c_c, G.linear_gain(lin, r_b, VALID), 1)
    lin_b, lin_c = r_b + obs, r_c + obs - _effect(a_hat, rough)

    def path(mus: np.ndarray) -> np.ndarray:
        return np.stack(
            [_effect(m * a_hat, rough) + (1 - m) * lin_b + m * lin_c - obs for m in mus]
        )

    lam = G.draw_scale(c_b - c_c, THR)
    signs = G.check_signs(T_N, f"toy {seed}")
    return G.auto_factor(
        r_b, r_c, VALID, lambda o, m: fit(o, m)[:5], path, BASE, lam, THR, data, 1, signs
    )


def test_smooth_toy_keeps_the_antithetic_share():
    """Smooth ``S sin(a z)`` planted at 0.2 rad (gain above the threshold, so the pair is
    fitted): roughness 0 (< 0.01 sigma^2: the grid's rounding) on every seed, the antithetic
    share chosen, factor <= 1.02."""
    for seed in range(6):
        chk = _toy(0.2, seed, rough=False)
        assert chk.branch == "antithetic" and chk.chosen == "antithetic", (seed, chk)
        assert chk.roughness < 0.01 and chk.factor <= 1.02, (seed, chk)


def test_rough_toy_measures_its_roughness_and_takes_the_draw_rule():
    """The same toy with 1-sigma jumps every 0.4 % of ``a`` (which the fits exploit): the pair's
    odd part misses the envelope slope (median roughness over six seeds >= 0.5 sigma^2, smooth:
    < 0.01), and where ``sqrt(3)`` times it passes the factor's denominator h38's draw decides
    (measured: 3 of 6 seeds; the jumps are the same for the ``+-`` fits, so one pair sees only
    part of them)."""
    chks = [_toy(0.2, seed, rough=True) for seed in range(6)]
    assert all(c.branch == "antithetic" for c in chks), [c.branch for c in chks]
    assert np.median([c.roughness for c in chks]) >= 0.5, [c.roughness for c in chks]
    for c in chks:
        rough = np.sqrt(3.0) * c.roughness > max(c.linears[0], c.precision) + 1
        assert c.chosen == ("draw" if rough else "antithetic"), c
        assert (len(c.gains) == 4) == rough and (np.isfinite(c.other)) == rough
    assert sum(c.chosen == "draw" for c in chks) >= 2, [c.chosen for c in chks]


# ---- h109: the antithetic share only past z's cut (gate.zauto_factor, CHECK_RULE "zauto") ----


def _phi(x: float) -> float:
    """Standard normal CDF from ``math.erf`` (an oracle independent of ``statistics``)."""
    import math

    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def _zrun(p: dict, thr: float, alpha: float, both: bool = False) -> G.LinearisationCheck:
    lam = G.draw_scale(p["gain"], thr)
    signs = G.check_signs(p["r_b"].shape[0], "h49")
    args = (p["r_b"], p["r_c"], p["valid"], p["fit"], p["path"], p["base"], lam, thr, 1.5, 2)
    return G.zauto_factor(*args, signs, p["gain"], alpha, both=both)


def _thr_at(gain: float, z: float, k: int = 2) -> float:
    """The threshold at which a gain ``gain`` sits ``z`` null standard deviations above a
    threshold-sized change, by bisection on the noncentral chi-square's moments (mean
    ``thr + k``, variance ``2 k + 4 thr``) written out here."""
    lo, hi = 0.0, gain
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if (gain - mid - k) / np.sqrt(4 * mid + 2 * k) > z:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_change_z_has_the_noncentral_chi2_moments_of_a_threshold_sized_change():
    """A change of squared size ``thr`` on ``k`` linear columns with unit white noise: its
    least-squares gain ``||P (delta + e)||^2`` over 40 000 noise draws has mean ``thr + k`` and
    variance ``2 k + 4 thr`` (Monte Carlo, 3 % / 5 %), and ``change_z`` standardises a gain by
    exactly those (a spread taken at the fitted gain, h49's offline form, is caught)."""
    rng = np.random.default_rng(0)
    n, k, thr = 60, 2, 9.0
    x = rng.standard_normal((n, k))
    q, _ = np.linalg.qr(x)
    delta = q @ np.array([3.0, 0.0])  # ||P delta||^2 = 9
    e = rng.standard_normal((40_000, n))
    g = np.sum(((delta + e) @ q) ** 2, axis=1)
    assert g.mean() == pytest.approx(thr + k, rel=0.03)
    assert g.var() == pytest.approx(2 * k + 4 * thr, rel=0.05)
    for gain in (11.0, 25.0, 60.0):
        z_mc = (gain - g.mean()) / g.std()
        assert G.change_z(gain, thr, k) == pytest.approx(z_mc, abs=0.05)
    assert G.change_z(60.0, thr, k) != pytest.approx((60.0 - thr) / (2 * np.sqrt(60.0)), rel=0.1)
    assert G.change_z(thr + k, thr, k) == 0.0


def test_z_cut_is_the_normal_quantile_of_the_candidate_level():
    """``Phi(z_cut(alpha)) = 1 - alpha`` (erf oracle), and the cut moves with the level:
    1.645 at 5 %, 2.46 at 0.7 % (design B's ``alpha'``), 3.09 at 0.1 %."""
    for a in (0.05, 0.007, 0.001):
        assert _phi(G.z_cut(a)) == pytest.approx(1.0 - a, abs=1e-12)
    assert G.z_cut(0.05) < G.z_cut(0.007) < G.z_cut(0.001)


def test_zauto_keeps_the_antithetic_share_on_a_change_far_above_threshold_size():
    """Linear model (exact fits, a smooth pair), the threshold 0.2 of the gain: ``z`` is far
    above the cut at 0.7 %, so the check is ``auto_factor``'s antithetic share (three fits,
    factor 1) with ``z`` and the cut recorded."""
    p, calls, _ = _linear(1.0)
    thr = 0.2 * p["gain"]
    z = (p["gain"] - thr - 2) / np.sqrt(4 * thr + 4)
    chk = _zrun(p, thr, 0.007)
    assert z > 2.0 * G.z_cut(0.007)
    assert chk.z == pytest.approx(z, rel=1e-12) and chk.cut == G.z_cut(0.007)
    assert (chk.rule, chk.chosen, chk.branch, len(calls)) == (
        "zauto",
        "antithetic",
        "antithetic",
        3,
    )
    assert chk.factor == pytest.approx(1.0, abs=1e-9) and np.isnan(chk.other)


def test_zauto_takes_the_draw_on_a_threshold_sized_change():
    """The same data with the threshold at 0.95 of the gain (``z`` under 1): exactly h38's draw
    (one fit, the data's offset shrunk by ``lambda``, no start on the path), its factor that of
    :func:`gate.null_draw_factor`, no antithetic fit."""
    p, calls, _ = _linear(1.0)
    thr = 0.95 * p["gain"]
    lam = G.draw_scale(p["gain"], thr)
    signs = G.check_signs(p["r_b"].shape[0], "h49")
    chk = _zrun(p, thr, 0.007)
    assert chk.z < 1.0 < G.z_cut(0.007)
    assert (chk.chosen, len(calls), calls[0][1]) == ("draw", 1, None)
    np.testing.assert_allclose(calls[0][0], G.draw_offset(p["r_b"], p["r_c"], signs[0], lam))
    drew = G.null_draw_factor(
        p["r_b"], p["r_c"], p["valid"], lambda o: p["fit"](o, None)[:4], signs, lam, 1.5
    )
    assert chk.factor == drew.factor and chk.gains == drew.gains


def test_the_cut_moves_with_the_level():
    """A threshold set so that ``z = 2.4`` (bisection on the moments): at ``alpha' = 5 %``
    (cut 1.64) the antithetic share, at 0.1 % (cut 3.09) the draw."""
    p, _, _ = _linear(1.0)
    thr = _thr_at(p["gain"], 2.4)
    assert G.change_z(p["gain"], thr, 2) == pytest.approx(2.4, abs=1e-9)
    assert _zrun(p, thr, 0.05).chosen == "antithetic"
    assert _zrun(p, thr, 0.001).chosen == "draw"


def test_zauto_takes_the_draw_where_the_antithetic_check_falls_back():
    """``z`` above the cut but the noise-free draw's gain lowered under half the threshold (the
    shrunk change absorbed by the base): no share, so h38's draw decides (the ``+`` fall-back's
    factor kept as ``other``)."""
    p0, _, _ = _linear(1.0)
    thr = 0.2 * p0["gain"]
    g0 = _zrun(p0, thr, 0.007).gains[0]
    p, calls, bump = _linear(1.0)
    bump[0] = -(g0 - 0.3 * thr)  # the noise-free draw's candidate fit lands 0.7 thr short
    chk = _zrun(p, thr, 0.007)
    assert chk.z > chk.cut and chk.branch == "plus" and chk.chosen == "draw"
    assert len(calls) == 3 and calls[2][1] is None
    assert chk.other == pytest.approx(max(1.0, chk.ratios[1]))
    assert chk.factor == pytest.approx(max(1.0, chk.ratios[2]))


def test_zauto_both_measures_the_other_rule():
    """``both=True`` below the cut: the verdict is the draw's; the antithetic rule also runs
    (three more fits) and its factor is ``other``, its roughness recorded."""
    p, calls, _ = _linear(1.0)
    thr = 0.95 * p["gain"]
    one = _zrun(p, thr, 0.007)
    calls.clear()
    chk = _zrun(p, thr, 0.007, both=True)
    assert (chk.chosen, chk.factor) == ("draw", one.factor) and len(calls) == 4
    assert chk.other == pytest.approx(1.0, abs=1e-9) and chk.roughness < 1e-6


def test_zauto_record_round_trips():
    chk = G.LinearisationCheck(
        4.6, 3.1, [4.6], [9.3], [0.05], scale=0.52, rule="zauto", chosen="draw", z=1.3, cut=2.41
    )
    d = chk.to_dict()
    assert (d["z_change"], d["z_cut"], d["chosen_rule"]) == (1.3, 2.41, "draw")
    assert "mu" not in d and G.LinearisationCheck.from_dict(d) == chk
    full = G.LinearisationCheck(
        1.0, 3.1, [1.0] * 3, [9.0, 12.0, 7.0], [0.5, 3.0, 2.0], scale=0.5, rule="zauto",
        branch="antithetic", mu=0.6, share=0.4, precision=0.1, roughness=0.2,
        chosen="antithetic", other=4.6, z=3.0, cut=2.41,
    )  # fmt: skip
    assert G.LinearisationCheck.from_dict(full.to_dict()) == full

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

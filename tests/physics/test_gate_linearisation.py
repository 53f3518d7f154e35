"""The gate's linearisation check (issue 17, h34; on null draws, h38): ``gate.linear_gain``
against a brute-force least-squares fit; the factor measured on null draws (the data less the
candidate's fitted effect) stays at 1 for a smooth model whatever the planted effect's size,
where the factor taken from the data's own fit grows with it; it exceeds 1 on a residual that
is rough in the parameter (a finite-difference Jacobian straddling jumps); the draws are
deterministic and flip whole trajectories; the null is scaled by the factor; the report shows
it on screen."""

from __future__ import annotations

import numpy as np
import pytest
from rough_toy import K_N, T_N, make_toy

from robogs.physics import gate as G


def _case(seed: int = 0, t_n: int = 9, k: int = 60):
    """A linear model: 1 base + 2 effect columns, 3 nuisance columns per trajectory."""
    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((t_n, k, 3))
    jl = rng.standard_normal((t_n, k, 3))
    valid = np.ones((t_n, k), bool)
    valid[2, -7:] = False  # a drop
    resid = rng.standard_normal((t_n, k)) * valid
    return G.LinearCandidate("c", jac, jl, 1), resid, valid


def _brute_gain(cand: G.LinearCandidate, resid: np.ndarray, valid: np.ndarray) -> float:
    """chi^2 of the base fit minus that of the candidate's, one dense least-squares each
    (global columns and every trajectory's nuisance block in one design matrix)."""
    t_n, k, _ = cand.jac.shape
    m = valid.reshape(-1)

    def chi2(cols: int) -> float:
        glob = cand.jac[..., :cols].reshape(t_n * k, cols)
        loc = np.zeros((t_n * k, 3 * t_n))
        for t in range(t_n):
            loc[t * k : (t + 1) * k, 3 * t : 3 * t + 3] = cand.jac_local[t]
        a = np.concatenate([glob, loc], 1)[m]
        y = resid.reshape(-1)[m]
        x, *_ = np.linalg.lstsq(a, y, rcond=None)
        return float(np.sum((y - a @ x) ** 2))

    return chi2(cand.n_base) - chi2(cand.jac.shape[-1])


def test_linear_gain_is_the_least_squares_fall():
    cand, resid, valid = _case()
    got = G.linear_gain(cand, resid, valid)
    assert got == pytest.approx(_brute_gain(cand, resid, valid), rel=1e-9)
    assert got > 0.0


# ---- a closed-form model (numpy, no engine) --------------------------------------------------
# Per trajectory t and sample i: pred = beta x + l_t + S sin(a z) (+ jumps), beta the base
# parameter, l_t a nuisance offset, a the effect's parameter (zero: no effect); unit noise.
# Fits are brute force: beta and l_t by linear least squares, a by a dense grid (so the
# nonlinear fit finds what a rough residual offers); Jacobians by a 1 % forward difference,
# as the engines' (fit.fit_problems).
_TOY = make_toy(0)
X, Z, XC, TAU, JUMPS = _TOY.x, _TOY.z, _TOY.xc, _TOY.tau, _TOY.jumps
VALID = np.ones((T_N, K_N), bool)
_effect, _profile = _TOY.effect, _TOY.profile


def _fit(offset: np.ndarray, obs: np.ndarray, rough: bool, grid: np.ndarray):
    """chi^2 of the base and base + effect fits of ``r(theta) + offset`` (r = pred - obs), the
    fitted ``a`` and the base fit's residual."""
    r_b = _profile(offset - obs)
    c_b = float(np.sum(r_b**2))
    c = np.array([np.sum(_profile(_effect(a, rough) + offset - obs) ** 2) for a in grid])
    j = int(np.argmin(c))
    return c_b, float(min(c[j], c_b)), float(grid[j]), r_b


def _linear(a: float, rough: bool) -> G.LinearCandidate:
    """The model linearised at effect value ``a`` (1 % forward-difference column)."""
    h = 0.01
    col = (_effect(a + h, rough) - _effect(a, rough)) / h
    return G.LinearCandidate("e", np.stack([X, col], -1), np.ones((T_N, K_N, 1)), 1)


THR = 10.0
"""The toy's null threshold [sigma^2] (about a one-parameter family-wise tail)."""


def _toy(amp: float, seed: int, rough: bool = False) -> tuple[float, G.LinearisationCheck]:
    """(the data's own ratio, the check on its draws) for a planted effect ``amp``."""
    grid = np.linspace(-0.4, 0.4, 801) if rough else np.linspace(-2.0, 2.0, 801)
    obs = _effect(amp, False) + 0.3 * X + np.random.default_rng(seed).standard_normal(X.shape)
    c_b, c_c, a_hat, r_b = _fit(np.zeros_like(obs), obs, rough, grid)
    r_c = _profile(_effect(a_hat, rough) - obs)
    data = G.linear_ratio(c_b - c_c, G.linear_gain(_linear(a_hat, rough), r_b, VALID), 1)

    def fit(off: np.ndarray):
        cb, cc, a, rb = _fit(off, obs, rough, grid)
        return cb, cc, _linear(a, rough), rb

    signs = G.check_signs(T_N, f"toy {seed}")
    lam = G.draw_scale(c_b - c_c, THR)
    return data, G.null_draw_factor(r_b, r_c, VALID, fit, signs, lam, data)


def test_null_draw_factor_does_not_grow_with_the_effect():
    """Smooth model: the data's own ratio (h34's factor) grows with the planted amplitude
    (the effect's own nonlinearity: 1.00 at 0, > 10 at 1 rad), the factor measured on draws
    with the fitted change shrunk to the threshold's scale stays near 1 at every amplitude."""
    amps = (0.0, 0.25, 0.5, 1.0)
    data, factors = [], []
    for amp in amps:
        d, chk = _toy(amp, seed=1)
        data.append(d)
        factors.append(chk.factor)
        assert len(chk.ratios) == G.CHECK_DRAWS and chk.data_ratio == d
    assert data[0] < 1.05 and data[-1] > 10.0
    assert all(np.diff(data[1:]) > 0), data
    assert max(factors) <= 1.02, factors


def test_null_draw_factor_above_one_on_a_rough_residual():
    """Rough model, null data (no effect): jumps of 1 sigma every 0.4 % of the parameter, which
    the 1 % forward difference straddles. The nonlinear fit gains more than the linear model,
    so the factor exceeds 1 (median over six null seeds >= 1.2); the same seeds on the smooth
    model stay at 1 (+-2 %)."""
    rough = [_toy(0.0, seed=s, rough=True)[1].factor for s in range(6)]
    smooth = [_toy(0.0, seed=s)[1].factor for s in range(6)]
    assert np.median(rough) >= 1.2, rough
    assert max(smooth) <= 1.02, smooth


def test_draws_are_deterministic_and_flip_whole_trajectories():
    """Signs from the fingerprint (the first draw +1), distinct; each draw's offset removes
    ``1 - lambda`` of the base fit's residual and ``lambda`` of the candidate's, and adds the
    candidate's with one sign per whole trajectory; ``lambda = 1, s = +1`` is the data."""
    assert np.array_equal(G.check_signs(9, "any"), np.ones((G.CHECK_DRAWS, 9)))
    signs = G.check_signs(9, "fingerprint A", draws=3)
    assert signs.shape == (3, 9)
    np.testing.assert_array_equal(signs, G.check_signs(9, "fingerprint A", draws=3))
    assert not np.array_equal(signs, G.check_signs(9, "fingerprint B", draws=3))
    assert np.all(signs[0] == 1.0) and set(np.unique(signs)) <= {-1.0, 1.0}
    assert len({tuple(r) for r in signs}) == len(signs)
    assert len(G.check_signs(1, "x", draws=3)) == 3
    cand, r_b, valid = _case(3)
    r_c = np.random.default_rng(4).standard_normal(r_b.shape) * valid
    assert not np.any(G.draw_offset(r_b, r_c, np.ones(9), 1.0))  # the data itself
    assert G.draw_scale(40.0, 10.0) == pytest.approx(0.5) and G.draw_scale(8.0, 10.0) == 1.0
    seen: list[np.ndarray] = []

    def fit(offset: np.ndarray):
        seen.append(offset)
        return 100.0, 40.0, cand, r_b + offset

    lam = 0.3
    chk = G.null_draw_factor(r_b, r_c, valid, fit, signs, lam)
    t_of = np.nonzero(valid)[0]
    for s, off in zip(signs, seen, strict=True):
        np.testing.assert_allclose(off, -(1 - lam) * r_b - lam * r_c + s[:, None] * r_c)
        flip = (off + (1 - lam) * r_b + lam * r_c)[valid] / r_c[valid]
        for t in range(9):
            assert np.allclose(flip[t_of == t], s[t])  # one sign for the whole trajectory
    lin = [G.linear_gain(cand, r_b + off, valid) for off in seen]
    np.testing.assert_allclose(chk.linears, lin)
    want = max(1.0, float(np.max([(60.0 + 2) / (max(v, 0.0) + 2) for v in lin])))
    assert chk.factor == pytest.approx(want) and chk.gains == [60.0] * len(signs)
    assert chk.scale == lam


def test_needs_check_only_where_it_can_change_a_verdict():
    assert G.needs_check(50.0, 30.0, 1.4, -12.0)
    assert not G.needs_check(20.0, 30.0, 1.4, -12.0)  # under its unscaled threshold
    assert not G.needs_check(50.0, 30.0, 0.9, -12.0)  # the fit gains no more than linear
    assert not G.needs_check(50.0, 30.0, 1.4, 3.0)  # ΔBIC >= 0: never reported anyway
    assert G.linear_ratio(8.2, 0.6, 1) == pytest.approx(9.2 / 1.6)
    assert G.linear_ratio(-3.0, 5.0, 2) == pytest.approx(2 / 7) and G.linear_ratio(9, 1, 0) == 1


def test_null_scaled_by_the_check_and_cached(tmp_path, monkeypatch):
    """Thresholds, own quantiles and p-values scaled by the factor (JSON too); another
    statistic's null cannot be scaled; the check is cached with the calibration."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    cand, resid, valid = _case(1)
    folds = [np.arange(9) % 3 == f for f in range(3)]
    kw = dict(draws=200, method="white", fingerprint="data|rev|mujoco")
    cal = G.calibrate([cand], resid, valid, folds, **kw)
    thr0, q0 = cal.thresholds["c"], cal.q95["c"]
    hb, he, delta = np.array([thr0 + 5.0]), np.array([0.0]), np.full((1, 4), 5.0)
    p0 = cal.p_value("c", thr0)
    assert cal.judge("c", hb, he, delta)[0] == pytest.approx(thr0)
    chk = G.LinearisationCheck(2.5, 3.0, [2.5, 1.1, 2.6], [20.0, 5.0, 22.0], [7.0, 4.0, 7.5])
    cal.apply_check("c", chk)
    thr, q95, _ = cal.judge("c", hb, he, delta)
    assert thr == pytest.approx(2.5 * thr0) and q95 == pytest.approx(2.5 * q0)
    assert cal.p_value("c", thr0) > p0
    d = cal.to_dict()
    assert d["inflation"] == {"c": 2.5} and d["thresholds_sigma2"]["c"] == pytest.approx(thr)
    assert d["linearisation_check"]["candidates"]["c"]["draw_ratios"] == [2.5, 1.1, 2.6]
    G.store_checks(cal)
    again = G.calibrate([cand], resid, valid, folds, **kw)
    assert again.cached and again.thresholds["c"] == pytest.approx(thr0)  # unscaled stored
    assert again.checks["c"].factor == 2.5 and again.inflation == {}
    t_cal = G.calibrate([cand], resid, valid, folds, draws=100, method="white", statistic="t")
    with pytest.raises(ValueError, match="held-out fall"):
        t_cal.apply_check("c", chk)


def test_report_shows_the_factor_on_screen(tmp_path, capsys, monkeypatch):
    """``robogs diagnose`` prints the scaled threshold's factor in the evidence column and the
    check's cost under the gate line (the diagnosis itself stubbed: its numbers are the
    gate's, tested above)."""
    from robogs.cli.main import main
    from robogs.physics import api
    from robogs.synth.scenarios import make_scenario, write_scenario

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    rec = make_scenario("none", seed=0, kinds=("push",), n_speeds=1, n_dirs=2, check=False)
    ds = tmp_path / "ds"
    write_scenario(rec, str(ds))
    chk = G.LinearisationCheck(2.5, 3.0, [2.5, 1.1, 2.6], [20.0, 5.0, 22.0], [7.0, 4.0, 7.5])
    chk.rollouts, chk.seconds = 84, 12.5
    row = {
        "name": "anisotropic_friction",
        "family": "contact",
        "reported": True,
        "verdict": "add",
        "delta_bic": -1981.0,
        "heldout_rms_before": 4.0,
        "heldout_rms_after": 3.0,
        "heldout_gain_sigma2": 2936.7,
        "null_threshold_sigma2": 1556.8,
        "null_factor": 1.12,
        "params": [],
    }
    plain = dict(row, name="table_tilt", reported=False, verdict="not supported", null_factor=1.0)
    gate = {
        "method": "linearised held-out null (both)",
        "draws": 656,
        "seconds": 1.9,
        "linearisation_check": {
            "candidates": {"anisotropic_friction": chk.to_dict() | {"factor": 1.12}},
            "rollouts": 84,
            "seconds": 12.5,
            "cached": False,
        },
    }
    doc = {
        "effects": [row, plain],
        "skipped": [],
        "rms_base_mm": 4.0,
        "noise_floor_mm": 3.0,
        "gate": gate,
    }

    class Stub:
        def to_dict(self):
            return doc

    monkeypatch.setattr(api, "diagnose", lambda *a, **k: Stub())
    capsys.readouterr()
    main(["diagnose", str(ds), "--no-progress", "--model", "object"])
    out = capsys.readouterr().out
    assert "2.94e+03 / 1.56e+03 σ² (×1.12)" in out, out
    assert out.count("(×") == 1  # the unscaled row shows none
    assert "linearisation check on null draws: anisotropic_friction threshold ×1.12" in out
    assert "84 rollouts, 12.5 s" in out


@pytest.mark.slow
def test_mujoco_null_threshold_near_planar_on_design_b_null_seed_1(shared_fits):
    """Oracle: the planar engine on the same design-B null recording (one box on a table, both
    engines represent it). Before any check (4 ms x 2 pusher pair) MuJoCo's tilt threshold was
    29.2 sigma^2 against planar's 51.8 (ratio 0.56) and the tilt was reported (held-out 31.2):
    its fit gains 28.3 sigma^2 where its 1 % forward-difference Jacobian accounts for 20.1
    (planar: 28.9 / 30.1). With the check on draws: no report, MuJoCo's tilt null scaled up
    (factor > 1.2) and planar's nulls unscaled (factor <= 1.1). Where the tilt's gain is at its
    threshold's scale (``lambda = 1``, before the engine smoothed its servo targets over the
    drive's knots, h67) the first draw gives the data's own ratio back; since h67 its gain is
    above it and the change is shrunk (4 ms x 2: ``lambda`` 0.853, factor 1.88, threshold ratio
    0.71; the 2.5 ms x 1.7 pair of stops 49-52: held-out 22.4 against 29.86 after factor 1.46,
    ``lambda`` 0.959, ratio 0.58). The ratio is one seed's wild tail, which h47 traced to this
    seed's noise meeting MuJoCo's strike error on the two fastest pushes, so its bound is 0.5
    (it was 0.7, met by the old pair only through the check's factor); where the engines must
    agree is asserted by :func:`test_mujoco_linearisation_agrees_with_planar_with_smooth_columns`.
    Stop 53's pusher pair (5 steps x 1.2, whose fast flush strikes no longer hang on sub-degree
    start yaws) brings MuJoCo's tilt fit in line with planar's: held-out fall 28.6 against
    planar's 26.7 sigma^2 (within [0.8, 1.25] asserted), below its unscaled threshold 33.7
    (planar 51.8; ratio 0.65), so no check is needed and none is made (asserted). Under the wild
    null (``both``); the default parametric null's thresholds on this seed
    (planar 110.1, MuJoCo 104.2 sigma^2) leave the tilt's fall far below them, so no check is
    made: :func:`test_mujoco_parametric_null_near_planar_on_design_b_null_seed_1`."""
    pytest.importorskip("mujoco")
    from robogs.physics.diagnose import GATE_METHOD_ENV, diagnose_recording
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios.design_b import make_design_b

    with pytest.MonkeyPatch.context() as m:
        m.setenv(GATE_METHOD_ENV, "both")
        rec = make_design_b("none", seed=1)
        res = {
            be: diagnose_recording(rec, engine=Engine(rec, backend=be))
            for be in ("planar", "mujoco")
        }
    thr = {be: {r.name: r.null_threshold_sigma2 for r in res[be].rows} for be in res}
    assert thr["mujoco"]["table_tilt"] / thr["planar"]["table_tilt"] >= 0.5
    assert not [r.name for r in res["mujoco"].rows if r.reported]
    assert max((res["planar"].gate["inflation"] or {"-": 1.0}).values()) <= 1.1
    fall = {be: {r.name: r.heldout_gain_sigma2 for r in res[be].rows} for be in res}
    assert 0.8 <= fall["mujoco"]["table_tilt"] / fall["planar"]["table_tilt"] <= 1.25, fall
    assert fall["mujoco"]["table_tilt"] < thr["mujoco"]["table_tilt"]
    assert res["mujoco"].gate["linearisation_check"] is None  # nothing near its gate to check


@pytest.mark.slow
def test_mujoco_linearisation_agrees_with_planar_with_smooth_columns(
    monkeypatch, tmp_path, shared_fits
):
    """Oracle (h48, with the gate's smooth start-pose columns, roughness.SMOOTH_NUISANCE): the
    planar engine on the same design-B null recording, compared where the engines must agree
    and not on one seed's wild tail (h47: that tail is set by the one or two pushes with the
    largest tilt-aligned residual, and MuJoCo's strike error points against seed 1's noise there):
    1. the linearisations on a common residual: planar's base residual with MuJoCo's linearised
       candidates gives the tilt's wild-null threshold within 0.7 of planar's own (offline on
       h47's fits: 39.5 vs 51.8 on this pair, 51.6 with 3 x 1.7; the rest of the gap is MuJoCo's
       1 % friction column, h47's swaps). With the fitter's 0.1 mm start-pose columns it was
       23.5 (0.45) on the pusher pair of stops 49-52: the oracle failed on rough columns. Stop
       53's pair (5 steps x 1.2) no longer hangs fast strikes on sub-degree start yaws
       (``test_mujoco_flush_strike.py``), and the fitter's own columns now pass too (45.3
       against 51.6, 0.88): asserted, so that a rougher engine fails here again;
    2. the tilt's white-noise nulls within 30 % (planar 8.8, MuJoCo 9.4);
    3. nothing reported on MuJoCo."""
    pytest.importorskip("mujoco")
    from robogs.physics import diagnose as D
    from robogs.physics import roughness as R
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios.design_b import make_design_b

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(R, "SMOOTH_NUISANCE", True)
    seen: dict[str, list] = {"lin": [], "outs": []}
    real_calibrate, real_inner = G.calibrate, D._calibrate

    def calibrate(cands, resid, valid, folds, **kw):
        seen["lin"].append((list(cands), resid, valid, folds))
        return real_calibrate(cands, resid, valid, folds, **kw)

    def inner(eng, space, cands, outs, *a, **kw):
        seen["outs"].append(outs)
        return real_inner(eng, space, cands, outs, *a, **kw)

    monkeypatch.setattr(G, "calibrate", calibrate)
    monkeypatch.setattr(D, "_calibrate", inner)
    rec = make_design_b("none", seed=1)
    res = {
        be: D.diagnose_recording(rec, engine=Engine(rec, backend=be)) for be in ("planar", "mujoco")
    }
    (lp, rp, vp, folds), (lm, rm, vm, _) = seen["lin"][:2]
    assert np.array_equal(vp, vm)

    def tilt(cands, resid, method):
        cal = real_calibrate(cands, resid, vp, folds, method=method)
        return cal.thresholds["table_tilt"]

    own = tilt(lp, rp, "wild")
    assert tilt(lm, rp, "wild") / own >= 0.7
    fitter = [
        G.LinearCandidate(c.name, c.jac, o.jac_local, c.n_base)
        for c, o in zip(lm, seen["outs"][1][1:], strict=True)
    ]
    assert tilt(fitter, rp, "wild") / own >= 0.7
    assert 0.7 <= tilt(lm, rm, "white") / tilt(lp, rp, "white") <= 1.3
    assert not [r.name for r in res["mujoco"].rows if r.reported]
    assert "nuisance_columns" in res["mujoco"].gate


def test_check_record_round_trips():
    chk = G.LinearisationCheck(1.4, 2.0, [1.0, 1.4, 0.9], [9.0, 12.0, 7.0], [0.5, 3.0, 2.0])
    chk.scale, chk.rollouts, chk.seconds = 0.6, 42, 3.5
    back = G.LinearisationCheck.from_dict(chk.to_dict())  # a cached check cost nothing
    assert (back.rollouts, back.seconds) == (0, 0.0)
    back.rollouts, back.seconds = chk.rollouts, chk.seconds
    assert back == chk
    old = chk.to_dict() | {"rule": "antithetic", "branch": "antithetic", "mu": 0.8}
    assert G.LinearisationCheck.from_dict(old).factor == 1.4  # keys of removed checks ignored


# ---- h99: the parametric null's start-pose columns (roughness.smooth_for) -----------------
def test_smooth_columns_only_for_the_parametric_null(monkeypatch):
    """The wild null (``both``) keeps the fitter's start-pose columns (its results unchanged);
    the parametric null (the default) always takes the smooth ones; the h48 flag still turns
    them on for all."""
    from robogs.physics import roughness as R

    monkeypatch.setattr(R, "SMOOTH_NUISANCE", False)
    assert [m for m in G.METHODS if R.smooth_for(m)] == ["parametric"]
    monkeypatch.setattr(R, "SMOOTH_NUISANCE", True)
    assert all(R.smooth_for(m) for m in G.METHODS)


@pytest.mark.slow
def test_mujoco_parametric_null_near_planar_on_design_b_null_seed_1(
    monkeypatch, tmp_path, shared_fits
):
    """Oracle: the planar engine on the same design-B null recording; the observed null tilt
    falls are the same scale on both engines (seeds 1, 6, 14, 18, 30, 39: h92), so the
    parametric nulls should be too. About 96 % of the drive-error response lies in the span of
    the base and start-pose columns, so the null hangs on how those columns are made (h92):
    with the fitter's 0.1 mm forward differences MuJoCo's tilt threshold was 30.2 sigma^2
    against planar's 111.4 (0.27). With the smooth columns (h99): 104.2 against 110.1.
    1. MuJoCo's tilt threshold within [0.7, 1.43] of planar's;
    2. MuJoCo's own fits with the fitter's columns put back: they failed it (< 0.7) on the
       pusher pair of stops 49-52; on stop 53's (5 steps x 1.2, whose fast strikes no longer
       hang on sub-degree start yaws) they pass (87.1 against 110.1, 0.79): asserted, so that
       a rougher engine fails here again;
    3. planar's unchecked thresholds move by under 5 % against its fitter's columns (the rule
       picks central columns where the forward one disagrees over 3 mm: -1.2 % tilt, -2.5 %
       camera);
    4. nothing reported on either engine."""
    pytest.importorskip("mujoco")
    from dataclasses import replace

    from robogs.physics import diagnose as D
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios.design_b import make_design_b

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("ROBOGS_GATE_METHOD", "parametric")
    monkeypatch.delenv("ROBOGS_GATE_INSAMPLE", raising=False)
    seen: dict[str, dict] = {}
    real_calibrate, real_inner = G.calibrate, D._calibrate
    cur = [""]

    def calibrate(cands, resid, valid, folds, **kw):
        cal = real_calibrate(cands, resid, valid, folds, **kw)
        seen[cur[0]].setdefault("cal", (list(cands), resid, valid, folds, kw, cal))
        return cal

    def inner(eng, space, cands, outs, *a, **kw):
        seen[cur[0]].setdefault("outs", outs)
        return real_inner(eng, space, cands, outs, *a, **kw)

    monkeypatch.setattr(G, "calibrate", calibrate)
    monkeypatch.setattr(D, "_calibrate", inner)
    rec = make_design_b("none", seed=1)
    res = {}
    for be in ("planar", "mujoco"):
        cur[0] = be
        seen[be] = {}
        res[be] = D.diagnose_recording(rec, engine=Engine(rec, backend=be))
    thr = {be: {r.name: r.null_threshold_sigma2 for r in res[be].rows} for be in res}
    assert 0.7 <= thr["mujoco"]["table_tilt"] / thr["planar"]["table_tilt"] <= 1.43, thr

    def with_fitter_columns(be: str) -> dict[str, float]:
        cands, resid, valid, folds, kw, _ = seen[be]["cal"]
        outs = seen[be]["outs"][1:]
        old = [replace(c, jac_local=o.jac_local) for c, o in zip(cands, outs, strict=True)]
        return real_calibrate(old, resid, valid, folds, **{**kw, "fingerprint": None}).thresholds

    assert with_fitter_columns("mujoco")["table_tilt"] / thr["planar"]["table_tilt"] >= 0.7
    new, old = seen["planar"]["cal"][-1].thresholds, with_fitter_columns("planar")
    for n in old:
        assert new[n] == pytest.approx(old[n], rel=0.05, abs=0.5), n
    for be in res:
        assert not [r.name for r in res[be].rows if r.reported], be
        assert "nuisance_columns" in res[be].gate

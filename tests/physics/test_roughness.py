"""Oracle tests of the gate's smooth start-pose columns (robogs.physics.roughness, h48).

A toy residual with a staircase (a quantised contact onset: the residual jumps by ``s`` every
``D`` of the nuisance parameter) has the closed-form smooth slope ``A + s / D``; the fitter's
forward column is ``A`` or ``A + s / h`` depending on where the onsets fall. A smooth residual
keeps the fitter's column bit for bit. A mutant rule (always the fitter's column, or one
agreement instead of two) is caught by the same assertions.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robogs.physics import roughness as R

T_N, K_N, L_N = 4, 60, 3
H = R.fitter_local_h()  # 1e-4, 1e-4, 1e-3
RESID = np.full((T_N, K_N), 20.0 / np.sqrt(K_N))  # chi2_t = 400: tolerance sin 1/800
VALID = np.ones((T_N, K_N), bool)


def _toy(period: float, phase: np.ndarray, seed: int = 0):
    """Residual ``r_tk(a) = A_tk . a + s_tk floor((a_0 - phase_t) / (period h_0))`` (the
    staircase on the first nuisance dimension), its closed-form smooth columns and the fitter's
    forward columns at ``a = 0``."""
    rng = np.random.default_rng(seed)
    a_mat = rng.standard_normal((T_N, K_N, L_N))
    d = period * H[0]
    # jumps as large as the smooth slope over one period, in another direction
    s = rng.standard_normal((T_N, K_N))
    s *= d * np.linalg.norm(a_mat[..., 0], axis=1)[:, None] / np.linalg.norm(s, axis=1)[:, None]

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        lo = local.numpy()  # [M, T, L]
        lin = np.einsum("tkl,mtl->mtk", a_mat, lo)
        steps = np.floor((lo[..., 0] - phase[None]) / d)  # [M, T]
        return torch.as_tensor(lin + s[None] * steps[..., None])

    smooth = a_mat.copy()
    smooth[..., 0] += s / d
    zero = torch.zeros((1, T_N, L_N), dtype=torch.float64)
    r0 = fn(torch.zeros((1, 1)), zero).numpy()[0]
    fwd = np.stack(
        [
            (fn(torch.zeros((1, 1)), zero + torch.as_tensor(H[j] * np.eye(L_N)[j])).numpy()[0] - r0)
            / H[j]
            for j in range(L_N)
        ],
        axis=-1,
    )
    return fn, smooth, fwd


def _err(cols: np.ndarray, smooth: np.ndarray) -> np.ndarray:
    """Sine of the angle between each trajectory's chosen and closed-form first column [T]."""
    return R.sin_angle(cols[..., 0], smooth[..., 0])


# phases: trajectory 0 has an onset within the fitter's forward step, 1 within the backward one,
# 2 and 3 none within one step (there the forward and central-1 columns agree by accident)
PHASES = np.array([0.5, -0.5, 1.5, 2.5]) * H[0]


def test_staircase_closed_form_slope_recovered():
    fn, smooth, fwd = _toy(4.0, PHASES)
    assert np.all(_err(fwd, smooth) > 0.3)  # the fitter's column is wrong on every trajectory
    cols, rec = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, RESID, VALID)
    # 20 and 60 steps hold exactly 5 and 15 onsets: the central columns at 10 and 30 are the
    # closed-form slope, so they agree and 10 is the first of two agreements in a row
    assert rec.stencil[:, 0].tolist() == [10] * T_N
    np.testing.assert_allclose(cols[..., 0], smooth[..., 0], rtol=1e-9, atol=1e-9)
    # the smooth dimensions keep the fitter's column bit for bit
    assert rec.stencil[:, 1:].tolist() == [[0, 0]] * T_N
    assert np.array_equal(cols[..., 1:], fwd[..., 1:])
    # the record: the fitter's roughness against the column chosen
    want = np.linalg.norm(fwd[..., 0] - smooth[..., 0], axis=1) / np.linalg.norm(
        smooth[..., 0], axis=1
    )
    np.testing.assert_allclose(rec.rel_fwd[:, 0], want, rtol=1e-9)
    assert rec.rows == 2 * L_N * len(R.STENCILS)
    d = rec.to_dict()
    assert d["stencil_counts"]["central 10"] == T_N and d["unresolved"] == 0


def _sparse_case():
    """A staircase sparser than the central-3 window (6 steps): onsets every 8.3 steps, with
    trajectories 2 and 3 placed so that none falls within 3 steps of the start pose (there the
    fitter's, central-1 and central-3 columns all agree, and all miss the onsets)."""
    period = 8.3
    phases = np.array([0.5, -0.5, 3.6, -3.4]) * H[0]
    return period, _toy(period, phases, seed=3)


def _sparse_ok(cols: np.ndarray, smooth: np.ndarray, m: np.ndarray) -> bool:
    """The chosen column is the closed form within one onset over its window
    (``||s|| / (2 m h)`` against the slope ``~ ||s|| / D``)."""
    period = _sparse_case()[0]
    rel = np.linalg.norm(cols[..., 0] - smooth[..., 0], axis=1) / np.linalg.norm(
        smooth[..., 0], axis=1
    )
    return bool(np.all(m >= 10) and np.all(rel <= period / (2.0 * np.maximum(m, 1))))


def test_sparse_staircase_within_one_onset():
    _, (fn, smooth, fwd) = _sparse_case()
    central = R.stencil_columns(fn, np.zeros(1), np.zeros((T_N, L_N)))
    # the premise: on trajectories 2 and 3 the three narrow columns agree exactly
    for t in (2, 3):
        np.testing.assert_allclose(fwd[t, :, 0], central[0, t, :, 0], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fwd[t, :, 0], central[1, t, :, 0], rtol=1e-9, atol=1e-12)
    cols, rec = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, RESID, VALID)
    assert _sparse_ok(cols, smooth, rec.stencil[:, 0])
    assert np.all(_err(cols, smooth) < _err(fwd, smooth))


def _smooth_toy(seed: int = 1):
    """A smooth nonlinear residual ``B sin(a / ell + phi)`` with ``ell`` = 10 cm / 1 rad (nearly
    linear over the widest stencil, 3 mm / 30 mrad)."""
    rng = np.random.default_rng(seed)
    b = rng.standard_normal((T_N, K_N, L_N))
    phi = rng.uniform(0, 2 * np.pi, (T_N, K_N, L_N))
    ell = np.array([0.1, 0.1, 1.0])

    def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
        lo = local.numpy()[:, :, None, :]
        return torch.as_tensor(np.sum(b * np.sin(lo / ell + phi), axis=-1))

    fwd = np.stack(
        [
            (np.sin(H[j] / ell[j] + phi[..., j]) - np.sin(phi[..., j])) / H[j] * b[..., j]
            for j in range(L_N)
        ],
        axis=-1,
    )
    exact = b * np.cos(phi) / ell
    return fn, fwd, exact


def test_smooth_residual_keeps_the_fitters_columns():
    fn, fwd, exact = _smooth_toy()
    cols, rec = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, RESID, VALID)
    assert np.all(rec.stencil == 0)
    assert np.array_equal(cols, fwd)
    assert np.all(rec.sin_fwd == 0.0) and np.all(rec.rel_fwd == 0.0)
    # the central columns themselves converge on the exact derivative as the stencil narrows
    central = R.stencil_columns(fn, np.zeros(1), np.zeros((T_N, L_N)))
    err = [np.max(np.abs(central[i] - exact)) for i in range(len(R.STENCILS))]
    assert err == sorted(err) and err[0] < 1e-3 * np.max(np.abs(exact))


def test_tolerance_is_the_datas():
    """A trajectory whose chi^2 is at most 1/2 cannot tell two columns apart (any angle moves
    its profiled chi^2 by under one sigma^2): the fitter's column stays; the staircase's other
    trajectories, at ``chi2_t = 400``, still get the smooth one."""
    fn, smooth, fwd = _toy(4.0, PHASES)
    resid = RESID.copy()
    resid[1] *= 0.7 / 20.0  # chi2 0.49
    cols, rec = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, resid, VALID)
    assert rec.stencil[1, 0] == 0 and np.isinf(rec.tol[1])
    assert np.array_equal(cols[1], fwd[1])
    assert rec.stencil[[0, 2, 3], 0].tolist() == [10, 10, 10]
    np.testing.assert_allclose(rec.tol[0], 1.0 / 800.0)


def test_projection_bound_behind_the_tolerance():
    """The rule's premise: two unit columns at angle theta give profiled residuals that differ
    by at most ``sin(theta) ||r||``, and profiled chi^2 by at most ``2 sin(theta) ||r||^2``
    (brute force over random columns and residuals, and the bound reached)."""
    rng = np.random.default_rng(7)
    for _ in range(200):
        a, b, r = rng.standard_normal((3, 30))
        qa, qb = a / np.linalg.norm(a), b / np.linalg.norm(b)
        pa, pb = r - qa * (qa @ r), r - qb * (qb @ r)
        sin = R.sin_angle(a, b)
        assert np.linalg.norm(pa - pb) <= sin * np.linalg.norm(r) + 1e-12
        assert abs(pa @ pa - pb @ pb) <= 2.0 * sin * (r @ r) + 1e-12
    # the residual bound is attained: r in the plane of a and b, along their bisector's normal
    a, b = np.eye(30)[0], np.cos(0.3) * np.eye(30)[0] + np.sin(0.3) * np.eye(30)[1]
    r = (a + b) / np.linalg.norm(a + b)
    pa, pb = r - a * (a @ r), r - b * (b @ r)
    assert np.linalg.norm(pa - pb) == pytest.approx(np.sin(0.3) * np.linalg.norm(r), rel=1e-9)


def _first_agreeing(fwd, central, resid, valid, run: int):
    """Mutant rules: the first column agreeing with the next ``run`` ones within the residual's
    one-sigma bound ``sin <= 1 / ||r_t||`` (run 1: one agreement; run 2: h48's first rule)."""
    chain = np.concatenate([fwd[None], central], 0)
    sins = R.sin_angle(np.moveaxis(chain[:-1], -1, -2), np.moveaxis(chain[1:], -1, -2))
    ok = sins <= (1.0 / np.linalg.norm(resid, axis=-1))[None, :, None]
    n = chain.shape[0]
    pick = np.full(ok.shape[1:], n - 1)
    for i in range(n - 2, -1, -1):
        good = np.all(ok[i : min(i + run, n - 1)], axis=0)
        pick = np.where(good, i, pick)
    return np.take_along_axis(chain, pick[None, :, None, :], axis=0)[0], pick


@pytest.mark.parametrize("mutant", ["fitter", "one_agreement", "first_rule"])
def test_mutants_caught(monkeypatch, mutant):
    """The staircase assertions fail for a rule that keeps the fitter's column, one that stops
    at the first agreement (F and C_1 agree where no onset is within one step), and h48's first
    rule (the next two columns within ``sin <= 1/||r_t||``: fooled by the sparse staircase)."""
    real = R.choose_columns

    def mutated(fwd_, central, resid, valid, stencils=R.STENCILS):
        rec = real(fwd_, central, resid, valid, stencils)[1]
        if mutant == "fitter":
            return fwd_.copy(), rec
        cols, pick = _first_agreeing(
            fwd_, central, resid, valid, 1 if mutant == "one_agreement" else 2
        )
        rec.stencil = np.asarray([0, *stencils])[pick]
        return cols, rec

    monkeypatch.setattr(R, "choose_columns", mutated)
    fn, smooth, fwd = _toy(4.0, PHASES)
    cols, _ = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, RESID, VALID)
    dense_ok = np.allclose(cols[..., 0], smooth[..., 0], rtol=1e-9, atol=1e-9)
    _, (fn, smooth, fwd) = _sparse_case()
    cols, rec = R.smooth_nuisance(fn, np.zeros(1), np.zeros((T_N, L_N)), fwd, RESID, VALID)
    assert not (dense_ok and _sparse_ok(cols, smooth, rec.stencil[:, 0]))


def test_bad_input_named():
    fn, smooth, fwd = _toy(4.0, PHASES)
    with pytest.raises(ValueError, match="local_h has 2 steps for 3 nuisance dimensions"):
        R.stencil_columns(fn, np.zeros(1), np.zeros((T_N, L_N)), local_h=(1e-4, 1e-4))
    with pytest.raises(ValueError, match="do not match"):
        R.choose_columns(fwd, np.zeros((2, T_N, K_N, L_N)), RESID, VALID)


def test_planar_gate_unchanged_with_smooth_columns(monkeypatch, tmp_path):
    """Design B on the planar engine: its 0.1 mm columns are nearly smooth (h47: ``||F - C_30||
    / ||C_30|| <= 0.04``), not to the chi^2 precision of the rule, so some are replaced; the
    thresholds stay within 1 % of the flag-off ones (seed 1 offline: tilt 51.82 -> 51.62) and
    the record says which stencils were taken. (Not every planar design is that smooth: on
    design A the planar columns of a 6-push scenario turn by 0.1-0.3 rad within 10 steps.)
    The flag is the wild null's (``both``): the default parametric null always takes the smooth
    columns (``roughness.smooth_for``, h99)."""
    from robogs.physics.diagnose import GATE_METHOD_ENV, diagnose_recording
    from robogs.synth.scenarios.design_b import make_design_b

    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv(GATE_METHOD_ENV, "both")
    rec = make_design_b("none", seed=1)
    cands = ["table_tilt", "anisotropic_friction", "time_offset"]
    res = {}
    for flag in (False, True):
        monkeypatch.setattr(R, "SMOOTH_NUISANCE", flag)
        res[flag] = diagnose_recording(rec, effects=cands)
    assert "nuisance_columns" not in res[False].gate
    cols = res[True].gate["nuisance_columns"]
    assert sorted(cols) == sorted(cands)
    for name, d in cols.items():
        assert sum(d["stencil_counts"].values()) == 9 * 3, name
        assert d["max_rel_fwd"] < 0.1 and d["rows"] == 2 * 3 * len(R.STENCILS)
    thr = {f: {r.name: r.null_threshold_sigma2 for r in res[f].rows} for f in res}
    for name in cands:
        assert thr[True][name] == pytest.approx(thr[False][name], rel=1e-2), name
    assert [r.name for r in res[True].rows if r.reported] == []
    assert res[True].gate["key"] != res[False].gate["key"]  # cached apart

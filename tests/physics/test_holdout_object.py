"""``--holdout`` for the object model (issue 17, Deliver 5): the named trajectories are one
held-out fold for fit's held-out error, diagnose's statistic and the gate's simulated null.

Oracles: (1) on a linear model one Gauss-Newton step from the full fit on the training
trajectories *is* the least-squares fit on them, so the held-out RMS must equal a brute-force
"fit on the others, predict the held-out, RMS" (numpy lstsq) to 1e-9; (2) ``fit --holdout`` on a
generated dataset prints the RMS of the bounded step recomputed by hand (lstsq on the training
rows of the full fit, one rollout at those parameters, RMS over the held-out samples); (3) the
null the gate is calibrated on is simulated for the held-out fold (the folds reaching
``gate.calibrate`` are that fold, and its thresholds differ from the default folds'), and on
fresh linear null data the gate keeps its 5 % family-wise size with the held-out fold; (4) a
held-out set on which an effect moves nothing leaves its gate uncalibrated and is refused.
"""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
from physics_scenarios import scenario

from robogs.format.errors import InputError
from robogs.physics import gate
from robogs.physics.api import _heldout_resid
from robogs.physics.diagnose import unjudged_on_holdout
from robogs.physics.fit import FitOutcome
from robogs.physics.heldout import holdout_folds, split_tag, trajectory_folds

NAMES = [f"push_{i}" for i in range(6)]


# --------------------------------------------------------------------------- names


def test_holdout_names_choose_one_fold_and_bad_choices_are_refused():
    (m,) = holdout_folds(NAMES, ["push_1", "push_4"])
    assert m.tolist() == [False, True, False, False, True, False]
    assert split_tag([m]) == "|holdout:010010"
    assert split_tag(trajectory_folds(6)) == ""  # the default folds keep their cache key
    assert all(
        np.array_equal(a, b)
        for a, b in zip(holdout_folds(NAMES, None), trajectory_folds(6), strict=True)
    )
    # an episode cut into pieces holds out all of them, and only them
    (m,) = holdout_folds(["s#0", "s#1", "s2#0", "t"], ["s"])
    assert m.tolist() == [True, True, False, False]
    with pytest.raises(InputError, match="no trajectory named 'nope'") as e:
        holdout_folds(NAMES, ["push_0", "nope"])
    assert "push_0, push_1, push_2, push_3, push_4, push_5" in e.value.hint
    with pytest.raises(InputError, match="holds out all 6 trajectories"):
        holdout_folds(NAMES, NAMES)
    with pytest.raises(InputError, match="names no trajectory"):
        holdout_folds(NAMES, [" ", ""])
    with pytest.raises(InputError, match="at least two trajectories"):
        holdout_folds(["only"], ["only"])


# --------------------------------------------------------------------------- linear oracle


class _LinearEngine:
    """``r_t(theta) = (y_t - A_t theta) / sigma`` per trajectory: 2 pose samples (x, y, z, yaw)
    per trajectory, positions in m, with a fixed per-sample sigma."""

    def __init__(self, a: np.ndarray, y: np.ndarray, sig: np.ndarray, mask: np.ndarray):
        self.a, self.y, self.sig, self.mask = a, y, sig, mask
        n_t = a.shape[0]
        names = [f"tr{t}" for t in range(n_t)]
        self.prep = SimpleNamespace(
            n_traj=n_t, rec=SimpleNamespace(trajectories=[SimpleNamespace(name=n) for n in names])
        )

    def resid(self, theta: np.ndarray) -> np.ndarray:
        return (self.y - np.einsum("tcp,p->tc", self.a, theta)) / self.sig

    def evaluate(self, space, thetas, locals_):
        return np.stack([self.resid(th) for th in thetas])

    def raw(self, weighted: np.ndarray) -> np.ndarray:
        r = weighted * self.sig
        return r.reshape(*r.shape[:-1], -1, 4)


def test_heldout_rms_equals_fit_on_the_others_for_a_linear_model():
    rng = np.random.default_rng(3)
    n_t, n_s, p = 6, 9, 3  # trajectories, pose samples each, parameters
    c = 4 * n_s
    a = rng.normal(size=(n_t, c, p)) * 0.01
    theta_true = np.array([0.3, -0.2, 0.5])
    sig = np.full((n_t, c), 1e-3)
    y = np.einsum("tcp,p->tc", a, theta_true) + rng.normal(size=(n_t, c)) * 1e-3
    y[2] += 0.004 * np.sin(np.arange(c))  # one trajectory the model does not fit well
    mask = np.ones((n_t, n_s), dtype=bool)
    mask[1, -2:] = False  # samples a trajectory lacks: zero residual rows, left out of the RMS
    y[1].reshape(n_s, 4)[-2:] = 0.0
    a[1].reshape(n_s, 4, p)[-2:] = 0.0
    eng = _LinearEngine(a, y, sig, mask)
    # the full fit on every trajectory, as the fitter leaves it
    theta = np.linalg.lstsq((a / sig[..., None]).reshape(-1, p), (y / sig).reshape(-1), rcond=None)[
        0
    ]
    r = eng.resid(theta)
    out = FitOutcome(
        theta=theta,
        local=np.zeros((n_t, 3)),
        cost=float(np.sum(r**2)),
        n=r.size,
        resid=r,
        jac=-a / sig[..., None],
        jac_local=np.zeros((n_t, c, 3)),
    )
    space = SimpleNamespace(lower=np.full(p, -10.0), upper=np.full(p, 10.0))
    for held in (["tr1"], ["tr2", "tr5"]):
        (h,), split, hm = _heldout_resid(eng, space, [out], [list(range(p))], held)
        keep = np.array([f"tr{t}" not in held for t in range(n_t)])
        # brute force: fit on the others, predict the held-out ones, RMS over their samples
        th_o = np.linalg.lstsq(
            (a[keep] / sig[keep][..., None]).reshape(-1, p),
            (y[keep] / sig[keep]).reshape(-1),
            rcond=None,
        )[0]
        err = (y - np.einsum("tcp,p->tc", a, th_o)).reshape(n_t, n_s, 4)[..., :3]
        sel = mask & ~keep[:, None]
        rms = np.sqrt(np.mean(np.sum(err[sel] ** 2, axis=-1))) * 1000.0
        from robogs.physics.engine import rms_mm

        assert rms_mm(eng.raw(h), hm) == pytest.approx(rms, rel=0, abs=1e-9)
        assert np.all(h[keep] == 0.0) and split.startswith("held out: " + ", ".join(held))
        assert hm.sum() == sel.sum()


# --------------------------------------------------------------------------- the gate's null


def _toy(rng, n_t=10, k=40, zero_on=None):
    """Linear base (one column) + candidate (one column) per trajectory, nuisance: an offset."""
    s = np.linspace(0.0, 1.0, k)
    jb = np.tile(s, (n_t, 1))[..., None] * (1 + 0.3 * rng.standard_normal((n_t, 1, 1)))
    je = (np.tile(s**2, (n_t, 1)) * (1 + 0.3 * rng.standard_normal((n_t, 1))))[..., None]
    if zero_on is not None:
        je[zero_on] = 0.0  # the candidate moves nothing on these trajectories
    jl = np.ones((n_t, k, 1))
    return gate.LinearCandidate("cand", np.concatenate([jb, je], -1), jl, 1)


def test_linear_gate_keeps_its_size_with_a_held_out_fold():
    """Fresh linear nulls (white noise, sigma 1): the held-out fall beats the threshold
    calibrated for the held-out fold in about 5 % of them."""
    rng = np.random.default_rng(11)
    cand = _toy(rng)
    n_t, k = cand.jac.shape[:2]
    valid = np.ones((n_t, k), dtype=bool)
    folds = holdout_folds([f"t{i}" for i in range(n_t)], ["t0", "t3", "t7"])
    base = rng.standard_normal((n_t, k))
    cal = gate.calibrate([cand], base, valid, folds, method="white", draws=400, seed=1)
    cal_def = gate.calibrate(
        [cand], base, valid, trajectory_folds(n_t), method="white", draws=400, seed=1
    )
    assert abs(cal.thresholds["cand"] - cal_def.thresholds["cand"]) > 0.1  # the split matters
    fresh = rng.standard_normal((3000, n_t, k))
    q = gate._profile(cand.jac_local, valid)
    r_b, h_b = gate._linear_heldout(cand.jac[..., :1], q, fresh, folds)
    r_c, h_c = gate._linear_heldout(cand.jac, q, fresh, folds)
    stat = gate.heldout_statistic(h_b, h_c, r_b - r_c)
    rate = float(np.mean(stat > cal.thresholds["cand"]))
    assert 0.05 - 3 * 0.004 < rate < 0.05 + 3 * 0.004  # binomial sd at 3000 draws: 0.004


def test_an_effect_acting_on_no_held_out_trajectory_is_refused():
    """The gate's statistic sums over the held-out trajectories an effect acts on (z_t >= 3):
    an effect that acts only on training trajectories has statistic 0 on the data whatever its
    size, so the choice is refused; the default folds hold every trajectory out once."""
    z = np.array([0.0, 0.1, 0.0, 5.9, 11.6, 17.8])  # a restitution seen in three drops
    held = np.array([True, False, False, False, False, False])
    assert unjudged_on_holdout(z, held) == (3, 17.8)
    assert unjudged_on_holdout(z, held | (np.arange(6) == 4)) is None  # a drop held out
    assert unjudged_on_holdout(z, np.ones(6, dtype=bool)) is None  # default folds: all held
    assert unjudged_on_holdout(np.full(6, 2.9), held) is None  # acts on none: nothing to miss
    # the statistic it protects: 0 on the data when no acted-on trajectory is held out
    held_b = np.where(held, 40.0, 0.0)  # held-out chi^2 per trajectory, base
    held_e = np.where(held, 38.0, 0.0)
    delta = np.zeros((6, 4))
    delta[:, 0] = z
    assert gate.heldout_statistic(held_b, held_e, delta) == 0.0


# --------------------------------------------------------------------------- end to end


@pytest.fixture(scope="module")
def tilt_ds(tmp_path_factory):
    from robogs.synth.scenarios import write_scenario

    ds = tmp_path_factory.mktemp("holdout") / "ds"
    write_scenario(scenario("table_tilt"), ds)
    return ds


def _cli(capsys, *argv):
    from robogs.cli.main import main

    capsys.readouterr()
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_fit_holdout_prints_the_recomputed_heldout_rms(tilt_ds, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    held = ["push_d0_v0", "push_d1_v1"]
    rc, out, err = _cli(
        capsys, "fit", str(tilt_ds), "--add", "table_tilt", "--dry-run", "--json",
        "--mask-frames", "0", "--holdout", ",".join(held),
    )  # fmt: skip
    assert rc == 0, err
    d = json.loads(out)
    assert d["heldout_split"] == f"held out: {', '.join(held)} (2 of 6 trajectories)"
    # recompute by hand: the joint fit, the step on the training rows by plain least squares
    # (the bounds are not reached), one rollout, the RMS over the held-out samples
    from robogs.format import Dataset
    from robogs.physics.api import _joint_fit
    from robogs.physics.baseline import baseline
    from robogs.physics.engine import Engine
    from robogs.physics.recording import load_recording

    rec = load_recording(Dataset.open(tilt_ds))
    eng = Engine(rec)
    cands = eng.check_effects(["table_tilt"])
    space = eng.space(cands)
    base_out, out_j, base_cols, free = _joint_fit(
        eng, space, cands, baseline(rec, engine=eng), None
    )
    names = [t.name for t in rec.trajectories]
    hold = np.array([n in held for n in names])
    for key, o, cols in (("before", base_out, base_cols), ("after", out_j, free)):
        j = o.jac[~hold].reshape(-1, len(cols))
        step = np.linalg.lstsq(j, -o.resid[~hold].reshape(-1), rcond=None)[0]
        th = o.theta.copy()
        th[cols] += step
        assert np.all((th[cols] > space.lower[cols]) & (th[cols] < space.upper[cols]))
        r = eng.evaluate(space, th[None], o.local[None])[0]
        assert np.sum(r[~hold] ** 2) <= np.sum(o.resid[~hold] ** 2)  # no halving
        raw = eng.raw(r)[..., :3]
        sel = eng.mask & hold[:, None]
        rms = float(np.sqrt(np.mean(np.sum(raw[sel] ** 2, axis=-1))) * 1000.0)
        assert d[f"heldout_rms_{key}_mm"] == pytest.approx(rms, rel=0, abs=1e-9)
        assert d[f"heldout_chi2_{key}"] == pytest.approx(float(np.sum(r[hold] ** 2)), rel=1e-12)
    # the text output prints the same numbers, named
    rc, out, _ = _cli(
        capsys, "fit", str(tilt_ds), "--add", "table_tilt", "--dry-run", "--mask-frames", "0",
        "--holdout", ",".join(held),
    )  # fmt: skip
    assert rc == 0
    line = next(ln for ln in out.splitlines() if ln.startswith("held-out position RMS"))
    assert f"{d['heldout_rms_before_mm']:.3f} → {d['heldout_rms_after_mm']:.3f} mm" in line
    assert "held out: push_d0_v0, push_d1_v1" in line


def test_diagnose_holdout_calibrates_the_gate_on_that_split(tilt_ds, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    seen = []
    real = gate.calibrate

    def spy(cands, base_resid, valid, folds, **kw):
        seen.append([np.asarray(f).copy() for f in folds])
        return real(cands, base_resid, valid, folds, **kw)

    monkeypatch.setattr(gate, "calibrate", spy)
    effects = "table_tilt,time_offset"
    rc, out, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--effects", effects, "--json", "--mask-frames", "0",
        "--holdout", "push_d2_v1",
    )  # fmt: skip
    assert rc == 0, err
    held = json.loads(out)
    rc, out, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--effects", effects, "--json", "--mask-frames", "0"
    )
    assert rc == 0, err
    dflt = json.loads(out)
    assert [m.tolist() for m in seen[0]] == [[False] * 5 + [True]]  # the statistic's fold
    assert len(seen[1]) == 5
    assert held["design"]["split"] == "held out: push_d2_v1 (1 of 6 trajectories)"
    assert held["design"]["holdout"] == ["push_d2_v1"]
    thr_h = {e["name"]: e["null_threshold_sigma2"] for e in held["effects"]}
    thr_d = {e["name"]: e["null_threshold_sigma2"] for e in dflt["effects"]}
    for name in ("table_tilt", "time_offset"):
        assert abs(thr_h[name] - thr_d[name]) > 0.05 * thr_d[name], name
    # the held-out RMS is the held-out trajectory's only: compare --holdout gives the same
    # base value for the same model
    rc, out, err = _cli(
        capsys, "compare", str(tilt_ds), "--json", "--mask-frames", "0", "--holdout",
        "push_d2_v1",
    )  # fmt: skip
    assert rc == 0, err
    cmp = json.loads(out)["heldout"]
    base = {e["heldout_rms_before"] for e in held["effects"]}
    assert len(base) == 1 and cmp["heldout_rms_mm"] == pytest.approx(base.pop(), abs=1e-9)


def test_a_holdout_the_effect_does_not_act_on_exits_2_before_the_null(
    tilt_ds, capsys, monkeypatch, tmp_path
):
    """Wiring of :func:`unjudged_on_holdout` on real fits, with the gate's "acts on" level
    raised from 3 to 5 sigma (a mutated constant): the tilt then acts on 5 of the 6 pushes (its
    whitened change per push is 4.2 sigma on push_d1_v0 and 6-14 on the others); holding out
    push_d1_v0 is refused before any null is simulated, holding out push_d0_v0 is not."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(gate, "AFFECTED_Z", 5.0)
    calls = []

    class Reached(Exception):
        pass

    def stub(*a, **k):
        calls.append(1)
        raise Reached

    monkeypatch.setattr(gate, "calibrate", stub)
    rc, _, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--effects", "table_tilt", "--no-progress",
        "--mask-frames", "0", "--holdout", "push_d1_v0",
    )  # fmt: skip
    assert rc == 2 and not calls, err
    assert re.search(
        r"too small for the gate: table_tilt moves 5 trajectories by >= 5 sigma \(up to "
        r"[\d.]+\), none of them held out",
        err,
    ), err
    with pytest.raises(Reached):  # passes the check, reaches the (stubbed) calibration
        from robogs.physics.api import diagnose

        diagnose(tilt_ds, effects=["table_tilt"], mask_frames=0, holdout=["push_d0_v0"])
    assert calls == [1]


def test_bad_holdout_names_exit_2_with_the_valid_names(tilt_ds, capsys):
    rc, out, err = _cli(capsys, "fit", str(tilt_ds), "--dry-run", "--holdout", "push_d0_v0,nope")
    assert rc == 2
    assert "no trajectory named 'nope'" in err and "push_d2_v1" in err
    rc, _, err = _cli(
        capsys, "diagnose", str(tilt_ds), "--holdout",
        "push_d0_v0,push_d0_v1,push_d1_v0,push_d1_v1,push_d2_v0,push_d2_v1",
    )  # fmt: skip
    assert rc == 2 and "holds out all 6 trajectories" in err

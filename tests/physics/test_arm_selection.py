"""Forward selection of the arm effects: look-alikes of an accepted effect are not reported.

Oracles: the hidden effects (and their parameters) the synthetic logs were generated with by
the independent inverse dynamics of :mod:`robogs.synth.armlogs`; for the null of the nested
held-out test, brute-force least squares per fold.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.physics.arm import diagnose_arm
from robogs.physics.arm.diagnose import _held_sse
from robogs.synth.armlogs import ArmLogSpec, generate_armlog


def _diagnose(root: Path, urdf: Path, effect: str, seed: int) -> tuple[dict, dict]:
    truth = generate_armlog(
        root / "logs", urdf, ArmLogSpec(effect=effect, seed=seed, segments=4, duration_s=4.0)
    )
    convert_path(root / "logs", root / "ds", fmt="tabular", options=ConvertOptions(urdf=urdf))
    return diagnose_arm(root / "ds"), truth


def _rel_errors(rows: dict, truth: dict, joints: list[str]) -> dict[str, float]:
    err: dict[str, float] = {}
    if "payload" in rows:
        p = {k: v["value"] for k, v in rows["payload"]["params"].items()}
        c = np.asarray(truth["com"])
        err["mass"] = abs(p["mass"] - truth["mass"]) / truth["mass"]
        err["com"] = float(np.linalg.norm([p["cx"], p["cy"], p["cz"]] - c) / np.linalg.norm(c))
    if "joint_friction" in rows:
        p = {k: v["value"] for k, v in rows["joint_friction"]["params"].items()}
        for n in ("fc", "fv"):
            for i, j in enumerate(joints):
                err[f"{n}.{j}"] = abs(p[f"{n}.{j}"] - truth[n][i]) / truth[n][i]
    return err


def test_hidden_payload_alone_reports_exactly_the_payload(tmp_path, ur5):
    rep, truth = _diagnose(tmp_path, ur5, "payload", seed=5)
    reported = [r["name"] for r in rep["effects"] if r["reported"]]
    assert rep["selected"] == ["payload"] and reported == ["payload"]
    rows = {r["name"]: r for r in rep["effects"]}
    # look-alikes pass the gate against the bare model, but not once the payload is in it
    first = rep["steps"][0]["candidates_passing"]
    assert {"payload", "mass_scale"} <= set(first)
    for name in set(first) - {"payload"}:
        assert rows[name]["given"] == ["payload"]
        assert rows[name]["reasons"][0].startswith("passes alone, explained by payload")
    errs = _rel_errors({"payload": rows["payload"]}, truth["params"], truth["joints"])
    assert len(errs) == 2 and max(errs.values()) < 0.10, errs


def test_payload_and_friction_hidden_together_are_both_reported(tmp_path, ur5):
    rep, truth = _diagnose(tmp_path, ur5, "payload+joint_friction", seed=7)
    assert truth["effects"] == ["payload", "joint_friction"]
    assert sorted(rep["selected"]) == ["joint_friction", "payload"]
    reported = [r["name"] for r in rep["effects"] if r["reported"]]
    assert reported == rep["selected"]  # accepted rows first, in order
    s1, s2 = rep["steps"]
    assert s1["given"] == [] and s2["given"] == [s1["added"]]
    assert s2["delta_bic"] <= -10
    rows = {r["name"]: r for r in rep["effects"]}
    for r in rep["effects"][2:]:
        assert r["given"] == rep["selected"] and not r["reported"]
    errs = _rel_errors({n: rows[n] for n in rep["selected"]}, truth["params"], truth["joints"])
    assert len(errs) == 2 + 12 and max(errs.values()) < 0.10, errs


def test_null_log_selects_nothing(tmp_path, ur5):
    rep, _ = _diagnose(tmp_path, ur5, "none", seed=9)
    assert rep["selected"] == [] and rep["steps"] == []
    assert not any(r["reported"] for r in rep["effects"])
    assert all(r["given"] == [] for r in rep["effects"])


def test_nested_null_held_out_sse_matches_brute_force_least_squares():
    rng = np.random.default_rng(0)
    n, d = 120, 7
    jac = rng.standard_normal((n, 3))
    noise = rng.standard_normal((n, d))
    folds = [np.arange(0, 40), np.arange(40, 90), np.arange(90, 120)]
    brute = np.zeros(d)
    for rows in folds:
        train = np.setdiff1d(np.arange(n), rows)
        coef = np.linalg.lstsq(jac[train], noise[train], rcond=None)[0]
        brute += ((noise[rows] - jac[rows] @ coef) ** 2).sum(0)
    np.testing.assert_allclose(_held_sse(jac, noise, folds), brute, rtol=1e-10)
    empty = _held_sse(jac[:, :0], noise, folds)
    np.testing.assert_allclose(empty, (noise**2).sum(0), rtol=1e-12)

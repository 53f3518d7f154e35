"""The arm loop converges: stacked bodies, joint refits, an auto loop that stops.

Oracles: the synthetic logs of :mod:`robogs.synth.armlogs` (inverse dynamics independent of the
model) generated with a URDF whose last link is ``d`` kg heavier than the dataset's URDF (the
distal-mass error, stored as a correction) plus a hidden payload of ``m`` kg; a fit of the
payload must report ``m``, not ``m + d``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format.dataset import Dataset
from robogs.physics.arm import diagnose_arm, fit_arm
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf

LAST = "wrist_3_link"
NOMINAL = (0.2, 0.2, 0.15, 0.05, 0.05, 0.05)
"""The generator's nominal effort noise, N m per joint (the tests also run 4x)."""


def _heavier_last_link(d: float) -> tuple[str, list[float]]:
    """The UR5 URDF with ``d`` kg more on the last link at its CoM, and that CoM (link frame)."""
    text = ur5_urdf()
    pat = re.compile(
        rf'(<link name="{LAST}"><inertial><mass value=")([^"]+)("/><origin xyz=")([^"]+)(")'
    )
    m = pat.search(text)
    assert m is not None
    com = [float(v) for v in m.group(4).split()]
    new = f"{m.group(1)}{float(m.group(2)) + d:.10g}{m.group(3)}{m.group(4)}{m.group(5)}"
    return text[: m.start()] + new + text[m.end() :], com


def _dataset(root: Path, urdf: Path, d: float, m: float, seed: int, scale: float = 1.0) -> Path:
    true_text, com = _heavier_last_link(d)
    true_urdf = root / "true.urdf"
    true_urdf.write_text(true_text)
    spec = ArmLogSpec(
        effect="payload",
        seed=seed,
        segments=4,
        duration_s=4.0,
        params={"mass": m, "com": [0.0, 0.03, 0.08]},
        effort_noise=tuple(scale * s for s in NOMINAL),
    )
    generate_armlog(root / "logs", true_urdf, spec)
    ds = root / "ds"
    convert_path(root / "logs", ds, fmt="tabular", options=ConvertOptions(urdf=urdf))
    d_ = Dataset.open(ds)
    try:
        doc = dict(d_.physics())
    except Exception:  # no physics.json yet
        doc = {"revision": 0, "objects": {}, "gravity_mps2": [0.0, 0.0, -9.81]}
    doc.pop("parent_revision", None)
    doc["distal_mass"] = {"link": LAST, "mass_kg": d, "com_m": com}
    with d_.edit() as w:
        w.set_physics(doc, note="distal-mass correction (test oracle)")
        w.commit()
    return ds


@pytest.mark.parametrize("scale", [1.0, 4.0])
@pytest.mark.parametrize("d", [0.6, 2.5])
def test_payload_is_reported_in_kg_whatever_distal_correction_is_stored(tmp_path, ur5, d, scale):
    m = 1.8
    ds = _dataset(tmp_path, ur5, d=d, m=m, seed=3, scale=scale)
    # diagnose (the loop run to its end) with the correction stored reports the payload alone
    rep = diagnose_arm(ds)
    assert rep["selected"] == ["payload"] and len(rep["steps"]) <= 5
    rows = {r["name"]: r for r in rep["effects"]}
    assert "distal_mass" not in rows  # a model correction, not a candidate
    assert abs(rows["payload"]["params"]["mass"]["value"] - m) / m < 0.05
    out = fit_arm(ds, ["payload"])
    assert "distal_mass" in out["held"] and "distal_mass" not in out["refitted"]
    mass = out["params"]["payload"]["mass"]["value"]
    assert abs(mass - m) / m < 0.05, (mass, m, d)
    phys = Dataset.open(ds).physics()
    assert phys["distal_mass"]["mass_kg"] == pytest.approx(d)  # the correction is kept
    assert phys["payload"]["mass_kg"] == pytest.approx(mass)
    # and the stored bodies now explain the data: the loop selects nothing more
    assert diagnose_arm(ds)["selected"] == []


def test_fit_add_refits_stored_effects_jointly_as_diagnose_scores_them(tmp_path, ur5):
    """Payload then friction, one ``fit --add`` each: the second refits the payload too, and
    the values equal those of one joint fit of both (what diagnose reports at step 2)."""
    generate_armlog(
        tmp_path / "logs",
        ur5,
        ArmLogSpec(effect="payload+joint_friction", seed=7, segments=4, duration_s=4.0),
    )
    ds = tmp_path / "ds"
    convert_path(tmp_path / "logs", ds, fmt="tabular", options=ConvertOptions(urdf=ur5))
    joint = fit_arm(ds, ["payload", "joint_friction"], write=False)
    first = fit_arm(ds, ["payload"])
    second = fit_arm(ds, ["joint_friction"])
    assert second["refitted"] == ["payload"]
    for eff in ("payload", "joint_friction"):
        for k, v in joint["params"][eff].items():
            got = second["params"][eff][k]["value"]
            assert got == pytest.approx(v["value"], rel=1e-3, abs=1e-6), (eff, k)
    # the frozen payload of the first fit differs from the joint one (friction was missing)
    d1 = first["params"]["payload"]["mass"]["value"]
    d2 = second["params"]["payload"]["mass"]["value"]
    assert not np.isclose(d1, d2, rtol=1e-4)


def _log(root: Path, urdf: Path, effect: str, seed: int, scale: float) -> Path:
    spec = ArmLogSpec(
        effect=effect,
        seed=seed,
        segments=4,
        duration_s=4.0,
        effort_noise=tuple(scale * s for s in NOMINAL),
    )
    generate_armlog(root / "logs", urdf, spec)
    convert_path(root / "logs", root / "ds", fmt="tabular", options=ConvertOptions(urdf=urdf))
    return root / "ds"


@pytest.mark.parametrize("scale", [1.0, 4.0])
@pytest.mark.parametrize("effect", ["none", "payload+joint_friction"])
def test_no_time_offset_reported_when_none_is_hidden(tmp_path, ur5, effect, scale):
    """Both noise levels (nominal and 4x): the held-out gain of a time offset stays under the
    null quantile, and the loop stops within 5 steps with exactly the hidden effects."""
    for seed in (11, 12):
        rep = diagnose_arm(_log(tmp_path / f"{seed}", ur5, effect, seed, scale))
        assert "effort_time_offset" not in rep["selected"], rep["steps"]
        assert sorted(rep["selected"]) == sorted(e for e in effect.split("+") if e != "none")
        assert len(rep["steps"]) <= 5
        row = {r["name"]: r for r in rep["effects"]}["effort_time_offset"]
        assert row["heldout_gain_sigma2"] <= max(row["null_gain_p95_sigma2"], 0.0) or any(
            "dBIC" in r for r in row["reasons"]
        )


def test_a_hidden_time_offset_is_reported_at_both_noise_levels(tmp_path, ur5):
    """The mutation that must be caught: 8 ms of effort lag (generator default)."""
    for scale in (1.0, 4.0):
        rep = diagnose_arm(_log(tmp_path / f"{scale}", ur5, "effort_time_offset", 13, scale))
        assert rep["selected"] == ["effort_time_offset"]
        delta = rep["effects"][0]["params"]["delta"]["value"]
        assert abs(delta - 0.008) < 0.001, delta


def test_diagnose_auto_prints_the_path_and_stops(tmp_path, ur5, capsys):
    """``robogs diagnose --auto``: one row per accepted effect (the hidden ones), then the stop
    row naming the null quantile the best remaining candidate failed; at most 5 steps."""
    import json

    from robogs.cli.main import main

    ds = _log(tmp_path, ur5, "payload+joint_friction", 7, 1.0)
    assert main(["diagnose", str(ds), "--auto", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    added = [r["effect"] for r in d["path"] if r["verdict"] == "added"]
    assert sorted(added) == ["joint_friction", "payload"] and len(added) <= 5
    stop = [r for r in d["path"] if r["step"] is None]
    assert len(stop) == 1 and stop[0]["verdict"].startswith("stop:")
    assert stop[0]["heldout_gain_sigma2"] <= stop[0]["null_quantile_sigma2"] or any(
        "dBIC" in x for x in stop[0]["verdict"].split(";")
    )
    for r in d["path"][:2]:
        assert r["heldout_gain_sigma2"] > r["null_quantile_sigma2"] > 0
        assert r["heldout_after"] < r["heldout_before"]
    assert main(["diagnose", str(ds), "--auto"]) == 0
    text = capsys.readouterr().out
    assert "selection path" in text and "loop stopped after 2 step(s)" in text


def test_fit_prints_held_out_error(tmp_path, ur5):
    """``fit`` reports held-out RMS per joint. Oracle: each fold refitted on its own (one fit per
    fold, not batched) and its residual taken on the units it did not see; and the held-out RMS
    is no lower than the in-sample one and far below the base model's for a real payload."""
    from robogs.physics.arm.api import open_arm
    from robogs.physics.arm.diagnose import unit_folds
    from robogs.physics.arm.identify import fit_many, unit_layout

    ds = _log(tmp_path, ur5, "payload", 5, 1.0)
    out = fit_arm(ds, ["payload"], write=False)
    s = open_arm(ds)
    pb = s.problem
    sig = pb.sigma.cpu().numpy()
    layout = unit_layout(pb)
    held = np.zeros((pb.n, len(sig)))
    for f in unit_folds(layout):
        keep = ~np.isin(np.arange(layout.n_units), f)
        one = fit_many(pb, [["payload"]], fixed=s.fixed, masks=[keep], layout=layout)[0]
        rows = np.isin(layout.unit, f)
        held[rows] = one.resid[rows] * sig
    for k, j in enumerate(pb.data.joint_names):
        want = float(np.sqrt(np.mean(held[:, k] ** 2)))
        got = out["heldout_rms_after_nm"][j]
        assert got == pytest.approx(want, rel=1e-3)
        assert got >= out["rms_after_nm"][j] * 0.999
    assert sum(out["heldout_rms_after_nm"].values()) < 0.5 * sum(out["rms_before_nm"].values())


def test_holdout_names_the_trajectories_held_out(tmp_path, ur5, capsys):
    """``--holdout TRAJ``: the held-out error is that of the fit on the other trajectories,
    evaluated on TRAJ alone (brute-force oracle); diagnose judges on the same split; an unknown
    name is one line naming the known ones."""
    from robogs.cli.main import main
    from robogs.format.errors import InputError
    from robogs.physics.arm.api import open_arm
    from robogs.physics.arm.identify import fit_many, unit_layout

    ds = _log(tmp_path, ur5, "payload", 5, 1.0)
    s = open_arm(ds)
    pb = s.problem
    names = list(pb.data.traj_names)
    held_out = names[1]
    out = fit_arm(ds, ["payload"], write=False, holdout=[held_out])
    assert out["heldout_split"].endswith(f"held out: {held_out}")
    layout = unit_layout(pb)
    keep = np.ones(layout.n_units, bool)
    keep[1] = False
    one = fit_many(pb, [["payload"]], fixed=s.fixed, masks=[keep], layout=layout)[0]
    rows = layout.unit == 1
    sig = pb.sigma.cpu().numpy()
    for k, j in enumerate(pb.data.joint_names):
        want = float(np.sqrt(np.mean((one.resid[rows, k] * sig[k]) ** 2)))
        assert out["heldout_rms_after_nm"][j] == pytest.approx(want, rel=1e-3)
    rep = diagnose_arm(ds, holdout=[held_out])
    assert rep["selected"] == ["payload"] and f"held out: {held_out}" in rep["split"]
    with pytest.raises(InputError, match="no trajectory named nope"):
        fit_arm(ds, ["payload"], write=False, holdout=["nope"])
    assert main(["fit", str(ds), "--add", "payload", "--dry-run", "--holdout", "nope"]) != 0
    err = capsys.readouterr().err
    assert "no trajectory named nope" in err and "Traceback" not in err

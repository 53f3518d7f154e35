"""Check G008 with fitted kinematic offsets: the physics module's kinematic model and the core
library's offset chain agree; a dataset recorded on a robot with hidden joint offsets fails
G008, passes after ``robogs fit --add kinematic_offsets``, and fails again when the offsets in
physics.json are wrong.

Oracles: the hidden offsets and noise of :mod:`robogs.synth.armlogs.kinematic` (its own numpy
forward kinematics); with the true offsets the G008 error is the pose noise alone (0.2 mm per
axis: the length of a 3-D normal vector, median 0.2 * 1.538 mm).
"""

from __future__ import annotations

import json

import numpy as np
import torch

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.format.kinematics import Chain, chain_with_offsets, read_joint_offsets
from robogs.format.urdf import load_urdf
from robogs.format.validate import validate
from robogs.physics.arm.api import open_arm
from robogs.physics.arm.kinematic_model import predict_ee
from robogs.physics.space import ParamSpace
from robogs.synth.armlogs import KinLogSpec, generate_kinematic_dataset

SMALL = {"segments": 3, "duration_s": 4.0, "ee_rate_hz": 40.0}
MEDIAN_NOISE_MM = 0.2 * 1.5382
"""Median length of a 3-D normal vector of 0.2 mm per axis (chi distribution, 3 dof)."""


def _g008(ds, budget: float | None = None) -> list:
    budgets = None if budget is None else {"geometry.fk_ee_mm": budget}
    return [f for f in validate(ds, select=["G008"], budgets=budgets).findings if f.code == "G008"]


def _set_offsets(ds, offsets: dict[str, dict[str, float]], extra: dict | None = None) -> None:
    d = Dataset.open(ds)
    doc = json.loads(json.dumps(d.physics()))
    joints = doc.setdefault("joints", {})
    for j, off in offsets.items():
        joints.setdefault(j, {})["offsets"] = off
        joints[j].update(extra or {})
    with d.edit() as w:
        w.set_physics(doc, note="test")
        w.commit()


def _truth_offsets(truth: dict, sign: float = 1.0) -> dict[str, dict[str, float]]:
    p = truth["params"]
    return {
        j: {
            "dtheta_rad": sign * p["dtheta"][i],
            "dd_m": sign * p["dd"][i],
            "da_m": sign * p["da"][i],
        }
        for i, j in enumerate(truth["joints"])
    }


def test_physics_model_and_core_offset_chain_agree(tmp_path, ur5):
    """The physics module's kinematic model with the offsets of physics.json (read by its
    effect, through predict_ee) equals the core library's chain_with_offsets used by G008."""
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="kinematic_offsets", seed=2, **SMALL)
    )
    _set_offsets(ds, _truth_offsets(truth, sign=7.0))  # large, so that errors would show
    s = open_arm(ds)
    assert set(s.fixed) == {"kinematic_offsets"}
    space = ParamSpace((), ())
    pos, R = predict_ee(space.defaults(1, dtype=torch.float64), space, s.kin, s.fixed)
    chain = Chain.from_urdf(load_urdf(ur5, load_meshes=False))
    off = read_joint_offsets(Dataset.open(ds).physics(), chain.joint_names)
    T = chain_with_offsets(chain, off).forward(s.kin.q)[:, chain.link_index("tool0")]
    np.testing.assert_allclose(pos[0].numpy(), T[:, :3, 3].numpy(), atol=1e-12)
    np.testing.assert_allclose(R[0].numpy(), T[:, :3, :3].numpy(), atol=1e-12)
    T0 = chain.forward(s.kin.q)[:, chain.link_index("tool0")]
    assert np.abs(T0[:, :3, 3].numpy() - pos[0].numpy()).max() > 0.02


def test_g008_fails_with_hidden_offsets_and_passes_after_the_fit(tmp_path, ur5):
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="kinematic_offsets", seed=5, **SMALL)
    )
    before = _g008(ds)
    assert len(before) == 3  # every episode, measured 3.8-4.8 mm against the 2 mm budget
    assert min(f.value for f in before) > 3.0 and max(f.value for f in before) < 6.0
    assert all("joint offsets" not in f.message for f in before)

    assert main(["fit", str(ds), "--add", "kinematic_offsets"]) == 0
    assert _g008(ds) == []
    after = _g008(ds, budget=0.0)  # every episode reported: the largest error per episode
    assert len(after) == 3 and max(f.value for f in after) < 1.2  # measured 0.73-0.89 mm
    assert all("FK with the joint offsets of physics revision 2" in f.message for f in after)

    # the true offsets leave the pose noise alone
    _set_offsets(ds, _truth_offsets(truth))
    medians = []
    for f in _g008(ds, budget=0.0):
        medians.append(float(f.message.split("(median ")[1].split(" mm")[0]))
    assert len(medians) == 3
    assert abs(np.median(medians) - MEDIAN_NOISE_MM) < 0.15 * MEDIAN_NOISE_MM, medians


def test_g008_catches_offsets_written_wrong(tmp_path, ur5):
    """Offsets of the wrong sign (a mutated physics.json) fail G008 by more than the hidden
    offsets alone; compliance and backlash in physics.json are named as not applied."""
    ds = tmp_path / "ds"
    truth = generate_kinematic_dataset(
        ds, ur5, KinLogSpec(effect="kinematic_offsets", seed=5, **SMALL)
    )
    nominal = {f.location.episode: f.value for f in _g008(ds)}
    _set_offsets(ds, _truth_offsets(truth, sign=-1.0), extra={"backlash_rad": 1e-3})
    wrong = _g008(ds)
    assert len(wrong) == 3
    ratio = [
        f.value / nominal[f.location.episode] for f in wrong
    ]  # twice the offsets: about 2x the error
    assert min(ratio) > 1.5 and max(ratio) < 2.5, ratio
    msg = wrong[0].message
    assert "FK with the joint offsets of physics revision 2" in msg
    assert "backlash_rad of physics revision 2 not applied" in msg

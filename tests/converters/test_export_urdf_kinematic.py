"""URDF and USD export of the fitted kinematic joint effects: offsets baked into the joint
origins, compliance and backlash in the sidecar and as USD attributes.

Oracle: forward kinematics of the exported URDF by yourdfpy's own scene graph, at the measured
joint angles, against the physics module's kinematic model with the fitted offsets
(``predict_ee``); the USD bodies' rest poses against the same yourdfpy FK.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import yourdfpy
from pxr import Usd, UsdGeom

from robogs.convert.export import export
from robogs.format.dataset import Dataset
from robogs.physics.arm.api import fit_arm, open_arm
from robogs.physics.arm.kinematic_model import predict_ee
from robogs.physics.space import ParamSpace
from robogs.synth.armlogs import KinLogSpec, generate_kinematic_dataset, ur5_urdf

SMALL = {"segments": 3, "duration_s": 4.0, "ee_rate_hz": 40.0}
COMPLIANCE = {"shoulder_lift_joint": 1e-4, "elbow_joint": 2e-4}
BACKLASH = {"wrist_1_joint": 8e-4}


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A dataset with hidden offsets, fitted (revision 2), then compliance and backlash added
    (revision 3); the model poses with the fitted offsets alone; URDF and USD exports."""
    root = tmp_path_factory.mktemp("kin")
    urdf = root / "ur5.urdf"
    urdf.write_text(ur5_urdf())
    ds = root / "ds"
    generate_kinematic_dataset(ds, urdf, KinLogSpec(effect="kinematic_offsets", seed=5, **SMALL))
    fit_arm(ds, ["kinematic_offsets"])
    s = open_arm(ds)
    fixed = {"kinematic_offsets": s.fixed["kinematic_offsets"]}
    space = ParamSpace((), ())
    pos, R = predict_ee(space.defaults(1, dtype=torch.float64), space, s.kin, fixed)
    d = Dataset.open(ds)
    doc = json.loads(json.dumps(d.physics()))
    for j, c in COMPLIANCE.items():
        doc["joints"].setdefault(j, {})["compliance_rad_per_nm"] = c
    for j, b in BACKLASH.items():
        doc["joints"].setdefault(j, {})["backlash_rad"] = b
    with d.edit() as w:
        w.set_physics(doc, note="test: compliance and backlash")
        w.commit()
    urdf_rep = export("urdf", ds, root / "urdf")
    usd_rep = export("usd", ds, root / "scene.usda")
    return {
        "root": root,
        "ds": ds,
        "urdf": urdf,
        "q": s.kin.q.numpy(),
        "pos": pos[0].numpy(),
        "R": R[0].numpy(),
        "physics": doc,
        "reports": (urdf_rep, usd_rep),
    }


def _fk(urdf_path, q: np.ndarray, link: str = "tool0") -> np.ndarray:
    u = yourdfpy.URDF.load(str(urdf_path), build_scene_graph=True, load_meshes=False)
    out = []
    for row in q:
        u.update_cfg(row)
        out.append(u.get_transform(link, "base_link"))
    return np.stack(out)


def test_exported_urdf_fk_reproduces_the_fitted_model(scene):
    idx = np.linspace(0, len(scene["q"]) - 1, 40).astype(int)
    q = scene["q"][idx]
    T = _fk(scene["root"] / "urdf" / "ur5_arm.urdf", q)
    err_m = np.abs(T[:, :3, 3] - scene["pos"][idx]).max()
    assert err_m <= 1e-9, err_m
    assert np.abs(T[:, :3, :3] - scene["R"][idx]).max() <= 1e-9
    T0 = _fk(scene["urdf"], q)  # the URDF as recorded: off by the hidden offsets (mm)
    assert np.abs(T0[:, :3, 3] - scene["pos"][idx]).max() > 2e-3
    # limits stay in the measured joint values; every actuated joint's origin was rewritten
    got = yourdfpy.URDF.load(str(scene["root"] / "urdf" / "ur5_arm.urdf"), load_meshes=False)
    orig = yourdfpy.URDF.load(str(scene["urdf"]), load_meshes=False)
    for j in orig.actuated_joint_names:
        a, b = orig.joint_map[j], got.joint_map[j]
        assert (a.limit.lower, a.limit.upper) == (b.limit.lower, b.limit.upper)
        assert not np.allclose(a.origin, b.origin, atol=1e-6, rtol=0)
    assert scene["reports"][0].facts["offset_joints"] == sorted(orig.actuated_joint_names)


def test_sidecar_carries_offsets_compliance_and_backlash(scene):
    side = json.loads((scene["root"] / "urdf" / "ur5_arm.contact.json").read_text())
    joints = scene["physics"]["joints"]
    for j, entry in joints.items():
        got = side["joints"][j]
        off = {k: entry["offsets"].get(k, 0.0) for k in ("dtheta_rad", "dd_m", "da_m")}
        assert got["offsets"] == {**off, "in_urdf": True}
        assert got.get("compliance_rad_per_nm") == COMPLIANCE.get(j)
        assert got.get("backlash_rad") == BACKLASH.get(j)
    assert "compliance_rad_per_nm" in side["units"] and "backlash_rad" in side["units"]


def test_usd_joint_frames_follow_the_offsets_and_keep_the_attributes(scene):
    stage = Usd.Stage.Open(str(scene["root"] / "scene.usda"))
    assert scene["reports"][1].facts["validator_errors"] == 0
    T_urdf = _fk(scene["root"] / "urdf" / "ur5_arm.urdf", np.zeros((1, 6)), "wrist_3_link")[0]
    cache = UsdGeom.XformCache()
    M = np.array(
        cache.GetLocalToWorldTransform(stage.GetPrimAtPath("/World/ur5_arm/wrist_3_link")),
        dtype=np.float64,
    ).T
    np.testing.assert_allclose(M, T_urdf, atol=1e-6)  # rest pose (q = 0) of the fitted model
    for j, entry in scene["physics"]["joints"].items():
        prim = stage.GetPrimAtPath(f"/World/ur5_arm/joints/{j}")
        off = entry["offsets"]
        assert prim.GetAttribute("robogs:offsetDthetaRad").Get() == off["dtheta_rad"]
        assert prim.GetAttribute("robogs:offsetDaM").Get() == off["da_m"]
        assert prim.GetAttribute("robogs:complianceRadPerNm").Get() == COMPLIANCE.get(j)
        assert prim.GetAttribute("robogs:backlashRad").Get() == BACKLASH.get(j)

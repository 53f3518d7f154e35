"""URDF export of the fitted arm physics: friction in <dynamics>, payload as a fixed link, mass scale.

Oracle: the rigid-body torques of the exported URDF (our RNEA on the exported file) plus the
friction written in its ``<dynamics>`` must equal the fitted torque model of the dataset, up to
the closed-form torques of the payload's sphere inertia (the model's payload is a point mass).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
import yourdfpy

from robogs.cli.main import main
from robogs.convert.export import export
from robogs.convert.export.arm_physics import PAYLOAD_RADIUS_M, deepest_moving_link, payload_spec
from robogs.convert.export.urdf_physics import FRAME_MASS_KG
from robogs.format.dataset import Dataset
from robogs.format.errors import FormatError
from robogs.format.kinematics import Chain
from robogs.physics.arm.api import open_arm
from robogs.physics.arm.compare import base_prediction
from robogs.physics.arm.effects import SMOOTHING_VELOCITY
from robogs.physics.arm.rnea import ArmModel, inverse_dynamics
from robogs.synth.armlogs import UR5_JOINTS, ArmLogSpec, generate_armlog, ur5_urdf


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def _load(path: Path) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)


def _exported_torques(urdf_path: Path, ds_path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(RNEA of the exported URDF + its <dynamics> friction, fitted model) on the dataset's data."""
    s = open_arm(ds_path)
    st = s.problem.state
    got = _load(urdf_path)
    # the tiny inertials the export gives massless frame links (declared in the sidecar) are
    # not part of the fitted model: their torques are bounded in _frame_torques_are_negligible
    for name in _frame_links(urdf_path):
        got.link_map[name].inertial = None
    model = ArmModel.from_urdf(got)
    tau = inverse_dynamics(model, st.q, st.qd, st.qdd).numpy()
    for k, j in enumerate(st.joint_names):
        dyn = got.joint_map[j].dynamics
        fc = float(dyn.friction) if dyn is not None and dyn.friction is not None else 0.0
        fv = float(dyn.damping) if dyn is not None and dyn.damping is not None else 0.0
        qd = st.qd[:, k].numpy()
        tau[:, k] += fc * np.tanh(qd / SMOOTHING_VELOCITY) + fv * qd
    return tau, base_prediction(s.problem, s.fixed).numpy()


def _frame_links(urdf_path: Path) -> list[str]:
    contact = json.loads(urdf_path.with_name(f"{urdf_path.stem}.contact.json").read_text())
    return contact.get("frame_inertials", {}).get("links", [])


def _frame_torques_are_negligible(urdf_path: Path, ds_path: Path) -> None:
    """The declared frame inertials (1e-6 kg) move the exported URDF's torques by < 1e-4 N m."""
    st = open_arm(ds_path).problem.state
    links = _frame_links(urdf_path)
    assert links and all(
        float(_load(urdf_path).link_map[n].inertial.mass) == FRAME_MASS_KG for n in links
    )
    full = inverse_dynamics(ArmModel.from_urdf(_load(urdf_path)), st.q, st.qd, st.qdd).numpy()
    bare = _load(urdf_path)
    for name in links:
        bare.link_map[name].inertial = None
    without = inverse_dynamics(ArmModel.from_urdf(bare), st.q, st.qd, st.qdd).numpy()
    assert 0 < np.max(np.abs(full - without)) < 1e-4


def _sphere_torques(urdf_path: Path, ds_path: Path, parent: str, inertia: float) -> np.ndarray:
    """Closed form of the joint torques an isotropic inertia ``inertia`` (kg m^2) on ``parent``
    adds: ``I z_j . w_dot`` for the joints above it (no gyroscopic term for a sphere), with
    ``w_dot = sum_k z_k qdd_k + (w_{k-1} x z_k) qd_k`` along the serial chain, [N, J] N m."""
    st = open_arm(ds_path).problem.state
    u = _load(urdf_path)
    chain = Chain.from_urdf(u)
    joints = [u.joint_map[j] for j in st.joint_names]
    T = chain.forward_links(st.q, [j.child for j in joints]).numpy()  # [N, J, 4, 4]
    z = np.einsum("njab,jb->nja", T[..., :3, :3], np.array([j.axis for j in joints]))
    qd, qdd = st.qd.numpy(), st.qdd.numpy()
    w = np.zeros((len(qd), 3))
    w_dot = np.zeros((len(qd), 3))
    above = set()
    link = parent
    parents = {j.child: j for j in u.robot.joints}
    while link in parents:
        above.add(parents[link].name)
        link = parents[link].parent
    for k, j in enumerate(joints):  # serial order, base first
        if j.name not in above:
            continue
        w_dot += z[:, k] * qdd[:, k, None] + np.cross(w, z[:, k]) * qd[:, k, None]
        w += z[:, k] * qd[:, k, None]
    on = np.array([j.name in above for j in joints], dtype=float)
    return inertia * np.einsum("nja,na->nj", z, w_dot) * on


def test_cli_convert_fit_export_carries_payload_and_friction(tmp_path, capsys):
    urdf = tmp_path / "ur5.urdf"
    urdf.write_text(ur5_urdf())
    truth = generate_armlog(
        tmp_path / "logs", urdf, ArmLogSpec(effect="payload", seed=11, segments=3, duration_s=4.0)
    )
    ds, out = tmp_path / "ds", tmp_path / "out"
    assert main(["convert", str(tmp_path / "logs"), str(ds), "--urdf", str(urdf)]) == 0
    rc = main(["fit", str(ds), "--add", "payload", "--add", "joint_friction"])
    text = capsys.readouterr().out
    assert rc == 0 and "wrote physics revision 2" in text and "payload:" in text
    phys = Dataset.open(ds).physics()
    pay = phys["payload"]
    assert pay["link"] == truth["payload_link"] and abs(pay["mass_kg"] - 1.5) < 0.15
    assert main(["export", "urdf", str(ds), str(out)]) == 0

    got = _load(out / "ur5_arm.urdf")
    link = got.link_map["payload"]
    assert float(link.inertial.mass) == pay["mass_kg"]  # exact: floats written with repr
    np.testing.assert_array_equal(np.asarray(link.inertial.origin)[:3, 3], pay["com_m"])
    i_sphere = 0.4 * pay["mass_kg"] * PAYLOAD_RADIUS_M**2  # solid sphere of 1 cm about the CoM
    np.testing.assert_allclose(np.asarray(link.inertial.inertia), i_sphere * np.eye(3), rtol=1e-15)
    joint = got.joint_map["payload_joint"]
    assert joint.type == "fixed" and joint.parent == pay["link"] and joint.child == "payload"
    np.testing.assert_array_equal(np.asarray(joint.origin), np.eye(4))
    for j, entry in phys["joints"].items():
        assert float(got.joint_map[j].dynamics.friction) == entry["friction"]
        assert float(got.joint_map[j].dynamics.damping) == entry["damping"]
    contact = json.loads((out / "ur5_arm.contact.json").read_text())
    assert contact["payload"]["parent"] == pay["link"]
    assert contact["payload"]["mass_kg"] == pay["mass_kg"]

    exported, fitted = _exported_torques(out / "ur5_arm.urdf", ds)
    sphere = _sphere_torques(out / "ur5_arm.urdf", ds, pay["link"], i_sphere)
    np.testing.assert_allclose(exported - fitted, sphere, rtol=0, atol=1e-9)
    _frame_torques_are_negligible(out / "ur5_arm.urdf", ds)
    # the sphere's inertia is invisible in the torques: well under the effort noise floor
    noise = np.array(list(open_arm(ds).problem.sigma.numpy()))
    assert 0 < np.max(np.abs(sphere)) < 0.02 * noise.min()
    # the payload matters: the dataset's own URDF misses it by newtons
    s = open_arm(ds)
    bare = inverse_dynamics(ArmModel.from_urdf(_load(urdf)), s.problem.state.q,
                            s.problem.state.qd, s.problem.state.qdd).numpy()  # fmt: skip
    assert np.max(np.abs(bare - fitted)) > 1.0


def test_mass_scale_payload_on_welded_link_and_name_clash(tmp_path):
    urdf = tmp_path / "ur5.urdf"
    urdf.write_text(ur5_urdf().replace('"tool0"', '"payload"'))  # the tool link is called payload
    generate_armlog(tmp_path / "logs", urdf, ArmLogSpec(segments=1, duration_s=2.0, seed=2))
    assert main(["convert", str(tmp_path / "logs"), str(tmp_path / "ds"), "--urdf", str(urdf)]) == 0
    ds = Dataset.open(tmp_path / "ds")
    doc = ds.physics()
    joints = list(UR5_JOINTS)
    doc["payload"] = {"link": "payload", "mass_kg": 0.8, "com_m": [0.03, -0.02, 0.05]}
    doc["effects"] = [
        {"name": "mass_scale", "target": "robot", "params": {"s": 1.2}},
        {"name": "effort_time_offset", "target": "robot", "params": {"delta": 0.004}},
    ]
    doc["joints"] = {j: {"friction": 0.5, "damping": 0.25, "armature": 0.1 * (k + 1)}
                     for k, j in enumerate(joints)}  # fmt: skip
    with ds.edit() as w:
        w.set_physics(doc, note="by hand")
        w.commit()
    report = export("urdf", tmp_path / "ds", tmp_path / "out")
    assert report.facts["mass_scale"] == 1.2 and report.facts["payload"]["link"] == "payload_2"
    got = _load(tmp_path / "out" / "ur5_arm.urdf")
    ref = _load(urdf)
    assert got.joint_map["payload_joint"].parent == "payload"  # the tool link, welded to wrist_3
    for lk in ref.robot.links:
        if lk.inertial is not None:
            m = float(got.link_map[lk.name].inertial.mass)
            assert m == pytest.approx(1.2 * float(lk.inertial.mass), rel=1e-15)
            np.testing.assert_allclose(
                got.link_map[lk.name].inertial.inertia, 1.2 * lk.inertial.inertia, rtol=1e-15
            )
    assert float(got.link_map["payload_2"].inertial.mass) == 0.8  # the payload is not scaled
    contact = json.loads((tmp_path / "out" / "ur5_arm.contact.json").read_text())
    assert contact["joints"][joints[2]] == {"armature": pytest.approx(0.3)}  # not in URDF
    assert [(e["name"], e["in_urdf"]) for e in contact["effects"]] == [
        ("mass_scale", True),
        ("effort_time_offset", False),
    ]
    # the time offset is a sensor effect: compare the rigid-body + friction part only
    s = open_arm(tmp_path / "ds")
    fixed = {k: v for k, v in s.fixed.items() if k not in ("effort_time_offset", "armature")}
    assert set(fixed) == {"payload", "mass_scale", "joint_friction"}
    exported, _ = _exported_torques(tmp_path / "out" / "ur5_arm.urdf", tmp_path / "ds")
    fitted = base_prediction(s.problem, fixed).numpy()
    sphere = _sphere_torques(tmp_path / "out" / "ur5_arm.urdf", tmp_path / "ds", "payload",
                             0.4 * 0.8 * PAYLOAD_RADIUS_M**2)  # fmt: skip
    np.testing.assert_allclose(exported - fitted, sphere, rtol=0, atol=1e-9)


def test_payload_spec_defaults_and_errors(tmp_path):
    urdf = tmp_path / "ur5.urdf"
    urdf.write_text(ur5_urdf())
    u = _load(urdf)
    assert deepest_moving_link(u) == "wrist_3_link"
    assert payload_spec({"payload": {"mass_kg": 0.0, "com_m": [0, 0, 0]}}, u, {}) is None
    assert payload_spec({}, u, {}) is None
    spec = payload_spec({"payload": {"mass_kg": 2.0}}, u, {"robot": {"ee_link": "tool0"}})
    assert spec.parent == "tool0" and spec.com.tolist() == [0.0, 0.0, 0.0]
    assert payload_spec({"payload": {"mass_kg": 2.0}}, u, {}).parent == "wrist_3_link"
    with pytest.raises(FormatError, match="'gripper'") as exc:
        payload_spec({"payload": {"mass_kg": 1.0, "link": "gripper"}}, u, {})
    assert exc.value.where == "payload.link"

"""The exported payload body: positive-definite inertia (check G003) and the USD export.

Oracles: ``robogs-validate`` (check G003) on a dataset built on the exported URDF, with a
mutated copy (the payload's inertia zeroed, as a point mass would be written) that must be
flagged; the USD stage read back with pxr against the exported URDF's mass properties and its
forward kinematics.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from lxml import etree
from pxr import Usd, UsdGeom, UsdPhysics

from robogs.cli.main import validate_main
from robogs.convert.export import export
from robogs.convert.export.arm_physics import PAYLOAD_RADIUS_M
from robogs.convert.ingest.context import ConvertOptions
from robogs.convert.ingest.convert import convert_path
from robogs.format import Dataset
from robogs.format.frames import quat_to_matrix
from robogs.format.kinematics import Chain
from robogs.format.qa.rerun_log import rest_joint_positions
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf

F32 = 1e-6  # UsdPhysics attributes are float32
MASS, COM, SCALE = 0.8, [0.03, -0.02, 0.05], 1.2


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A UR5 joint log with a hand-written payload on tool0 (offset from the flange) and a
    mass scale; ``urdf/`` and ``scene.usda`` exported from it."""
    root = tmp_path_factory.mktemp("payload")
    urdf = root / "ur5.urdf"
    urdf.write_text(
        ur5_urdf().replace(
            '<child link="tool0"/><origin xyz="0 0 0" rpy="0 0 0"/>',
            '<child link="tool0"/><origin xyz="0.01 0 0.05" rpy="0 0.3 0.2"/>',
        )
    )
    generate_armlog(root / "logs", urdf, ArmLogSpec(segments=1, duration_s=1.0, seed=4))
    convert_path(root / "logs", root / "ds", fmt="tabular", options=ConvertOptions(urdf=urdf))
    ds = Dataset.open(root / "ds")
    doc = ds.physics()
    doc["payload"] = {"link": "tool0", "mass_kg": MASS, "com_m": COM}
    doc["effects"] = [{"name": "mass_scale", "target": "robot", "params": {"s": SCALE}}]
    with ds.edit() as w:
        w.set_physics(doc, note="by hand")
        w.commit()
    rep_urdf = export("urdf", root / "ds", root / "urdf")
    rep_usd = export("usd", root / "ds", root / "scene.usda")
    assert rep_usd.facts["validator_errors"] == 0, rep_usd.notes
    assert rep_usd.facts["mass_scale"] == rep_urdf.facts["mass_scale"] == SCALE
    assert rep_usd.facts["payload"]["parent"] == rep_urdf.facts["payload"]["parent"] == "tool0"
    return root


def _g003(root: Path, urdf: Path, name: str, capsys: pytest.CaptureFixture) -> list[dict]:
    convert_path(root / "logs", root / name, fmt="tabular", options=ConvertOptions(urdf=urdf))
    capsys.readouterr()
    validate_main([str(root / name), "--select", "G003", "--json", "--no-progress"])
    out = json.loads(capsys.readouterr().out)
    return [f for f in out["findings"] if f["code"] == "G003"]


def test_validator_passes_the_exported_payload_and_flags_a_point_mass(scene, capsys):
    urdf = scene / "urdf" / "ur5_arm.urdf"
    assert _g003(scene, urdf, "ds_exported", capsys) == []
    # mutation: the same URDF with the payload written as a point mass (zero inertia)
    root = etree.parse(str(urdf)).getroot()
    (inertia,) = root.xpath("link[@name='payload']/inertial/inertia")
    for k in inertia.attrib:
        inertia.set(k, "0.0")
    bad = scene / "point_mass.urdf"
    bad.write_bytes(etree.tostring(root))
    found = _g003(scene, bad, "ds_point_mass", capsys)
    assert len(found) == 1 and "payload" in json.dumps(found[0]), found


def _world(prim: Usd.Prim) -> np.ndarray:
    return np.array(UsdGeom.XformCache().GetLocalToWorldTransform(prim), dtype=np.float64).T


def _pose(pos, rot) -> np.ndarray:  # noqa: ANN001 - Gf types
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(np.array([rot.GetReal(), *rot.GetImaginary()], dtype=np.float64))
    T[:3, 3] = list(pos)
    return T


def _tensor(api: UsdPhysics.MassAPI) -> np.ndarray:
    d = np.array(api.GetDiagonalInertiaAttr().Get(), dtype=np.float64)
    q = api.GetPrincipalAxesAttr().Get()
    R = np.asarray(quat_to_matrix(np.array([q.GetReal(), *q.GetImaginary()], dtype=np.float64)))
    return R @ np.diag(d) @ R.T


def test_usd_payload_body_and_mass_scale_match_the_urdf_export(scene):
    import yourdfpy

    stage = Usd.Stage.Open(str(scene / "scene.usda"))
    got = yourdfpy.URDF.load(
        str(scene / "urdf" / "ur5_arm.urdf"), build_scene_graph=False, load_meshes=False
    )
    orig = yourdfpy.URDF.load(str(scene / "ur5.urdf"), build_scene_graph=False, load_meshes=False)
    robot = stage.GetPrimAtPath("/World/ur5_arm")
    assert robot.GetAttribute("robogs:massScale").Get() == SCALE
    # every link body: the exported URDF's (scaled) mass properties
    total = 0.0
    for link in orig.robot.links:
        if link.inertial is None:
            continue
        api = UsdPhysics.MassAPI(stage.GetPrimAtPath(f"/World/ur5_arm/{link.name}"))
        ref = got.link_map[link.name].inertial
        assert float(ref.mass) == pytest.approx(SCALE * float(link.inertial.mass), rel=1e-15)
        assert api.GetMassAttr().Get() == pytest.approx(float(ref.mass), rel=F32)
        T = np.asarray(ref.origin)
        want = T[:3, :3] @ np.asarray(ref.inertia) @ T[:3, :3].T
        np.testing.assert_allclose(_tensor(api), want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
        total += api.GetMassAttr().Get()
    # the payload body: mass, CoM, the 1 cm sphere inertia, all as in the URDF's payload link
    prim = stage.GetPrimAtPath("/World/ur5_arm/payload")
    assert prim.HasAPI(UsdPhysics.RigidBodyAPI) and prim.HasAPI(UsdPhysics.MassAPI)
    assert prim.GetAttribute("robogs:payloadLink").Get() == "tool0"
    api = UsdPhysics.MassAPI(prim)
    ref = got.link_map["payload"].inertial
    assert api.GetMassAttr().Get() == pytest.approx(MASS, rel=F32) == float(ref.mass)
    np.testing.assert_allclose(api.GetCenterOfMassAttr().Get(), COM, atol=1e-7)
    i_sphere = 0.4 * MASS * PAYLOAD_RADIUS_M**2
    np.testing.assert_allclose(_tensor(api), i_sphere * np.eye(3), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(ref.inertia), i_sphere * np.eye(3), rtol=1e-15)
    assert total + MASS == pytest.approx(
        sum(float(lk.inertial.mass) for lk in got.robot.links if lk.inertial is not None), rel=F32
    )
    # its CoM in the world equals the exported URDF's forward kinematics at the rest pose
    chain = Chain.from_urdf(got)
    q = rest_joint_positions(Dataset.open(scene / "ds"), chain)
    T_payload = chain.forward_links(q, ["payload"]).numpy()[0]
    com_urdf = T_payload @ np.asarray(ref.origin)[:, 3]
    com_usd = _world(prim) @ np.array([*COM, 1.0])
    np.testing.assert_allclose(com_usd[:3], com_urdf[:3], atol=1e-6)
    # welded by a fixed joint to the body tool0 belongs to (wrist_3_link), frames coincide
    parsed = UsdPhysics.UsdPhysicsLoadStageFromPrimRange(stage, ["/"])
    fixed = dict(zip(*parsed[UsdPhysics.ObjectType.FixedJoint], strict=True))
    d = fixed[next(p for p in fixed if str(p) == "/World/ur5_arm/joints/payload_joint")]
    assert str(d.body0) == "/World/ur5_arm/wrist_3_link"
    assert str(d.body1) == "/World/ur5_arm/payload"
    F0 = _world(stage.GetPrimAtPath(str(d.body0))) @ _pose(
        d.localPose0Position, d.localPose0Orientation
    )
    F1 = _world(prim) @ _pose(d.localPose1Position, d.localPose1Orientation)
    np.testing.assert_allclose(F0, F1, atol=1e-6)
    np.testing.assert_allclose(
        F1, _world(stage.GetPrimAtPath("/World/ur5_arm/wrist_3_link/tool0")), atol=1e-6
    )

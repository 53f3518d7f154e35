"""USD export: parsed back with UsdPhysics, checked by usd-core's validators."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdPhysics

from robogs.convert.export import export
from robogs.convert.export.usd_physics import validate_usd
from robogs.format import Dataset
from robogs.format.frames import quat_to_matrix

try:
    from .test_export_data import PHYSICS, build_tiny_dataset
except ImportError:
    from test_export_data import PHYSICS, build_tiny_dataset

F32 = 1e-6  # attributes are float32 in UsdPhysics


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    ds = build_tiny_dataset(tmp_path_factory.mktemp("usd") / "tiny")
    with ds.edit() as w:  # a non-zero rest configuration exercises the joint frames
        w.manifest["robot"]["splats"]["rest"]["joint_positions"] = {"j1": 0.7, "j2": 0.05}
        return w.commit()


@pytest.fixture(scope="module")
def stage_path(tiny: Dataset, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("usd_out") / "scene.usda"
    report = export("usd", tiny, out)
    assert report.facts["validator_errors"] == 0, report.notes
    return out


def _world(prim: Usd.Prim) -> np.ndarray:
    M = UsdGeom.XformCache().GetLocalToWorldTransform(prim)
    return np.array(M, dtype=np.float64).T  # Gf matrices act on row vectors


def _pose(pos, rot) -> np.ndarray:  # noqa: ANN001 - Gf types
    T = np.eye(4)
    T[:3, :3] = np.asarray(
        quat_to_matrix(np.array([rot.GetReal(), *rot.GetImaginary()], dtype=np.float64))
    )
    T[:3, 3] = list(pos)
    return T


def test_validators_report_no_issue(stage_path: Path) -> None:
    issues = validate_usd(stage_path)
    assert [i for i in issues if i.kind == "error"] == []


def test_validators_catch_a_broken_joint(stage_path: Path, tmp_path: Path) -> None:
    stage = Usd.Stage.Open(str(stage_path))
    UsdPhysics.RevoluteJoint(
        stage.GetPrimAtPath("/World/tiny_arm/joints/j1")
    ).GetBody1Rel().SetTargets(["/World/nowhere"])
    bad = tmp_path / "bad.usda"
    stage.GetRootLayer().Export(str(bad))
    issues = [i for i in validate_usd(bad) if i.kind == "error"]
    assert [(i.name, i.sites) for i in issues] == [
        ("JointInvalidPrimRel", ("/World/tiny_arm/joints/j1",))
    ]


def test_stage_metadata(stage_path: Path) -> None:
    stage = Usd.Stage.Open(str(stage_path))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdPhysics.GetStageKilogramsPerUnit(stage) == 1.0
    scene = UsdPhysics.Scene(stage.GetPrimAtPath("/World/PhysicsScene"))
    assert scene.GetGravityMagnitudeAttr().Get() == pytest.approx(9.81, rel=F32)
    assert tuple(scene.GetGravityDirectionAttr().Get()) == (0.0, 0.0, -1.0)
    assert stage.GetPrimAtPath("/World/tiny_arm").HasAPI(UsdPhysics.ArticulationRootAPI)


def test_masses_and_inertia_equal_the_dataset(tiny: Dataset, stage_path: Path) -> None:
    stage = Usd.Stage.Open(str(stage_path))
    urdf = tiny.urdf(load_meshes=False)
    expected = {}
    for link in urdf.robot.links:
        if link.inertial is not None:
            T = np.asarray(link.inertial.origin)
            expected[f"/World/tiny_arm/{link.name}"] = (
                link.inertial.mass,
                T[:3, 3],
                T[:3, :3] @ np.asarray(link.inertial.inertia) @ T[:3, :3].T,
            )
    box = PHYSICS["objects"]["box"]
    expected["/World/Objects/box"] = (
        box["mass_kg"],
        np.array(box["com_m"]),
        np.array(box["inertia_kgm2"]),
    )
    for path, (m, com, inertia) in expected.items():
        api = UsdPhysics.MassAPI(stage.GetPrimAtPath(path))
        assert api.GetMassAttr().Get() == pytest.approx(m, rel=F32)
        np.testing.assert_allclose(api.GetCenterOfMassAttr().Get(), com, atol=1e-7)
        d = np.array(api.GetDiagonalInertiaAttr().Get(), dtype=np.float64)
        q = api.GetPrincipalAxesAttr().Get()
        R = np.asarray(quat_to_matrix(np.array([q.GetReal(), *q.GetImaginary()], dtype=np.float64)))
        np.testing.assert_allclose(
            R @ np.diag(d) @ R.T, inertia, rtol=1e-5, atol=1e-6 * np.abs(inertia).max()
        )
    # a massless frame link is not a body
    assert not stage.GetPrimAtPath("/World/tiny_arm/link2/tool").HasAPI(UsdPhysics.RigidBodyAPI)
    assert not stage.GetPrimAtPath("/World/Objects/table").HasAPI(UsdPhysics.RigidBodyAPI)


def test_joints_limits_frames_and_materials(tiny: Dataset, stage_path: Path) -> None:
    stage = Usd.Stage.Open(str(stage_path))
    parsed = UsdPhysics.UsdPhysicsLoadStageFromPrimRange(stage, ["/"])
    joints = {
        str(p): d
        for kind in (UsdPhysics.ObjectType.RevoluteJoint, UsdPhysics.ObjectType.PrismaticJoint)
        for p, d in zip(*parsed[kind], strict=True)
    }
    urdf = tiny.urdf(load_meshes=False)
    q_rest = {"j1": 0.7, "j2": 0.05}
    for name in ("j1", "j2"):
        j = urdf.joint_map[name]
        d = joints[f"/World/tiny_arm/joints/{name}"]
        scale = 180.0 / math.pi if j.type == "revolute" else 1.0
        assert d.limit.enabled
        assert d.limit.lower == pytest.approx(j.limit.lower * scale, rel=F32, abs=1e-7)
        assert d.limit.upper == pytest.approx(j.limit.upper * scale, rel=F32, abs=1e-7)
        assert (
            str(d.body0) == f"/World/tiny_arm/{j.parent}"
            and str(d.body1) == f"/World/tiny_arm/{j.child}"
        )
        # joint frames on both bodies, placed at the rest configuration, differ by motion(q_rest)
        F0 = _world(stage.GetPrimAtPath(str(d.body0))) @ _pose(
            d.localPose0Position, d.localPose0Orientation
        )
        F1 = _world(stage.GetPrimAtPath(str(d.body1))) @ _pose(
            d.localPose1Position, d.localPose1Orientation
        )
        rel = np.linalg.inv(F0) @ F1
        axis = {"X": 0, "Y": 1, "Z": 2}[str(d.axis)] if not isinstance(d.axis, int) else d.axis
        e = np.eye(3)[axis]
        if j.type == "revolute":
            c, s = math.cos(q_rest[name]), math.sin(q_rest[name])
            K = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
            np.testing.assert_allclose(rel[:3, :3], np.eye(3) + s * K + (1 - c) * K @ K, atol=1e-6)
            np.testing.assert_allclose(rel[:3, 3], 0, atol=1e-6)
        else:
            np.testing.assert_allclose(rel[:3, :3], np.eye(3), atol=1e-6)
            np.testing.assert_allclose(rel[:3, 3], q_rest[name] * e, atol=1e-6)
        prim = stage.GetPrimAtPath(f"/World/tiny_arm/joints/{name}")
        assert prim.GetAttribute("robogs:damping").Get() == PHYSICS["joints"][name]["damping"]
        assert prim.GetAttribute("robogs:friction").Get() == PHYSICS["joints"][name]["friction"]

    mats = {
        str(p): d for p, d in zip(*parsed[UsdPhysics.ObjectType.RigidBodyMaterial], strict=True)
    }
    for body in ("link1", "box", "table"):
        ref = PHYSICS["objects"][body]
        d = mats[f"/World/PhysicsMaterials/{body}"]
        assert d.staticFriction == pytest.approx(ref["friction_static"], rel=F32)
        assert d.dynamicFriction == pytest.approx(ref["friction_dynamic"], rel=F32)
        assert d.restitution == pytest.approx(ref["restitution"], rel=F32, abs=1e-9)
    shapes = {str(p): d for p, d in zip(*parsed[UsdPhysics.ObjectType.MeshShape], strict=True)}
    assert [str(m) for m in shapes["/World/tiny_arm/link1/collisions/mesh_0"].materials] == [
        "/World/PhysicsMaterials/link1"
    ]
    assert str(shapes["/World/Objects/box/collisions/mesh_0"].rigidBody) == "/World/Objects/box"

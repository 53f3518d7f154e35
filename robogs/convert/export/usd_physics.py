"""Export the scene as an OpenUSD stage with UsdPhysics (usd-core ``pxr``).

Stage: ``upAxis = Z``, ``metersPerUnit = 1``, ``kilogramsPerUnit = 1``; all angles in degrees
(UsdPhysics convention), everything else SI. Prims::

    /World                                   default prim
    /World/PhysicsScene                      UsdPhysics.Scene (gravity from physics.json)
    /World/PhysicsMaterials/<body>           UsdShade.Material + PhysicsMaterialAPI
    /World/<robot>                           Xform + ArticulationRootAPI
    /World/<robot>/<link>                    Xform at T_world_link (rest configuration) +
                                             RigidBodyAPI + MassAPI
    /World/<robot>/<link>/visuals/mesh_<i>   UsdGeom.Mesh (render)
    /World/<robot>/<link>/collisions/mesh_<i>  UsdGeom.Mesh (guide) + CollisionAPI +
                                             MeshCollisionAPI(convexHull) + physics material
    /World/<robot>/joints/<joint>            Revolute/Prismatic/FixedJoint
    /World/<robot>/joints/root_fixed         FixedJoint world -> root link (fixed base)
    /World/<robot>/payload                   fitted payload: RigidBodyAPI + MassAPI, at its link's
                                             frame; FixedJoint joints/payload_joint to that link
    /World/Objects/<name>                    rigid: RigidBodyAPI + MassAPI; kinematic:
                                             kinematicEnabled; static: collider only

Mapping follows newton-physics/urdf-usd-converter (``docs/concept_mapping.md``): a joint's
frame is its URDF origin in the parent body, turned so that the joint axis is the USD axis
(X, Y or Z; an axis that is none of them is realised by rotating the joint frame onto X);
``localPos1/localRot1`` is that frame in the child body at q = 0, so with the bodies placed at
the rest configuration the joint reads q_rest. Revolute limits are in degrees, prismatic in
metres. The inertia tensor is written as ``diagonalInertia`` + ``principalAxes``
(eigen-decomposition). A massless link attached by a fixed joint (a frame such as a tool
flange) is not a body: it becomes an Xform nested in its parent's body. Passive joint
damping becomes a zero-stiffness force drive (damping per degree for revolute joints); URDF
damping, friction, armature and effort/velocity limits are also kept as ``robogs:*``
attributes in SI units, since core UsdPhysics has no place for them.

The arm torque model's fitted physics is carried as in the URDF export
(:mod:`robogs.convert.export.urdf_physics`): a ``mass_scale`` multiplies every link's mass and
inertia (recorded as ``robogs:massScale`` on the robot prim), and a ``payload`` becomes its own
rigid body (mass, CoM in the parent link frame, the inertia of a 1 cm solid sphere about the
CoM, :func:`.arm_physics.payload_inertia`) welded by a fixed joint to the link it was fitted on
(``robogs:payloadLink``). Fitted kinematic joint offsets (``physics.json``
``joints.<j>.offsets``) are baked into the joint origins as in the URDF export
(:func:`robogs.format.kinematics.chain_with_offsets`): the bodies' rest poses and the joint
frames follow the fitted model, and the values are also kept as ``robogs:offsetDthetaRad``,
``robogs:offsetDdM``, ``robogs:offsetDaM``. Joint compliance and backlash have no UsdPhysics
field: they are written as ``robogs:complianceRadPerNm`` and ``robogs:backlashRad``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdPhysics, UsdShade, UsdValidation, Vt

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.frames import matrix_to_quat, quat_to_matrix
from robogs.format.kinematics import Chain, chain_with_offsets, read_joint_offsets
from robogs.format.qa.rerun_log import rest_joint_positions, robot_link_meshes

from . import ExportReport, register_exporter
from .arm_physics import PAYLOAD_RADIUS_M, mass_scale, payload_inertia, payload_spec
from .physics_model import (
    BodyInertia,
    ContactMaterial,
    contact_material,
    joint_dynamics,
    link_inertias,
    principal_axes,
    scene_objects,
)

__all__ = ["USD_VALIDATORS", "UsdIssue", "export_usd", "validate_usd"]

#: validators run on the exported stage (those present in this usd-core are used)
USD_VALIDATORS: tuple[str, ...] = (
    "usdPhysicsValidators:RigidBodyChecker",
    "usdPhysicsValidators:ColliderChecker",
    "usdPhysicsValidators:PhysicsJointChecker",
    "usdPhysicsValidators:ArticulationChecker",
    "usdGeomValidators:StageMetadataChecker",
    "usdGeomValidators:EncapsulationChecker",
    "usdValidation:StageMetadataChecker",
    "usdValidation:CompositionErrorTest",
    "usdValidation:AttributeTypeMismatch",
    "usdShadeValidators:MaterialBindingApiAppliedValidator",
    "usdShadeValidators:MaterialBindingRelationships",
)


@dataclass(frozen=True)
class UsdIssue:
    """One validator report: ``kind`` is ``error``, ``warning`` or ``info``."""

    validator: str
    name: str
    kind: str
    message: str
    sites: tuple[str, ...] = ()


def validate_usd(path: str | Path) -> list[UsdIssue]:
    """Run usd-core's validators (:data:`USD_VALIDATORS`) on a stage file."""
    reg = UsdValidation.ValidationRegistry()
    names = [n for n in USD_VALIDATORS if reg.HasValidator(n)]
    stage = Usd.Stage.Open(str(path))
    errors = UsdValidation.ValidationContext(reg.GetOrLoadValidatorsByName(names)).Validate(stage)
    kinds = {
        UsdValidation.ValidationErrorType.Error: "error",
        UsdValidation.ValidationErrorType.Warn: "warning",
    }
    out = []
    for e in errors:
        if e.HasNoError():
            continue
        sites = tuple(
            str(s.GetPrim().GetPath()) if s.IsPrim() else str(s.GetPropertyPath())
            for s in e.GetSites()
        )
        out.append(
            UsdIssue(
                e.GetValidator().GetMetadata().name if e.GetValidator() else "",
                e.GetName(),
                kinds.get(e.GetType(), "info"),
                e.GetMessage(),
                sites,
            )
        )
    return out


def _name(raw: str, used: set[str]) -> str:
    base = Tf.MakeValidIdentifier(raw)
    name, k = base, 1
    while name in used:
        name, k = f"{base}_{k}", k + 1
    used.add(name)
    return name


def _quatd(R: np.ndarray) -> Gf.Quatd:
    q = np.asarray(matrix_to_quat(np.asarray(R, dtype=np.float64)))
    return Gf.Quatd(float(q[0]), Gf.Vec3d(*(float(v) for v in q[1:])))


def _quatf(R: np.ndarray) -> Gf.Quatf:
    q = np.asarray(matrix_to_quat(np.asarray(R, dtype=np.float64)))
    return Gf.Quatf(float(q[0]), Gf.Vec3f(*(float(v) for v in q[1:])))


def _set_pose(prim: Usd.Prim, T: np.ndarray) -> None:
    x = UsdGeom.Xformable(prim)
    x.ClearXformOpOrder()
    x.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*(float(v) for v in T[:3, 3])))
    x.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(_quatd(T[:3, :3]))


def _define_mesh(stage: Usd.Stage, path: Sdf.Path, mesh: Any, *, guide: bool) -> UsdGeom.Mesh:
    m = UsdGeom.Mesh.Define(stage, path)
    faces = np.asarray(mesh.faces, dtype=np.int32)
    m.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(mesh.vertices, dtype=np.float32)))
    m.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
    m.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.reshape(-1)))
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    lo, hi = np.asarray(mesh.bounds, dtype=np.float32)
    m.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
    if guide:
        m.CreatePurposeAttr(UsdGeom.Tokens.guide)
    return m


@dataclass
class _Builder:
    stage: Usd.Stage
    root: Sdf.Path
    materials: dict[str, UsdShade.Material] = field(default_factory=dict)
    material_names: set[str] = field(default_factory=set)
    notes: list[str] = field(default_factory=list)

    def material(self, body: str, mat: ContactMaterial) -> UsdShade.Material | None:
        if not mat.as_dict():
            return None
        if body not in self.materials:
            folder = UsdGeom.Scope.Define(
                self.stage, self.root.AppendChild("PhysicsMaterials")
            ).GetPath()
            path = folder.AppendChild(_name(body, self.material_names))
            material = UsdShade.Material.Define(self.stage, path)
            api = UsdPhysics.MaterialAPI.Apply(material.GetPrim())
            if mat.friction_static is not None:
                api.CreateStaticFrictionAttr(float(mat.friction_static))
            if mat.friction_dynamic is not None:
                api.CreateDynamicFrictionAttr(float(mat.friction_dynamic))
            if mat.restitution is not None:
                api.CreateRestitutionAttr(float(mat.restitution))
            self.materials[body] = material
        return self.materials[body]

    def colliders(
        self,
        parent: Sdf.Path,
        meshes: list[Any],
        material: UsdShade.Material | None,
        approximation: str,
    ) -> None:
        folder = UsdGeom.Scope.Define(self.stage, parent.AppendChild("collisions")).GetPath()
        for i, mesh in enumerate(meshes):
            m = _define_mesh(self.stage, folder.AppendChild(f"mesh_{i}"), mesh, guide=True)
            prim = m.GetPrim()
            UsdPhysics.CollisionAPI.Apply(prim)
            UsdPhysics.MeshCollisionAPI.Apply(prim).CreateApproximationAttr(approximation)
            if material is not None:
                UsdShade.MaterialBindingAPI.Apply(prim).Bind(
                    material, UsdShade.Tokens.weakerThanDescendants, "physics"
                )

    def visuals(self, parent: Sdf.Path, meshes: list[Any]) -> None:
        folder = UsdGeom.Scope.Define(self.stage, parent.AppendChild("visuals")).GetPath()
        for i, mesh in enumerate(meshes):
            _define_mesh(self.stage, folder.AppendChild(f"mesh_{i}"), mesh, guide=False)

    def mass(self, prim: Usd.Prim, inertia: BodyInertia, where: str) -> None:
        api = UsdPhysics.MassAPI.Apply(prim)
        api.CreateMassAttr(float(inertia.mass))
        api.CreateCenterOfMassAttr(Gf.Vec3f(*(float(v) for v in inertia.com)))
        d, R = principal_axes(inertia.inertia, where=where)
        api.CreateDiagonalInertiaAttr(Gf.Vec3f(*(float(v) for v in d)))
        api.CreatePrincipalAxesAttr(_quatf(R))


def _scaled(inertia: BodyInertia, s: float) -> BodyInertia:
    """``inertia`` with mass and inertia tensor times ``s`` (same CoM and frame)."""
    return BodyInertia(
        inertia.mass * s,
        inertia.com,
        inertia.inertia * s,
        inertia.frame,
        inertia.inertia_in_frame * s,
    )


def _axis_frame(axis: np.ndarray) -> tuple[str, np.ndarray]:
    """USD axis token and rotation ``Ra`` with ``Ra @ e_token == axis`` (identity when aligned)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    for token, e in zip("XYZ", np.eye(3), strict=True):
        if np.allclose(a, e, atol=1e-12):
            return token, np.eye(3)
    x = np.array([1.0, 0.0, 0.0])
    v = np.cross(x, a)
    s, c = np.linalg.norm(v), float(np.dot(x, a))
    if s < 1e-12:  # a == -x: half turn about z
        return "X", np.diag([-1.0, -1.0, 1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    ang = math.atan2(s, c)
    return "X", np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * (K @ K)


def _set_joint_frames(joint: UsdPhysics.Joint, T0: np.ndarray, T1: np.ndarray) -> None:
    joint.CreateLocalPos0Attr(Gf.Vec3f(*(float(v) for v in T0[:3, 3])))
    joint.CreateLocalRot0Attr(_quatf(T0[:3, :3]))
    joint.CreateLocalPos1Attr(Gf.Vec3f(*(float(v) for v in T1[:3, 3])))
    joint.CreateLocalRot1Attr(_quatf(T1[:3, :3]))


def _custom(prim: Usd.Prim, name: str, value: float | None) -> None:
    if value is not None and math.isfinite(value):
        prim.CreateAttribute(f"robogs:{name}", Sdf.ValueTypeNames.Double, custom=True).Set(
            float(value)
        )


def _object_rest_pose(ds: Dataset, name: str) -> np.ndarray:
    """T_world_object at rest: the splats' rest pose, else the first sample, else identity."""
    T = np.eye(4)
    rest = (((ds.assets.get(name) or {}).get("splats") or {}).get("rest") or {}).get(
        "object_poses", {}
    )
    pose = rest.get(name)
    if pose is None:
        for ep in ds.episodes:
            if ep.has("object_poses"):
                tab = ep.table("object_poses")
                idx = [i for i, n in enumerate(tab.column("object").to_pylist()) if n == name]
                if idx:
                    row = {
                        c: tab.column(c)[idx[0]].as_py()
                        for c in ("x", "y", "z", "qw", "qx", "qy", "qz")
                    }
                    pose = [row[c] for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]
                    break
    if pose is not None:
        T[:3, :3] = np.asarray(quat_to_matrix(np.asarray(pose[3:7], dtype=np.float64)))
        T[:3, 3] = pose[:3]
    return T


def export_usd(ds: Dataset, out: Path, *, objects: bool = True) -> ExportReport:
    """Write the robot (and scene objects) as a UsdPhysics stage; suffix picks usda/usdc.

    Args:
        ds: the dataset (must have a robot).
        out: output ``.usda``, ``.usdc`` or ``.usd`` file.
        objects: include the ``physics.json`` scene objects.

    Returns:
        The report; ``facts["validator_errors"]`` counts errors from :func:`validate_usd`.
    """
    if not (ds.manifest.get("robot") or {}).get("urdf"):
        raise InputError(
            "dataset has no robot (manifest 'robot.urdf' is missing)",
            path=ds.manifest_path,
            hint="the usd export needs robot/robot.urdf",
        )
    if out.suffix.lower() not in (".usda", ".usdc", ".usd"):
        raise InputError(
            f"USD output must end in .usda, .usdc or .usd, not {out.suffix!r}", path=out
        )
    urdf = ds.urdf(load_meshes=True)
    physics = ds.physics() if ds.manifest.get("physics") else None
    phys_path = ds.root / "physics.json"
    chain = Chain.from_urdf(urdf, floating_as_fixed=True)
    offsets = read_joint_offsets(physics, chain.joint_names, path=phys_path)
    chain = chain_with_offsets(chain, offsets)
    origin_of = dict(zip(chain.tree_joint_names, chain.origins, strict=True))
    q_rest = rest_joint_positions(ds, chain)
    T_world = chain.forward(torch.from_numpy(q_rest)).numpy()  # [L, 4, 4]

    stage = Usd.Stage.CreateNew(str(out))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdPhysics.SetStageKilogramsPerUnit(stage, 1.0)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    b = _Builder(stage, world.GetPath())

    scene = UsdPhysics.Scene.Define(stage, "/World/PhysicsScene")
    g = np.asarray((physics or {}).get("gravity_mps2", (0.0, 0.0, -9.81)), dtype=np.float64)
    gn = float(np.linalg.norm(g))
    scene.CreateGravityDirectionAttr(Gf.Vec3f(*(g / gn if gn > 0 else (0.0, 0.0, -1.0)).tolist()))
    scene.CreateGravityMagnitudeAttr(gn)

    used: set[str] = {"PhysicsScene", "PhysicsMaterials", "Objects"}
    robot_path = world.GetPath().AppendChild(_name(urdf.robot.name or "robot", used))
    robot = UsdGeom.Xform.Define(stage, robot_path)
    UsdPhysics.ArticulationRootAPI.Apply(robot.GetPrim())
    inertias = link_inertias(urdf, physics)
    m_scale = mass_scale(physics, path=phys_path)
    if m_scale is not None:
        inertias = {k: _scaled(v, m_scale) for k, v in inertias.items()}
        _custom(robot.GetPrim(), "massScale", m_scale)
        b.notes.append(
            f"mass_scale {m_scale:.6g} applied to the mass and inertia of {len(inertias)} link(s)"
        )
    payload = payload_spec(physics, urdf, ds.manifest, path=phys_path)
    if offsets:
        b.notes.append(f"kinematic offsets of {len(offsets)} joint(s) baked into the joint frames")
    visuals = robot_link_meshes(urdf)
    collisions = robot_link_meshes(urdf, collision=True)
    objects_phys = (physics or {}).get("objects", {})
    joint_by_child = {j.child: j for j in urdf.robot.joints}

    body_of: dict[str, str] = {}  # link -> link name of the rigid body it belongs to
    T_body_link: dict[str, np.ndarray] = {}
    prim_path: dict[str, Sdf.Path] = {}
    link_used: set[str] = {"joints"}
    for k, link in enumerate(chain.link_names):
        j = joint_by_child.get(link)
        merged = j is not None and j.type == "fixed" and link not in inertias
        if merged:
            parent = j.parent
            body_of[link] = body_of[parent]
            origin = origin_of[j.name]
            T_body_link[link] = T_body_link[parent] @ origin
            path = prim_path[parent].AppendChild(_name(link, set()))
            prim = UsdGeom.Xform.Define(stage, path).GetPrim()
            _set_pose(prim, origin)
        else:
            body_of[link], T_body_link[link] = link, np.eye(4)
            path = robot_path.AppendChild(_name(link, link_used))
            prim = UsdGeom.Xform.Define(stage, path).GetPrim()
            _set_pose(prim, T_world[k])
            UsdPhysics.RigidBodyAPI.Apply(prim)
            if link in inertias:
                b.mass(prim, inertias[link], where=f"link {link}")
            else:
                b.notes.append(
                    f"link {link} has no inertial: its mass is left to the simulator (density)"
                )
        prim_path[link] = path
        if visuals.get(link):
            b.visuals(path, visuals[link])
        cols = collisions.get(link) or visuals.get(link) or []
        if cols:
            mat = b.material(body_of[link], contact_material(objects_phys.get(body_of[link])))
            b.colliders(path, cols, mat, UsdPhysics.Tokens.convexHull)

    joints_path = robot_path.AppendChild("joints")
    UsdGeom.Scope.Define(stage, joints_path)
    root_link = chain.link_names[0]
    fixed = UsdPhysics.FixedJoint.Define(stage, joints_path.AppendChild("root_fixed"))
    fixed.CreateBody1Rel().SetTargets([prim_path[root_link]])
    _set_joint_frames(fixed, T_world[0], np.eye(4))
    dynamics = joint_dynamics(urdf, physics)
    jused: set[str] = {"root_fixed"}
    n_joints = 0
    for j in urdf.robot.joints:
        if body_of.get(j.child) != j.child:  # merged frame link
            continue
        origin = origin_of.get(j.name)
        if origin is None:  # not in the chain's tree (cannot happen for a loaded URDF)
            origin = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=np.float64)
        T0 = T_body_link[j.parent] @ origin
        path = joints_path.AppendChild(_name(j.name, jused))
        if j.type in ("revolute", "continuous", "prismatic"):
            token, Ra = _axis_frame(np.asarray(j.axis if j.axis is not None else (1.0, 0.0, 0.0)))
            Ta = np.eye(4)
            Ta[:3, :3] = Ra
            if j.type == "prismatic":
                joint = UsdPhysics.PrismaticJoint.Define(stage, path)
                scale, drive = 1.0, "linear"
            else:
                joint = UsdPhysics.RevoluteJoint.Define(stage, path)
                scale, drive = 180.0 / math.pi, "angular"
            joint.CreateAxisAttr(token)
            if j.type != "continuous" and j.limit is not None:
                if j.limit.lower is not None:
                    joint.CreateLowerLimitAttr(float(j.limit.lower) * scale)
                if j.limit.upper is not None:
                    joint.CreateUpperLimitAttr(float(j.limit.upper) * scale)
            _set_joint_frames(joint, T0 @ Ta, Ta)
            dyn = dynamics.get(j.name)
            prim = joint.GetPrim()
            if dyn is not None:
                _custom(prim, "damping", dyn.damping)
                _custom(prim, "friction", dyn.friction)
                _custom(prim, "armature", dyn.armature)
                if dyn.damping:
                    api = UsdPhysics.DriveAPI.Apply(prim, drive)
                    api.CreateTypeAttr(UsdPhysics.Tokens.force)
                    api.CreateStiffnessAttr(0.0)
                    api.CreateDampingAttr(float(dyn.damping) / scale)
                    api.CreateTargetVelocityAttr(0.0)
            if j.limit is not None:
                _custom(prim, "effortLimit", j.limit.effort)
                _custom(prim, "velocityLimit", j.limit.velocity)
            entry = ((physics or {}).get("joints") or {}).get(j.name) or {}
            _custom(prim, "complianceRadPerNm", entry.get("compliance_rad_per_nm"))
            _custom(prim, "backlashRad", entry.get("backlash_rad"))
            if j.name in offsets:
                o = offsets[j.name]
                _custom(prim, "offsetDthetaRad", o.dtheta)
                _custom(prim, "offsetDdM", o.dd)
                _custom(prim, "offsetDaM", o.da)
        elif j.type == "fixed":
            joint = UsdPhysics.FixedJoint.Define(stage, path)
            _set_joint_frames(joint, T0, np.eye(4))
        else:
            b.notes.append(
                f"joint {j.name}: type {j.type!r} is not exported (no UsdPhysics equivalent)"
            )
            continue
        joint.CreateBody0Rel().SetTargets([prim_path[body_of[j.parent]]])
        joint.CreateBody1Rel().SetTargets([prim_path[j.child]])
        n_joints += 1
    payload_entry = None
    if payload is not None:
        parent = payload.parent
        path = robot_path.AppendChild(_name("payload", link_used))
        prim = UsdGeom.Xform.Define(stage, path).GetPrim()
        _set_pose(prim, T_world[chain.link_index(parent)])  # the payload frame = its link's
        UsdPhysics.RigidBodyAPI.Apply(prim)
        b.mass(prim, payload_inertia(payload), where="payload")
        prim.CreateAttribute("robogs:payloadLink", Sdf.ValueTypeNames.String, custom=True).Set(
            parent
        )
        weld = UsdPhysics.FixedJoint.Define(
            stage, joints_path.AppendChild(_name("payload_joint", jused))
        )
        _set_joint_frames(weld, T_body_link[parent], np.eye(4))
        weld.CreateBody0Rel().SetTargets([prim_path[body_of[parent]]])
        weld.CreateBody1Rel().SetTargets([path])
        n_joints += 1
        payload_entry = {
            "prim": str(path),
            "joint": str(weld.GetPath()),
            "parent": parent,
            "mass_kg": payload.mass,
            "com_m": [float(v) for v in payload.com],
            "inertia": f"solid sphere of radius {PAYLOAD_RADIUS_M} m about the CoM",
        }
        b.notes.append(f"payload {payload.mass:.4g} kg written as body {path} fixed to {parent!r}")

    n_objects = 0
    if objects:
        objs = scene_objects(ds, physics, set(chain.link_names))
        if objs:
            folder = UsdGeom.Scope.Define(stage, world.GetPath().AppendChild("Objects")).GetPath()
        oused: set[str] = set()
        for obj in objs:
            path = folder.AppendChild(_name(obj.name, oused))
            prim = UsdGeom.Xform.Define(stage, path).GetPrim()
            _set_pose(prim, _object_rest_pose(ds, obj.name))
            if obj.equation in ("rigid", "kinematic", "articulated"):
                body = UsdPhysics.RigidBodyAPI.Apply(prim)
                if obj.equation == "kinematic":
                    body.CreateKinematicEnabledAttr(True)
                if obj.inertia is not None:
                    b.mass(prim, obj.inertia, where=f"object {obj.name}")
            for key in ("damping_linear", "damping_angular"):
                _custom(prim, key, obj.params.get(key))
            if obj.mesh_path is not None:
                mesh = ds.mesh(obj.name)
                b.visuals(path, [mesh])
                approx = (
                    UsdPhysics.Tokens.none
                    if obj.equation == "static"
                    else UsdPhysics.Tokens.convexHull
                )
                b.colliders(path, [mesh], b.material(obj.name, obj.material), approx)
            else:
                b.notes.append(f"object {obj.name} has no mesh: exported without collider")
            n_objects += 1
    stage.GetRootLayer().Save()
    del stage
    issues = validate_usd(out)
    errors = [i for i in issues if i.kind == "error"]
    b.notes += [f"USD validator {i.kind}: {i.name}: {i.message}" for i in issues]
    return ExportReport(
        out=out,
        files=[out.name],
        notes=b.notes,
        facts={
            "bodies": sum(1 for link in chain.link_names if body_of[link] == link)
            + n_objects
            + (payload is not None),
            "joints": n_joints + 1,
            "objects": n_objects,
            "validators_run": [
                n for n in USD_VALIDATORS if UsdValidation.ValidationRegistry().HasValidator(n)
            ],
            "validator_errors": len(errors),
            "validator_issues": len(issues),
            **({"payload": payload_entry} if payload_entry else {}),
            **({"mass_scale": m_scale} if m_scale is not None else {}),
            **({"offset_joints": sorted(offsets)} if offsets else {}),
        },
    )


register_exporter(
    "usd",
    export_usd,
    output="file",
    suffix=".usda",
    help="OpenUSD stage with UsdPhysics bodies, masses, colliders, materials and joints",
)

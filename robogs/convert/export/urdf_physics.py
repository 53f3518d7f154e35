"""Export the robot as a URDF that carries the dataset's physics, plus one URDF per object.

Output folder::

    OUT/<robot>.urdf             the dataset URDF, edited (see below)
    OUT/<robot>.contact.json     what URDF cannot hold: contact friction/restitution, armature
    OUT/meshes/...               every mesh the URDF references, copied; paths are relative
    OUT/objects/<name>/<name>.urdf, mesh.<ext>   one single-link URDF per scene object

Edits to the dataset URDF (parsed with lxml, so transmissions, Gazebo tags and anything else
are kept as they were):

* ``<inertial>`` of a link is replaced when ``physics.json`` gives that link a mass
  (``com_m``, ``inertia_kgm2``);
* ``<dynamics damping friction>`` of every non-fixed joint from ``physics.json`` ``joints``
  (URDF units: N·m·s/rad and N·m, or N·s/m and N for prismatic joints);
* a link with visual geometry but no collision gets its visual geometry as collision;
* mesh ``filename`` attributes point at the copies under ``meshes/``;
* a fitted ``mass_scale`` (``physics.json`` ``effects``) multiplies every link's mass and
  inertia;
* a fitted ``payload`` (``physics.json`` ``payload: {link, mass_kg, com_m}``) becomes a link
  ``payload`` welded by a fixed joint ``payload_joint`` (identity origin) to the link it was
  fitted on: ``<inertial>`` origin at the CoM, and about it the inertia of a solid sphere of
  1 cm radius (:func:`.arm_physics.payload_inertia`; the torque model's point mass has none, a
  zero tensor is not positive definite), so that inverse dynamics of the exported URDF equals
  the fitted torque model's rigid-body part up to ``I |w_dot|`` (below 1e-3 N m).

* fitted kinematic joint offsets (``physics.json`` ``joints.<j>.offsets = {dtheta_rad, dd_m,
  da_m}``) are baked into the joint ``<origin>``: ``origin · Trans(da u + dd z) · Rot(z, dtheta)``
  (:func:`robogs.format.kinematics.offset_origin`; a translation along the axis for ``dtheta``
  of a prismatic joint; a mimic joint turns by ``multiplier * dtheta``), so forward kinematics
  of the exported URDF at the *measured* joint values is the fitted kinematic model, and joint
  limits stay in the measured (controller) values. URDF's ``<calibration rising/falling>``
  records where a homing switch trips; no kinematics library applies it, so it is not used.

URDF has no rotor-inertia, compliance or backlash field: joint ``armature``,
``compliance_rad_per_nm`` and ``backlash_rad`` go to the sidecar only (``joints``), with the
offsets (marked ``in_urdf``), as do the ``physics.json`` ``effects`` (each marked ``in_urdf``)
and a summary of the payload.

The sidecar schema is documented in ``docs/exports.md``.
"""

from __future__ import annotations

import json
import re
import shutil
from copy import deepcopy
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from robogs.format import Dataset
from robogs.format.errors import FormatError, InputError
from robogs.format.kinematics import Chain, chain_with_offsets, read_joint_offsets
from robogs.format.meshes import load_mesh
from robogs.format.urdf import parse_urdf_xml

from . import ExportReport, register_exporter
from .arm_physics import (
    PAYLOAD_RADIUS_M,
    PayloadSpec,
    mass_scale,
    payload_inertia,
    payload_spec,
    unique_name,
)
from .physics_model import (
    BodyInertia,
    contact_material,
    joint_dynamics,
    link_inertias,
    scene_objects,
)
from .urdf_scene import pose_matrix, scene_state

__all__ = [
    "CONTACT_FORMAT",
    "FRAME_MASS_KG",
    "FRAME_RADIUS_M",
    "MESH_SUFFIXES",
    "export_urdf",
    "frame_inertia",
    "write_mesh",
]

CONTACT_FORMAT = "robogs.contact"
_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")


def _fmt(v: float) -> str:
    return repr(float(v))


def _rpy(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (fixed-axis XYZ: R = Rz(y) Ry(p) Rx(r)) of a rotation matrix."""
    pitch = float(np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0])))  # exact near +-pi/2 too
    if abs(R[2, 0]) < 1.0 - 1e-12:
        roll = float(np.arctan2(R[2, 1], R[2, 2]))
        yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    else:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = float(np.arctan2(-R[0, 1], R[1, 1]))
    return roll, pitch, yaw


def _inertial_element(inertia: BodyInertia) -> etree._Element:
    el = etree.Element("inertial")
    xyz = " ".join(_fmt(v) for v in inertia.frame[:3, 3])
    rpy = " ".join(_fmt(v) for v in _rpy(inertia.frame[:3, :3]))
    etree.SubElement(el, "origin", xyz=xyz, rpy=rpy)
    etree.SubElement(el, "mass", value=_fmt(inertia.mass))
    J = inertia.inertia_in_frame
    etree.SubElement(
        el, "inertia",
        ixx=_fmt(J[0, 0]), ixy=_fmt(J[0, 1]), ixz=_fmt(J[0, 2]),
        iyy=_fmt(J[1, 1]), iyz=_fmt(J[1, 2]), izz=_fmt(J[2, 2]),
    )  # fmt: skip
    return el


MESH_SUFFIXES = (".stl", ".obj")
"""Mesh formats the export writes: the ones yourdfpy, MuJoCo and pybullet all load."""

FRAME_MASS_KG = 1e-6
"""kg; mass given to a non-root link that has no ``<inertial>`` (a flange or tool frame)."""

FRAME_RADIUS_M = 1e-3
"""m; such a link's inertia is a solid sphere of this radius about its origin."""


def frame_inertia() -> BodyInertia:
    """The explicit inertial of a massless frame link: ``FRAME_MASS_KG`` at its origin, the
    inertia of a solid sphere of radius ``FRAME_RADIUS_M`` (``2/5 m r^2`` = 4e-13 kg·m²)."""
    inertia = np.eye(3) * 0.4 * FRAME_MASS_KG * FRAME_RADIUS_M**2
    return BodyInertia(FRAME_MASS_KG, np.zeros(3), inertia, np.eye(4), inertia)


def write_mesh(src: Path, dst_stem: Path) -> Path:
    """Copy an STL or OBJ mesh, or convert any other mesh (PLY, DAE, ...) to binary STL.

    Args:
        src: the source mesh file.
        dst_stem: destination path without suffix.

    Returns:
        The written file (``dst_stem`` + ``.stl`` or ``.obj``).

    Raises:
        FormatError: the mesh cannot be read or has no triangles.
    """
    suffix = src.suffix.lower()
    if suffix in MESH_SUFFIXES:
        dst = dst_stem.with_suffix(suffix)
        shutil.copyfile(src, dst)
        return dst
    mesh = load_mesh(src)
    dst = dst_stem.with_suffix(".stl")
    mesh.export(str(dst), file_type="stl")
    return dst


class _MeshCopier:
    """Writes mesh files under ``OUT/meshes`` with unique, safe names, as STL or OBJ."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.by_source: dict[Path, str] = {}
        self.converted: dict[str, str] = {}  # written file -> source suffix, for non-STL/OBJ
        self.used: set[str] = set()

    def add(self, src: Path) -> str:
        src = src.resolve()
        if src in self.by_source:
            return self.by_source[src]
        stem = _SAFE.sub("_", src.stem) or "mesh"
        suffix = src.suffix.lower() if src.suffix.lower() in MESH_SUFFIXES else ".stl"
        name, k = stem, 1
        while f"{name}{suffix}" in self.used:
            name, k = f"{stem}_{k}", k + 1
        self.used.add(f"{name}{suffix}")
        (self.out / "meshes").mkdir(exist_ok=True)
        dst = write_mesh(src, self.out / "meshes" / name)
        rel = f"meshes/{dst.name}"
        if src.suffix.lower() not in MESH_SUFFIXES:
            self.converted[rel] = src.suffix.lower()
        self.by_source[src] = rel
        return rel


def _mujoco_element() -> etree._Element:
    """MuJoCo's URDF extension: keep mesh paths relative to the URDF (its URDF default strips
    folders), keep visual geometry, and do not rebalance inertias."""
    el = etree.Element("mujoco")
    etree.SubElement(
        el, "compiler", strippath="false", discardvisual="false", balanceinertia="false"
    )
    return el


def _object_urdf(name: str, inertia: BodyInertia | None, mesh_rel: str | None) -> etree._Element:
    robot = etree.Element("robot", name=name)
    robot.append(_mujoco_element())
    robot.append(_object_link(name, inertia, mesh_rel))
    return robot


def _object_link(name: str, inertia: BodyInertia | None, mesh_rel: str | None) -> etree._Element:
    link = etree.Element("link", name=name)
    if inertia is not None:
        link.append(_inertial_element(inertia))
    if mesh_rel is not None:
        for tag in ("visual", "collision"):
            g = etree.SubElement(etree.SubElement(link, tag), "geometry")
            etree.SubElement(g, "mesh", filename=mesh_rel)
    return link


def _add_frame_inertials(root: etree._Element) -> list[str]:
    """Give every non-root link without ``<inertial>`` the explicit :func:`frame_inertia`;
    returns their names. (pybullet gives such a link 1 kg; MuJoCo refuses a massless moving
    body.)"""
    children = {
        j.find("child").get("link") for j in root.findall("joint") if j.find("child") is not None
    }
    filled = []
    for link in root.findall("link"):
        if link.get("name") in children and link.find("inertial") is None:
            link.insert(0, _inertial_element(frame_inertia()))
            filled.append(link.get("name"))
    return filled


def _scene_urdf(
    robot: etree._Element,
    name: str,
    objects: list[tuple[str, etree._Element, str, np.ndarray]],
) -> tuple[etree._Element, str]:
    """A URDF of the whole scene: a root link ``world`` (the robot's root link frame), the robot
    welded to it at the identity, and each object link joined to it at its pose.

    Args:
        robot: the exported robot URDF (copied, not changed).
        name: the scene's robot name.
        objects: ``(name, link element, joint type, T_world_object)`` per object.

    Returns:
        The scene element and the name of its root link.
    """
    scene = etree.Element("robot", name=name)
    scene.append(_mujoco_element())
    names = {lk.get("name") for lk in robot.findall("link")} | {o[0] for o in objects}
    children = {j.find("child").get("link") for j in robot.findall("joint")}
    root_link = next(
        lk.get("name") for lk in robot.findall("link") if lk.get("name") not in children
    )
    world = "world" if root_link == "world" else unique_name("world", names)
    joints = {j.get("name") for j in robot.findall("joint")}
    if world != root_link:
        etree.SubElement(scene, "link", name=world)
        j = etree.SubElement(
            scene, "joint", name=unique_name(f"{world}_to_{root_link}", joints), type="fixed"
        )
        etree.SubElement(j, "parent", link=world)
        etree.SubElement(j, "child", link=root_link)
        etree.SubElement(j, "origin", xyz="0 0 0", rpy="0 0 0")
    for el in robot:
        if el.tag != "mujoco":
            scene.append(deepcopy(el))
    for obj, link, jtype, T in objects:
        scene.append(link)
        j = etree.SubElement(
            scene, "joint", name=unique_name(f"{world}_to_{obj}", joints), type=jtype
        )
        etree.SubElement(j, "parent", link=world)
        etree.SubElement(j, "child", link=obj)
        etree.SubElement(j, "origin", **_origin_attrs(T))
    return scene, world


def _scale_inertials(root: etree._Element, s: float) -> int:
    """Multiply every link's ``<mass>`` and ``<inertia>`` by ``s``; returns the links changed."""
    n = 0
    for link in root.findall("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass = inertial.find("mass")
        if mass is not None and mass.get("value") is not None:
            mass.set("value", _fmt(float(mass.get("value")) * s))
        inertia = inertial.find("inertia")
        if inertia is not None:
            for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
                if inertia.get(key) is not None:
                    inertia.set(key, _fmt(float(inertia.get(key)) * s))
        n += 1
    return n


def _add_payload(root: etree._Element, spec: PayloadSpec) -> tuple[str, str]:
    """Append the payload link and its fixed joint; returns their names."""
    link_name = unique_name("payload", {lk.get("name") for lk in root.findall("link")})
    joint_name = unique_name("payload_joint", {j.get("name") for j in root.findall("joint")})
    link = etree.SubElement(root, "link", name=link_name)
    link.append(_inertial_element(payload_inertia(spec)))
    joint = etree.SubElement(root, "joint", name=joint_name, type="fixed")
    etree.SubElement(joint, "parent", link=spec.parent)
    etree.SubElement(joint, "child", link=link_name)
    etree.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    return link_name, joint_name


def _origin_attrs(T: np.ndarray) -> dict[str, str]:
    return {
        "xyz": " ".join(_fmt(v) for v in T[:3, 3]),
        "rpy": " ".join(_fmt(v) for v in _rpy(T[:3, :3])),
    }


def _bake_offsets(root: etree._Element, chain: Chain, offsets: dict[str, Any]) -> list[str]:
    """Rewrite the ``<origin>`` of every joint the offsets move; returns their names."""
    moved = chain_with_offsets(chain, offsets)
    elements = {j.get("name"): j for j in root.findall("joint")}
    changed = []
    for k, name in enumerate(chain.tree_joint_names):
        if np.array_equal(moved.origins[k], chain.origins[k]):
            continue
        el = elements[name]
        origin = el.find("origin")
        if origin is None:
            origin = etree.Element("origin")
            el.insert(0, origin)
        for key, value in _origin_attrs(moved.origins[k]).items():
            origin.set(key, value)
        changed.append(name)
    return changed


def _joint_extras(physics: dict[str, Any] | None, offsets: dict[str, Any]) -> dict[str, dict]:
    """Sidecar ``joints`` entries of the kinematic joint effects URDF cannot hold (or, for the
    offsets, holds in the origins)."""
    table = (physics or {}).get("joints") or {}
    out: dict[str, dict[str, Any]] = {}
    for j, entry in table.items():
        if not isinstance(entry, dict):
            continue
        for key in ("compliance_rad_per_nm", "backlash_rad"):
            if entry.get(key) is not None:
                out.setdefault(j, {})[key] = float(entry[key])
    for j, o in offsets.items():
        out.setdefault(j, {})["offsets"] = {
            "dtheta_rad": o.dtheta,
            "dd_m": o.dd,
            "da_m": o.da,
            "in_urdf": True,
        }
    return out


def _write_xml(root: etree._Element, path: Path) -> None:
    path.write_bytes(
        etree.tostring(root, xml_declaration=True, encoding="utf-8", pretty_print=True)
    )


def export_urdf(ds: Dataset, out: Path, *, objects: bool = True) -> ExportReport:
    """Write the robot URDF with physics, its meshes, the contact sidecar and object URDFs.

    Args:
        ds: the dataset (must have a robot).
        out: output folder (exists, empty).
        objects: also write one single-link URDF per scene object of ``physics.json``.

    Returns:
        The report; ``facts`` has ``links``, ``joints`` and ``objects`` counts.

    Raises:
        InputError: the dataset has no robot.
    """
    if not (ds.manifest.get("robot") or {}).get("urdf"):
        raise InputError(
            "dataset has no robot (manifest 'robot.urdf' is missing)",
            path=ds.manifest_path,
            hint="the urdf export needs robot/robot.urdf",
        )
    urdf = ds.urdf(load_meshes=True)
    physics = ds.physics() if ds.manifest.get("physics") else None
    root = parse_urdf_xml(ds.urdf_path, verbatim=True)
    robot_name = _SAFE.sub("_", root.get("name") or "robot")
    meshes = _MeshCopier(out)
    uri_to_path = {ref.uri: ref.path for ref in urdf.robogs_mesh_refs if ref.path is not None}

    inertias = link_inertias(urdf, physics)
    overrides = set((physics or {}).get("objects", {})) & {lk.name for lk in urdf.robot.links}
    for link in root.findall("link"):
        name = link.get("name")
        if name in overrides and name in inertias and "mass_kg" in physics["objects"][name]:
            old = link.find("inertial")
            new = _inertial_element(inertias[name])
            if old is not None:
                link.replace(old, new)
            else:
                link.insert(0, new)
        if link.find("collision") is None:
            for vis in link.findall("visual"):
                col = etree.SubElement(link, "collision")
                if vis.get("name"):
                    col.set("name", vis.get("name"))
                for child in vis:
                    if child.tag in ("origin", "geometry"):
                        col.append(deepcopy(child))
    for mesh in root.iter("mesh"):
        uri = mesh.get("filename", "")
        src = uri_to_path.get(uri)
        if src is None:
            raise FormatError(
                "mesh URI was not resolved by the loader", path=ds.urdf_path, where=uri
            )
        mesh.set("filename", meshes.add(src))

    dynamics = joint_dynamics(urdf, physics)
    for joint in root.findall("joint"):
        dyn = dynamics.get(joint.get("name", ""))
        if dyn is None or (dyn.damping is None and dyn.friction is None):
            continue
        el = joint.find("dynamics")
        if el is None:
            el = etree.SubElement(joint, "dynamics")
        el.set("damping", _fmt(dyn.damping or 0.0))
        el.set("friction", _fmt(dyn.friction or 0.0))
    notes: list[str] = []
    phys_path = ds.root / "physics.json"
    chain = Chain.from_urdf(urdf, floating_as_fixed=True)
    offsets = read_joint_offsets(physics, chain.joint_names, path=phys_path)
    if offsets:
        moved = _bake_offsets(root, chain, offsets)
        notes.append(
            f"kinematic offsets of {len(offsets)} joint(s) baked into the origins of "
            f"{len(moved)} joint(s)"
        )
    scale = mass_scale(physics, path=phys_path)
    if scale is not None:
        n = _scale_inertials(root, scale)
        notes.append(f"mass_scale {scale:.6g} applied to the mass and inertia of {n} link(s)")
    payload = payload_spec(physics, urdf, ds.manifest, path=phys_path)
    payload_entry: dict[str, Any] | None = None
    if payload is not None:
        link_name, joint_name = _add_payload(root, payload)
        payload_entry = {
            "link": link_name,
            "joint": joint_name,
            "parent": payload.parent,
            "mass_kg": payload.mass,
            "com_m": [float(v) for v in payload.com],
            "inertia": f"solid sphere of radius {PAYLOAD_RADIUS_M} m about the CoM",
            "inertia_kgm2": float(payload_inertia(payload).inertia[0, 0]),
        }
        notes.append(
            f"payload {payload.mass:.4g} kg written as link {link_name!r} fixed to {payload.parent!r}"
        )
    filled = _add_frame_inertials(root)
    if filled:
        notes.append(
            f"{len(filled)} link(s) without <inertial> given {FRAME_MASS_KG:g} kg: "
            + ", ".join(filled)
        )
    root.insert(0, _mujoco_element())
    _write_xml(root, out / f"{robot_name}.urdf")

    objs = scene_objects(ds, physics, {lk.name for lk in urdf.robot.links})
    contact: dict[str, Any] = {
        "format": CONTACT_FORMAT,
        "version": 1,
        "robot": robot_name,
        "urdf": f"{robot_name}.urdf",
        "units": {
            "friction_static": "1 (Coulomb coefficient)",
            "friction_dynamic": "1 (Coulomb coefficient)",
            "restitution": "1",
            "armature": "kg·m² (revolute) | kg (prismatic)",
            "compliance_rad_per_nm": "rad/(N·m) (revolute) | m/N (prismatic)",
            "backlash_rad": "rad, half-width of the dead band (revolute) | m (prismatic)",
            "offsets": "dtheta_rad rad (m if prismatic), dd_m m, da_m m; in the URDF origins",
            "gravity_mps2": "m/s², world frame, z up",
        },
        "gravity_mps2": list((physics or {}).get("gravity_mps2", [0.0, 0.0, -9.81])),
        "links": {},
        "joints": {},
        "objects": {},
        "contacts": dict((physics or {}).get("contacts", {})),
        "source": {"dataset": ds.name, "physics_revision": (physics or {}).get("revision")},
    }
    for link in urdf.robot.links:
        mat = contact_material((physics or {}).get("objects", {}).get(link.name)).as_dict()
        if mat:
            contact["links"][link.name] = mat
    for jname, dyn in dynamics.items():
        if dyn.armature is not None:
            contact["joints"][jname] = {"armature": dyn.armature}
    for jname, extra in _joint_extras(physics, offsets).items():
        if jname in dynamics:
            contact["joints"].setdefault(jname, {}).update(extra)
    if payload_entry is not None:
        contact["payload"] = payload_entry
    effects = [
        {**e, "in_urdf": e.get("name") == "mass_scale"}
        for e in (physics or {}).get("effects", []) or []
    ]
    if effects:
        contact["effects"] = effects
    if filled:
        contact["frame_inertials"] = {
            "links": filled,
            "mass_kg": FRAME_MASS_KG,
            "inertia_kgm2": float(frame_inertia().inertia[0, 0]),
            "why": "links without <inertial> (frames such as tool0) get this explicit tiny "
            f"inertial (solid sphere of radius {FRAME_RADIUS_M} m at the link origin): pybullet "
            "gives a link without one 1 kg, MuJoCo refuses a massless moving body",
        }
    files = [f"{robot_name}.urdf", f"{robot_name}.contact.json"]
    state = scene_state(ds, [o.name for o in objs])
    scene_entry: dict[str, Any] = {
        "episode": state.episode,
        "t_ns": state.t_ns,
        "time": "start of the first episode; each object's pose is its first sample there",
        "world": "the robot's root link frame; the robot is at the identity",
        "pose_order": "[x, y, z, qw, qx, qy, qz], m and a unit quaternion, T_world_object",
        "joint_positions": state.joint_positions,
        "joint_positions_t_ns": state.joint_positions_t_ns,
        "objects": {},
    }
    scene_objs: list[tuple[str, etree._Element, str, np.ndarray]] = []
    for obj in objs:
        entry: dict[str, Any] = {"equation": obj.equation, **obj.material.as_dict()}
        pose = state.objects[obj.name]
        jtype = "floating" if obj.equation == "rigid" and obj.inertia is not None else "fixed"
        scene_entry["objects"][obj.name] = {**pose.as_dict(), "joint": jtype}
        if objects:
            folder = out / "objects" / _SAFE.sub("_", obj.name)
            folder.mkdir(parents=True)
            mesh_rel = None
            if obj.mesh_path is not None:
                mesh_rel = write_mesh(obj.mesh_path, folder / "mesh").name
                if obj.mesh_path.suffix.lower() not in MESH_SUFFIXES:
                    meshes.converted[f"objects/{folder.name}/{mesh_rel}"] = (
                        obj.mesh_path.suffix.lower()
                    )
                files.append(f"objects/{folder.name}/{mesh_rel}")
            rel = f"objects/{folder.name}/{folder.name}.urdf"
            _write_xml(_object_urdf(obj.name, obj.inertia, mesh_rel), out / rel)
            entry["urdf"] = rel
            files.append(rel)
            scene_mesh = None if mesh_rel is None else f"objects/{folder.name}/{mesh_rel}"
            link = _object_link(obj.name, obj.inertia, scene_mesh)
            scene_objs.append((obj.name, link, jtype, pose_matrix(pose.pose)))
            if obj.equation == "rigid" and obj.inertia is None:
                notes.append(f"rigid object {obj.name!r} has no mass_kg: fixed in scene.urdf")
        contact["objects"][obj.name] = entry
    if objects:
        scene, world = _scene_urdf(root, f"{robot_name}_scene", scene_objs)
        _write_xml(scene, out / "scene.urdf")
        files.insert(2, "scene.urdf")
        scene_entry["urdf"] = "scene.urdf"
        scene_entry["root_link"] = world
    contact["scene"] = scene_entry
    if meshes.converted:
        contact["converted_meshes"] = {
            rel: f"converted from {suffix} to binary STL (geometry only)"
            for rel, suffix in sorted(meshes.converted.items())
        }
    (out / f"{robot_name}.contact.json").write_text(
        json.dumps(contact, indent=2, ensure_ascii=False) + "\n"
    )
    files += sorted(meshes.by_source.values())
    return ExportReport(
        out=out,
        files=files,
        notes=notes,
        facts={
            "links": len(urdf.robot.links) + (payload is not None),
            "joints": len(urdf.robot.joints) + (payload is not None),
            "objects": len(objs),
            "frame_inertials": filled,
            "converted_meshes": sorted(meshes.converted),
            **({"payload": payload_entry} if payload_entry else {}),
            **({"mass_scale": scale} if scale is not None else {}),
            **({"offset_joints": sorted(offsets)} if offsets else {}),
        },
    )


register_exporter(
    "urdf",
    export_urdf,
    output="folder",
    help="URDF with inertials, joint dynamics, collision meshes + contact sidecar",
)

"""The dataset's URDF robot as MJCF bodies, driven kinematically, for the MuJoCo scene document.

What does what:

* **MuJoCo's own URDF compiler reads the URDF** (``mujoco.MjSpec.from_string``, see MuJoCo's
  documentation, "URDF extensions"): rpy -> quaternions, joint types, axes and limits, inertials,
  primitive and mesh geometry, ``<mimic>`` -> a joint ``<equality>`` with ``polycoef = (offset,
  multiplier)``. robogs only prepares its input: the URDF is parsed by the one hardened parser
  (:func:`robogs.format.urdf.load_urdf`, entities and DTDs refused, tree checked), every mesh URI
  is resolved inside the allowed root (:func:`robogs.format.urdf.resolve_mesh_uri`: ``file://``,
  absolute paths, ``..`` and symbolic links out are refused) and rewritten to the converted file,
  and a ``<mujoco><compiler>`` element asks for every link as a body (``fusestatic="false"``),
  visual geometry kept, inertias as written and paths as given.
* **robogs writes the document** from the compiled model (bodies' frames, joints' axes, ranges and
  limits, inertials: all float64, written with ``repr``) and from the spec (geometry: MuJoCo
  re-centres a mesh at its own centroid when it compiles, so the mesh geoms' frames are the
  uncompiled ones). MuJoCo's writer ``MjSpec.to_xml`` is not used: it prints 6 significant digits
  (a joint origin of rpy 0.3 becomes quat ``0.988771 0.149438 0 0``; a 1e-6 kg frame link's
  inertia 4e-13 kg m^2 becomes 0), and its round trip moved the Franka Panda's links by up to
  1.15e-6 (m and rotation-matrix entries, 20 random poses; mujoco 3.17), over the 1e-6 m /
  1e-6 rad the forward kinematics must keep. Written this way, the four real arms of
  ``../shared/fixtures/real`` match robogs' own forward kinematics to 1e-15.
* **Meshes**: an STL is copied byte for byte; DAE, PLY, GLB, glTF and OBJ are read by
  :func:`robogs.format.meshes.load_mesh` (COLLADA first checked for entities) and written as OBJ
  (positions and triangles only, 12 digits), so the vertex count MuJoCo compiles equals the
  source's. Each mesh is compiled alone first. One MuJoCo refuses is, in this order: kept with
  ``inertia="shell"`` (MuJoCo's own advice when a flat or tiny mesh has too small a volume; the
  geometry is unchanged), replaced by its convex hull (:func:`robogs.format.mjcf.collision_hull`,
  decimated to :data:`robogs.format.mjcf.MAX_HULL_VERTICES` vertices), or dropped (fewer than 4
  vertices); :attr:`MjcfRobot.notes` and :attr:`MjcfRobot.conversions` say which. File names are made from ``[A-Za-z0-9_.-]`` only,
  under ``meshdir``, so nothing is written outside the output folder.

**Kinematic, not dynamic.** The robot is driven by the recorded joints and acts on nothing:

* its geoms have ``contype = conaffinity = 0`` and no ``<pair>``, so the scene's contacts are
  exactly the fitted ones (the pusher primitive stays the contact proxy of the end effector);
* every robot body has ``gravcomp="1"`` (gravity has no effect on it);
* every joint has ``armature`` :data:`ROBOT_ARMATURE` (kg m^2 or kg) and two servos, the
  pusher's design (``robogs.format.mjcf``): a position servo ``robot_<joint>`` (ctrl: target, rad
  or m) and a velocity servo ``robot_v_<joint>`` (ctrl: target velocity), ``kp = 0.3 A / dt^2``,
  ``kv = A / dt`` (dead-beat velocity tracking with explicit forces, the link inertias being
  small next to ``A``). A mocap body was not used: MuJoCo gives mocap bodies zero velocity in
  the solver and mocap bodies cannot form a joint tree, so the recorded joint values could not be
  replayed as joint values. A mimic joint has no servo; MuJoCo's equality moves it.
* the URDF's effort limits and ``<dynamics>`` are not written (they would stop the replay);
  ``floating`` and ``planar`` joints are frozen at their origin (as
  :meth:`robogs.format.kinematics.Chain.from_urdf` with ``floating_as_fixed``); a moving link
  without ``<inertial>`` gets :data:`FRAME_MASS_KG` as a solid sphere of :data:`FRAME_RADIUS_M`
  (MuJoCo refuses a massless moving body). Each is said in the notes.

World frame: the robot's root link is the world (robogs' world origin is the robot base), so the
root body sits at the identity and a link's ``xpos``/``xmat`` is ``T_root_link``.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import FormatError

__all__ = [
    "FRAME_MASS_KG",
    "FRAME_RADIUS_M",
    "ROBOT_ARMATURE",
    "MeshConversion",
    "MjcfRobot",
    "add_robot",
    "document_names",
    "robot_document",
    "robot_mjcf",
    "robot_qpos",
]

ROBOT_ARMATURE = 1000.0
"""kg m^2 (hinge) or kg (slide): added inertia of every robot joint, so that the servos track
the recorded joints whatever the links weigh (the pusher body's 1000 kg, same reason)."""

FRAME_MASS_KG = 1e-6
"""kg given to a moving link without ``<inertial>`` (as ``robogs export urdf`` does)."""

FRAME_RADIUS_M = 1e-3
"""m: that link's inertia is a solid sphere of this radius about its origin."""

_SAFE = re.compile(r"[^A-Za-z0-9_.-]+")
_COPY = (".stl",)
_CONVERT = (".dae", ".ply", ".glb", ".gltf", ".obj")
_GEOM_SIZES = {"sphere": 1, "capsule": 2, "cylinder": 2, "ellipsoid": 3, "box": 3}


def _f(v: float) -> str:
    return repr(float(v))


def _vec(vs: Sequence[float]) -> str:
    return " ".join(_f(v) for v in vs)


@dataclass(frozen=True)
class MeshConversion:
    """What became of one mesh file of the URDF.

    Attributes:
        source: the resolved source file.
        file: the written file, relative to the document (``None``: dropped).
        action: ``copied`` (STL as is), ``converted`` (to OBJ), ``hulled`` or ``dropped``.
        shell: MuJoCo computes the mesh's centroid and inertia over its surface
            (``inertia="shell"``), because it refuses the volume of a flat or tiny mesh.
        vertices_in: the source's vertex count (trimesh, as loaded; STL: distinct positions).
        vertices_out: the vertex count MuJoCo compiles from ``file`` (0 when dropped).
        why: the reason for ``hulled``/``dropped`` (MuJoCo's message), else ``""``.
    """

    source: Path
    file: str | None
    action: str
    vertices_in: int
    vertices_out: int
    why: str = ""
    shell: bool = False


@dataclass
class MjcfRobot:
    """MJCF elements of a robot (see the module docstring for the choices).

    Attributes:
        name: the URDF's robot name.
        root: the root link (the world frame).
        links: link name -> MuJoCo body name (prefixed; the root link named ``world`` maps to
            MuJoCo's world body ``world``).
        joints: MuJoCo joints of the robot in qpos order (URDF names, prefixed), each one qpos.
        actuated: the joints with servos, in :class:`robogs.format.kinematics.Chain`'s
            ``joint_names`` order (URDF names, not prefixed): the columns of a recorded ``q``.
        mimic: mimic joint -> (source joint, multiplier, offset), URDF names.
        bodies: the root link's child ``<body>`` elements (or its own), for ``<worldbody>``.
        root_geoms: geoms of the root link when it is MuJoCo's world body.
        meshes: ``<mesh>`` asset elements.
        equality: ``<joint>`` equality elements (mimic joints).
        files: relative file path -> bytes of every mesh to write beside the document.
        conversions: one :class:`MeshConversion` per distinct mesh file.
        notes: one line per substitution or simplification.
        prefix: the name prefix of every element.
    """

    name: str
    root: str
    links: dict[str, str]
    joints: list[str]
    actuated: list[str]
    mimic: dict[str, tuple[str, float, float]]
    bodies: list[ET.Element] = field(default_factory=list)
    root_geoms: list[ET.Element] = field(default_factory=list)
    meshes: list[ET.Element] = field(default_factory=list)
    equality: list[ET.Element] = field(default_factory=list)
    files: dict[str, bytes] = field(default_factory=dict)
    conversions: list[MeshConversion] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    prefix: str = ""

    def names(self) -> set[str]:
        """Every body, joint and mesh name this robot adds to a document."""
        out = {v for k, v in self.links.items() if v != "world"} | set(self.joints)
        out |= {m.get("name", "") for m in self.meshes}
        return out


# --------------------------------------------------------------------------- meshes


def _compile_mesh_alone(fname: str, data: bytes, shell: bool = False) -> int:
    """Vertex count MuJoCo compiles from one mesh file (raises ValueError when it refuses)."""
    import mujoco

    attrs = ' inertia="shell"' if shell else ""
    xml = (
        '<mujoco><compiler inertiafromgeom="false"/>'
        f'<asset><mesh name="m" file="{fname}"{attrs}/></asset>'
        '<worldbody><body><joint/><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>'
        '<geom type="mesh" mesh="m" contype="0" conaffinity="0"/></body></worldbody></mujoco>'
    )
    model = mujoco.MjModel.from_xml_string(xml, {fname: data})
    return int(model.mesh_vertnum[0])


def _obj_bytes(mesh: Any) -> bytes:
    import trimesh

    text = trimesh.exchange.obj.export_obj(
        mesh, include_normals=False, include_color=False, include_texture=False, digits=12
    )
    return text.encode()


class _MeshWriter:
    """Converts each distinct source mesh once and names the written file uniquely."""

    def __init__(self, meshdir: str, urdf_path: Path) -> None:
        self.meshdir = meshdir
        self.urdf_path = urdf_path
        self.by_source: dict[Path, MeshConversion] = {}
        self.files: dict[str, bytes] = {}
        self.used: set[str] = set()
        self.notes: list[str] = []

    def _name(self, src: Path, suffix: str) -> str:
        stem = "robot_" + (_SAFE.sub("_", src.stem).strip("._") or "mesh")
        name, k = stem, 1
        while name.lower() in self.used:
            name, k = f"{stem}_{k}", k + 1
        self.used.add(name.lower())
        return f"{self.meshdir}{name}{suffix}"

    def add(self, src: Path, where: str) -> MeshConversion:
        from robogs.format.meshes import load_mesh
        from robogs.format.urdf import _check_dae

        if src in self.by_source:
            return self.by_source[src]
        suffix = src.suffix.lower()
        if suffix not in _COPY + _CONVERT:
            raise FormatError(
                f"unsupported mesh type '{src.suffix}'",
                path=self.urdf_path,
                where=where,
                hint=f"use one of {sorted(_COPY + _CONVERT)}",
            )
        if suffix == ".dae":
            _check_dae(src)
        mesh = load_mesh(src, where=where, process=False)
        if suffix in _COPY:
            fname, data = self._name(src, ".stl"), src.read_bytes()
            # MuJoCo keeps one vertex per distinct position of an STL: count those
            n_in, action = len(np.unique(np.asarray(mesh.vertices), axis=0)), "copied"
        else:
            fname, data = self._name(src, ".obj"), _obj_bytes(mesh)
            n_in, action = len(mesh.vertices), "converted"
        why = ""
        try:
            n_out = _compile_mesh_alone(fname, data)
        except ValueError as exc:
            why = str(exc).splitlines()[0].removeprefix("Error: ")
            conv = self._fallback(src, mesh, fname, data, action, n_in, why)
        else:
            conv = MeshConversion(src, fname, action, n_in, n_out)
            self.files[fname] = data
        self.by_source[src] = conv
        return conv

    def _fallback(
        self, src: Path, mesh: Any, fname: str, data: bytes, action: str, n_in: int, why: str
    ) -> MeshConversion:
        """MuJoCo refused the mesh: its surface inertia (``inertia="shell"``, MuJoCo's own
        advice for a flat or tiny mesh, geometry unchanged), else its convex hull, else drop."""
        from robogs.format.mjcf import collision_hull

        try:
            n_out = _compile_mesh_alone(fname, data, shell=True)
        except ValueError:
            pass
        else:
            self.files[fname] = data
            self.notes.append(
                f"mesh {src.name} kept with inertia='shell' (surface centroid; its volume is "
                f"refused: {why}); vertices {n_in} -> {n_out}"
            )
            return MeshConversion(src, fname, action, n_in, n_out, why, shell=True)
        try:
            hull, _ = collision_hull(mesh, src.name)
            fname = fname.rsplit(".", 1)[0] + "_hull.obj"
            data = _obj_bytes(hull)
            n_out = _compile_mesh_alone(fname, data)
        except (FormatError, ValueError):
            self.notes.append(f"mesh {src.name} dropped: MuJoCo refuses it ({why}), and its hull")
            return MeshConversion(src, None, "dropped", n_in, 0, why)
        self.files[fname] = data
        self.notes.append(
            f"mesh {src.name} replaced by its convex hull ({n_in} -> {n_out} vertices): "
            f"MuJoCo refuses it ({why})"
        )
        return MeshConversion(src, fname, "hulled", n_in, n_out, why)


# --------------------------------------------------------------------------- URDF -> MJCF


def _frame_inertial() -> Any:
    from lxml import etree

    el = etree.Element("inertial")
    etree.SubElement(el, "origin", xyz="0 0 0", rpy="0 0 0")
    etree.SubElement(el, "mass", value=_f(FRAME_MASS_KG))
    i = _f(0.4 * FRAME_MASS_KG * FRAME_RADIUS_M**2)
    etree.SubElement(el, "inertia", ixx=i, ixy="0", ixz="0", iyy=i, iyz="0", izz=i)
    return el


def _prepared_urdf(
    path: Path,
    root: Path | None,
    package_roots: Mapping[str, Any] | None,
    writer: _MeshWriter | None,
    notes: list[str],
) -> tuple[bytes, dict[str, MeshConversion]]:
    """The URDF text MuJoCo compiles: meshes rewritten to their converted files, a compiler
    element, floating/planar joints fixed, frame inertials added."""
    from lxml import etree

    from robogs.format.urdf import parse_urdf_xml, resolve_mesh_file

    xml = parse_urdf_xml(path)
    for old in xml.findall("mujoco"):
        xml.remove(old)
    xml.insert(
        0,
        etree.fromstring(
            '<mujoco><compiler strippath="false" discardvisual="false" '
            'balanceinertia="false" fusestatic="false" meshdir="" /></mujoco>'
        ),
    )
    cache: dict[str, Path] = {}
    by_uri: dict[str, MeshConversion] = {}
    for link in xml.findall("link"):
        for kind in ("visual", "collision"):
            for item in link.findall(kind):
                mesh = item.find("geometry/mesh")
                if mesh is None:
                    continue
                if writer is None:
                    link.remove(item)
                    continue
                uri = mesh.get("filename", "")
                where = f"link '{link.get('name')}' {kind} mesh '{uri}'"
                src = resolve_mesh_file(
                    uri,
                    path,
                    root,
                    package_roots,
                    where=where,
                    missing_hint="check the dataset's robot folder (or package_roots/root)",
                    cache=cache,
                )
                conv = writer.add(src, where)
                by_uri[uri] = conv
                if conv.file is None:
                    link.remove(item)
                else:
                    mesh.set("filename", conv.file)
    frozen = []
    moving_children = set()
    for joint in xml.findall("joint"):
        if joint.get("type") in ("floating", "planar"):
            frozen.append(joint.get("name"))
            joint.set("type", "fixed")
        if joint.get("type") != "fixed":
            child = joint.find("child")
            if child is not None:
                moving_children.add(child.get("link"))
    if frozen:
        notes.append(f"floating/planar joint(s) frozen at their origin: {', '.join(frozen)}")
    filled = []
    for link in xml.findall("link"):
        if link.get("name") in moving_children and link.find("inertial") is None:
            link.insert(0, _frame_inertial())
            filled.append(link.get("name"))
    if filled:
        notes.append(
            f"moving link(s) without <inertial> given {FRAME_MASS_KG:g} kg: {', '.join(filled)}"
        )
    return etree.tostring(xml), by_uri


def _body_element(spec_body: Any, model: Any, prefix: str, links: dict[str, str]) -> ET.Element:
    import mujoco

    b = model.body(spec_body.name)
    el = ET.Element(
        "body",
        name=prefix + spec_body.name,
        pos=_vec(model.body_pos[b.id]),
        quat=_vec(model.body_quat[b.id]),
        gravcomp="1",
    )
    links[spec_body.name] = prefix + spec_body.name
    if spec_body.explicitinertial:
        ET.SubElement(
            el,
            "inertial",
            pos=_vec(model.body_ipos[b.id]),
            quat=_vec(model.body_iquat[b.id]),
            mass=_f(model.body_mass[b.id]),
            diaginertia=_vec(model.body_inertia[b.id]),
        )
    for j in spec_body.joints:
        mj = model.joint(j.name)
        kind = {mujoco.mjtJoint.mjJNT_HINGE: "hinge", mujoco.mjtJoint.mjJNT_SLIDE: "slide"}.get(
            j.type
        )
        if kind is None:
            raise FormatError(f"unexpected MuJoCo joint type {j.type}", where=f"joint '{j.name}'")
        attrs = {
            "name": prefix + j.name,
            "type": kind,
            "pos": _vec(model.jnt_pos[mj.id]),
            "axis": _vec(model.jnt_axis[mj.id]),
            "armature": _f(ROBOT_ARMATURE),
            "limited": "true" if model.jnt_limited[mj.id] else "false",
        }
        if model.jnt_limited[mj.id]:
            attrs["range"] = _vec(model.jnt_range[mj.id])
        ET.SubElement(el, "joint", **attrs)
    _geoms(el, spec_body, prefix)
    for child in spec_body.bodies:
        el.append(_body_element(child, model, prefix, links))
    return el


def _geoms(parent: ET.Element, spec_body: Any, prefix: str) -> None:
    for g in spec_body.geoms:
        kind = str(g.type).rsplit("_", 1)[-1].lower()
        visual = int(g.contype) == 0 and int(g.conaffinity) == 0
        attrs = {
            "type": kind,
            "pos": _vec(g.pos),
            "quat": _vec(g.quat),
            "contype": "0",
            "conaffinity": "0",
            "group": "1" if visual else "3",
            "rgba": _vec(g.rgba),
        }
        if kind == "mesh":
            attrs["mesh"] = prefix + g.meshname
        elif kind in _GEOM_SIZES:
            attrs["size"] = _vec(list(g.size)[: _GEOM_SIZES[kind]])
        else:
            raise FormatError(f"unexpected geom type {kind!r}", where=f"body '{spec_body.name}'")
        ET.SubElement(parent, "geom", **attrs)


def robot_mjcf(
    urdf_path: str | os.PathLike[str],
    *,
    root: str | os.PathLike[str] | None = None,
    package_roots: Mapping[str, str | os.PathLike[str]] | None = None,
    meshdir: str = "meshes/robot/",
    prefix: str = "",
    meshes: bool = True,
) -> MjcfRobot:
    """Turn a URDF into MJCF elements (module docstring: what MuJoCo does, what robogs does).

    Args:
        urdf_path: the ``.urdf`` file.
        root: allowed root of its mesh files (default: :func:`robogs.format.urdf.
            default_allowed_root`; a dataset passes its root).
        package_roots: explicit ``{package: folder}`` for ``package://`` URIs.
        meshdir: folder of the written meshes, relative to the document (``[A-Za-z0-9_./-]``,
            no ``..``, ending in ``/``).
        prefix: prefix of every body, joint and mesh name (to avoid names the scene has).
        meshes: False leaves every mesh geom out (kinematics, inertials and primitive geometry
            only; no mesh file is read).

    Returns:
        The elements, mesh bytes and notes.

    Raises:
        InputError: the URDF is missing.
        FormatError: hostile or malformed URDF, missing or unreadable mesh, a model MuJoCo
            refuses (its message, with the element it names).
        PathEscapeError: a mesh URI outside the allowed root.
    """
    import mujoco

    from robogs.format.kinematics import Chain
    from robogs.format.urdf import load_urdf

    path = Path(urdf_path)
    if (
        not re.fullmatch(r"([A-Za-z0-9_.-]+/)*", meshdir)
        or ".." in meshdir.split("/")
        or meshdir.startswith("/")
    ):
        raise FormatError(
            f"meshdir {meshdir!r} must be a relative folder inside the output",
            where="meshdir",
            hint='e.g. "meshes/robot/"',
        )
    urdf = load_urdf(path, root=root, package_roots=package_roots, load_meshes=False)
    chain = Chain.from_urdf(urdf, floating_as_fixed=True)
    notes: list[str] = []
    writer = _MeshWriter(meshdir, path)
    text, _ = _prepared_urdf(
        path, root and Path(root), package_roots, writer if meshes else None, notes
    )
    notes += writer.notes
    if not meshes:
        notes.append("mesh geometry left out (meshes=False)")
    shells = {c.file for c in writer.by_source.values() if c.shell}
    try:
        spec = mujoco.MjSpec.from_string(text.decode(), assets=dict(writer.files))
        for m in spec.meshes:
            if m.file in shells:
                m.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
        model = spec.compile()
    except ValueError as exc:
        raise FormatError(
            f"MuJoCo refuses the robot: {' '.join(str(exc).split())}",
            path=path,
            hint="the element MuJoCo names is in the URDF (masses and inertias must be > 0)",
        ) from None
    world = spec.worldbody
    root_name = chain.link_names[0]
    links: dict[str, str] = {}
    robot = MjcfRobot(
        name=urdf.robot.name,
        root=root_name,
        links=links,
        joints=[],
        actuated=list(chain.joint_names),
        mimic={},
        files=dict(writer.files),
        conversions=list(writer.by_source.values()),
        notes=notes,
        prefix=prefix,
    )
    if root_name == "world":  # MuJoCo's URDF compiler makes a root link 'world' its world body
        links["world"] = "world"
        holder = ET.Element("body")
        _geoms(holder, world, prefix)
        robot.root_geoms = list(holder)
        robot.bodies = [_body_element(b, model, prefix, links) for b in world.bodies]
    else:
        robot.bodies = [_body_element(b, model, prefix, links) for b in world.bodies]
    robot.joints = [prefix + model.joint(i).name for i in range(model.njnt)]
    for m in spec.meshes:
        attrs = {"name": prefix + m.name, "file": m.file}
        if not np.allclose(m.scale, 1.0):
            attrs["scale"] = _vec(m.scale)
        if m.file in shells:
            attrs["inertia"] = "shell"
        robot.meshes.append(ET.Element("mesh", **attrs))
    for e in spec.equalities:
        if e.type != mujoco.mjtEq.mjEQ_JOINT:
            raise FormatError(f"unexpected MuJoCo equality {e.type}", path=path)
        robot.equality.append(
            ET.Element(
                "joint",
                joint1=prefix + e.name1,
                joint2=prefix + e.name2,
                polycoef=_vec(e.data[:5]),
            )
        )
    for j in urdf.robot.joints:
        if j.mimic is not None and j.type not in ("fixed", "floating", "planar"):
            robot.mimic[j.name] = (
                j.mimic.joint,
                1.0 if j.mimic.multiplier is None else float(j.mimic.multiplier),
                0.0 if j.mimic.offset is None else float(j.mimic.offset),
            )
    return robot


def robot_qpos(robot: MjcfRobot, q: Any) -> np.ndarray:
    """Joint values of every MuJoCo robot joint (:attr:`MjcfRobot.joints` order) from the actuated
    ones (mimic joints: ``multiplier * q[source] + offset``).

    Args:
        robot: the robot.
        q: [..., J] in :attr:`MjcfRobot.actuated` order (rad, m).

    Returns:
        [..., len(robot.joints)] float64.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (len(robot.actuated),):
        raise FormatError(
            f"q has shape {q.shape}, expected [..., {len(robot.actuated)}]",
            hint=f"joint order: {robot.actuated}",
        )
    col = {n: i for i, n in enumerate(robot.actuated)}
    out = np.zeros((*q.shape[:-1], len(robot.joints)))
    for k, name in enumerate(robot.joints):
        urdf_name = name[len(robot.prefix) :]
        if urdf_name in col:
            out[..., k] = q[..., col[urdf_name]]
        elif urdf_name in robot.mimic:
            src, mul, off = robot.mimic[urdf_name]
            out[..., k] = mul * q[..., col[src]] + off
        else:
            raise FormatError(f"robot joint {urdf_name!r} is neither actuated nor a mimic")
    return out


# --------------------------------------------------------------------------- documents


def _servos(robot: MjcfRobot, timestep: float) -> list[ET.Element]:
    pos, vel = [], []
    for j in robot.actuated:
        name = robot.prefix + j
        pos.append(
            ET.Element(
                "position",
                name=f"robot_{name}",
                joint=name,
                kp=_f(0.3 * ROBOT_ARMATURE / timestep**2),
                ctrllimited="false",
                forcelimited="false",
            )
        )
        vel.append(
            ET.Element(
                "velocity",
                name=f"robot_v_{name}",
                joint=name,
                kv=_f(ROBOT_ARMATURE / timestep),
                ctrllimited="false",
                forcelimited="false",
            )
        )
    return pos + vel


def _child(root: ET.Element, tag: str, before: Sequence[str] = ()) -> ET.Element:
    el = root.find(tag)
    if el is None:
        el = ET.Element(tag)
        idx = len(root)
        for k, c in enumerate(root):
            if c.tag in before:
                idx = k
                break
        root.insert(idx, el)
    return el


def document_names(xml: str) -> set[str]:
    """Every ``name`` attribute of an MJCF document (to choose a :func:`robot_mjcf` prefix)."""
    return {el.get("name") for el in ET.fromstring(xml).iter() if el.get("name")}


def add_robot(
    scene_xml: str, robot: MjcfRobot, q0: Sequence[float] | None = None
) -> tuple[str, list[str]]:
    """Put the robot into a scene document (e.g. :func:`robogs.format.mjcf.scene_mjcf`'s).

    The robot's bodies come after the scene's (the scene's qpos, qvel and ctrl indices do not
    move), its servos after the scene's actuators, its meshes into ``<asset>``, its mimic
    equalities into ``<equality>``. Every ``<key>`` gets the robot's joints at ``q0`` appended to
    its ``qpos`` and a ``ctrl`` (the scene's part zeros, the robot's position servos ``q0``,
    velocity servos 0).

    Args:
        scene_xml: the scene document.
        robot: from :func:`robot_mjcf`.
        q0: [J] actuated joint values (:attr:`MjcfRobot.actuated` order; default zeros).

    Returns:
        (the document, the robot's actuator names in ctrl order).

    Raises:
        FormatError: a robot name is already a scene name (pass a ``prefix``).
    """
    root = ET.fromstring(scene_xml)
    clash = sorted(robot.names() & document_names(scene_xml))
    if clash:
        raise FormatError(
            f"robot names already used by the scene: {clash[:5]}",
            where="robot",
            hint="build the robot with robot_mjcf(..., prefix='robot/')",
        )
    option = root.find("option")
    dt = float(option.get("timestep", 0.002)) if option is not None else 0.002
    world = _child(root, "worldbody")
    for g in robot.root_geoms:
        world.append(g)
    for b in robot.bodies:
        world.append(b)
    if robot.meshes:
        asset = _child(root, "asset", before=("worldbody",))
        asset.extend(robot.meshes)
    if robot.equality:
        eq = _child(root, "equality", before=("actuator", "keyframe", "custom"))
        eq.extend(robot.equality)
    servos = _servos(robot, dt)
    nu_scene = 0
    if servos:
        act = _child(root, "actuator", before=("keyframe", "custom"))
        nu_scene = len(act)
        act.extend(servos)
    q = np.zeros(len(robot.actuated)) if q0 is None else np.asarray(q0, dtype=float)
    qpos = robot_qpos(robot, q)
    for key in root.iter("key"):
        old = (key.get("qpos") or "").split()
        key.set("qpos", _vec([*(float(v) for v in old), *qpos]))
        scene_ctrl = [float(v) for v in (key.get("ctrl") or "").split()] or [0.0] * nu_scene
        key.set("ctrl", _vec([*scene_ctrl, *q, *([0.0] * len(robot.actuated))]))
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n", [s.get("name") for s in servos]


def robot_document(
    robot: MjcfRobot, *, timestep: float = 1e-3, model_name: str | None = None
) -> str:
    """A document of the robot alone (world at its root link, ``<option timestep>``, no
    gravity effect): the robot part of :func:`add_robot`, for tests and for users."""
    doc = ET.Element("mujoco", model=model_name or robot.name)
    ET.SubElement(doc, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    ET.SubElement(doc, "option", timestep=_f(timestep))
    ET.SubElement(doc, "worldbody")
    xml, _ = add_robot(ET.tostring(doc, encoding="unicode"), robot)
    return xml

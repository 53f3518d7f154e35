"""The robot of a synthetic scene: the generated UR5 or an imported URDF.

Either way the result is a :class:`RobotAssets`: the URDF text to store as
``robot/robot.urdf``, the files it references (dataset paths under ``robot/``),
the parsed kinematic tree, one visual mesh per link in the link frame, colours,
and the tool link (a ``pusher_tip`` sphere that touches the box).

Imported URDFs are copied with their ``package://`` and relative mesh URIs
rewritten to paths relative to ``robot/robot.urdf`` (``meshes/<package>/<rest>``),
and get the same ``pusher_tip`` link appended below their flange (``tool0`` if
present, else the deepest link fixed to the last revolute joint).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from xml.etree import ElementTree as ET

import numpy as np
import trimesh
from defusedxml import ElementTree as DET

from robogs.format.errors import InputError

from .chain import RobotModel, parse_urdf_bytes
from .mdh import mdh_fk
from .primitives import float32_exact, mass_props, union
from .ur5 import (
    LINK_COLORS,
    PUSHER_LENGTH,
    PUSHER_RADIUS,
    UR5_MASSES,
    pusher_parts,
    ur5_links,
    ur5_mdh,
    ur5_urdf_text,
)

__all__ = ["RobotAssets", "generated_ur5", "imported_robot", "TOOL_LINK"]

TOOL_LINK = "pusher_tip"
_PALETTE = [
    (0.30, 0.30, 0.33),
    (0.22, 0.47, 0.78),
    (0.78, 0.78, 0.80),
    (0.68, 0.72, 0.80),
    (0.18, 0.42, 0.72),
    (0.30, 0.56, 0.86),
    (0.40, 0.40, 0.45),
    (0.55, 0.60, 0.70),
]


@dataclass
class RobotAssets:
    """Everything the generator needs about the robot.

    Attributes:
        urdf_text: URDF to store at ``robot/robot.urdf``.
        files: dataset path -> bytes of each referenced mesh.
        model: the parsed tree of ``urdf_text``.
        meshes: link -> visual mesh in the link frame (metres), visuals concatenated in URDF order.
        colors: link -> linear RGB in [0, 1].
        tool_link: link whose origin is the pusher sphere centre.
        pusher_radius: m.
        mdh: the modified-DH table (generated arm only), else None.
        source: 'generated' or the imported URDF path.
    """

    urdf_text: str
    files: dict[str, bytes]
    model: RobotModel
    meshes: dict[str, trimesh.Trimesh]
    colors: dict[str, tuple[float, float, float]]
    tool_link: str = TOOL_LINK
    pusher_radius: float = PUSHER_RADIUS
    mdh: dict | None = None
    source: str = "generated"
    extra: dict = field(default_factory=dict)

    @property
    def visible_links(self) -> list[str]:
        """Links with visual geometry, in URDF link order."""
        return [lk for lk in self.model.links if lk in self.meshes]


def _stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    return mesh.export(file_type="stl")


def generated_ur5() -> RobotAssets:
    """The generated UR5-like arm with its MDH table (``T_tool`` = pusher offset)."""
    links = ur5_links()
    uris = {name: f"meshes/{name}.stl" for name in links}
    text = ur5_urdf_text(links, uris)
    files = {f"robot/{uris[n]}": _stl_bytes(gl.mesh) for n, gl in links.items()}
    model = parse_urdf_bytes(text.encode(), "robot/robot.urdf")
    mdh = ur5_mdh()
    mdh["T_base"] = np.eye(4).tolist()
    T_tool = np.eye(4)
    T_tool[2, 3] = PUSHER_LENGTH
    mdh["T_tool"] = T_tool.tolist()
    mdh["tool_link"] = TOOL_LINK
    # own consistency check: the URDF tree and the MDH table are the same arm
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (16, 6))
    err = np.abs(model.fk(q)[TOOL_LINK] - mdh_fk(mdh, q)).max()
    if err > 1e-9:
        raise RuntimeError(f"generated URDF and MDH disagree by {err:.3g}")
    meshes = {n: gl.mesh for n, gl in links.items()}
    return RobotAssets(text, files, model, meshes, dict(LINK_COLORS), mdh=mdh)


# ----------------------------------------------------------------------------- import


def _resolve_uri(uri: str, urdf_path: Path, package_roots: dict[str, Path]) -> tuple[Path, str]:
    """Source file of a mesh URI and its destination under ``robot/`` (relative to the URDF)."""
    uri = uri.strip()
    if uri.startswith("package://"):
        name, _, rest = uri[len("package://") :].partition("/")
        if not name or not rest:
            raise InputError(f"malformed package URI {uri!r}", path=urdf_path)
        candidates: list[Path] = []
        if name in package_roots:
            candidates.append(Path(package_roots[name]) / rest)
        for anc in [urdf_path.parent, *urdf_path.parent.parents]:
            candidates += [anc / rest, anc / name / rest]
        for c in candidates:
            if c.is_file():
                parts = PurePosixPath(rest).parts
                dest = f"meshes/{name}/{rest}" if ".." not in parts else f"meshes/{name}/{c.name}"
                return c, dest
        raise InputError(
            f"cannot find the file of {uri!r}",
            path=urdf_path,
            hint=f"pass --package {name}=<folder that holds it>",
        )
    src = Path(uri[len("file://") :]) if uri.startswith("file://") else Path(uri)
    if not src.is_absolute():
        src = urdf_path.parent / src
    if not src.is_file():
        raise InputError(f"mesh file of {uri!r} does not exist", path=urdf_path)
    parts = PurePosixPath(uri).parts
    if uri.startswith(("/", "file://")) or ".." in parts:
        return src, f"meshes/local/{src.name}"
    return src, f"meshes/local/{PurePosixPath(uri)}"


def _load_mesh(path: Path) -> trimesh.Trimesh:
    try:
        m = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # trimesh/pycollada raise many types
        raise InputError(f"unreadable mesh ({type(exc).__name__}: {exc})", path=path) from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise InputError("mesh has no triangles", path=path)
    return trimesh.Trimesh(
        np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64), process=False
    )


def _primitive(kind: str, params: tuple[float, ...]) -> trimesh.Trimesh:
    if kind == "box":
        return trimesh.creation.box(extents=params)
    if kind == "cylinder":
        return trimesh.creation.cylinder(radius=params[0], height=params[1], sections=24)
    return trimesh.creation.icosphere(subdivisions=2, radius=params[0])


def _flange_link(model: RobotModel) -> str:
    """``tool0`` if present, else the deepest link of the fixed tail after the last revolute joint.

    Links below a prismatic joint (gripper fingers) are not candidates.
    """
    if "tool0" in model.links:
        return "tool0"
    best, best_key = model.root, (-1, -1)
    for lk in model.links:
        path = model.path_to(lk)
        moving = [j for j in path if j.type in ("revolute", "continuous", "prismatic")]
        if not moving or moving[-1].type == "prismatic":
            continue
        key = (sum(j.type != "prismatic" for j in moving), len(path))
        if key > best_key:
            best, best_key = lk, key
    return best


def imported_robot(
    urdf: str | Path, package_roots: dict[str, str | Path] | None = None
) -> RobotAssets:
    """Copy a real URDF and its meshes; append the pusher below the flange.

    Args:
        urdf: path of an expanded URDF (no xacro).
        package_roots: ``{package name: folder}`` for ``package://`` URIs; otherwise
            the URDF's ancestors are searched for the file.

    Raises:
        InputError: unreadable URDF or meshes, unresolvable URIs.
    """
    urdf_path = Path(urdf).resolve()
    if not urdf_path.is_file():
        raise InputError("URDF file does not exist", path=urdf)
    data = urdf_path.read_bytes()
    src_model = parse_urdf_bytes(data, urdf_path)
    if TOOL_LINK in src_model.links:
        raise InputError(f"URDF already has a link named {TOOL_LINK!r}", path=urdf_path)
    roots = {k: Path(v) for k, v in (package_roots or {}).items()}
    try:  # own parse on purpose: synth stays independent of robogs.format.urdf, which it tests
        tree = DET.fromstring(data, forbid_dtd=True)
    except Exception as exc:  # already parsed once; defensive
        raise InputError(f"URDF is not readable XML ({exc})", path=urdf_path) from None
    files: dict[str, bytes] = {}
    src_by_dest: dict[str, Path] = {}
    for mesh_el in tree.iter("mesh"):
        uri = mesh_el.get("filename")
        if not uri:
            continue
        src, dest = _resolve_uri(uri, urdf_path, roots)
        files[f"robot/{dest}"] = src.read_bytes()
        src_by_dest[dest] = src
        mesh_el.set("filename", dest)
    flange = _flange_link(src_model)
    joint = ET.SubElement(tree, "joint", {"name": "pusher_joint", "type": "fixed"})
    ET.SubElement(joint, "parent", {"link": flange})
    ET.SubElement(joint, "child", {"link": TOOL_LINK})
    ET.SubElement(joint, "origin", {"xyz": f"0 0 {PUSHER_LENGTH!r}", "rpy": "0 0 0"})
    pusher_mesh = union(pusher_parts())
    props = mass_props(pusher_parts(), UR5_MASSES[TOOL_LINK])
    link = ET.SubElement(tree, "link", {"name": TOOL_LINK})
    for tag in ("visual", "collision"):
        el = ET.SubElement(link, tag)
        ET.SubElement(el, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
        g = ET.SubElement(el, "geometry")
        ET.SubElement(g, "mesh", {"filename": f"meshes/{TOOL_LINK}.stl"})
    inert = ET.SubElement(link, "inertial")
    ET.SubElement(
        inert, "origin", {"xyz": " ".join(repr(float(v)) for v in props.com), "rpy": "0 0 0"}
    )
    ET.SubElement(inert, "mass", {"value": repr(props.mass)})
    inertia = props.inertia
    ET.SubElement(
        inert,
        "inertia",
        {
            k: repr(float(v))
            for k, v in (
                ("ixx", inertia[0, 0]),
                ("ixy", inertia[0, 1]),
                ("ixz", inertia[0, 2]),
                ("iyy", inertia[1, 1]),
                ("iyz", inertia[1, 2]),
                ("izz", inertia[2, 2]),
            )
        },
    )
    files[f"robot/meshes/{TOOL_LINK}.stl"] = _stl_bytes(pusher_mesh)
    buf = io.BytesIO()
    ET.ElementTree(tree).write(buf, encoding="utf-8", xml_declaration=True)
    text = buf.getvalue().decode("utf-8")
    model = parse_urdf_bytes(text.encode(), "robot/robot.urdf")
    meshes: dict[str, trimesh.Trimesh] = {}
    cache: dict[Path, trimesh.Trimesh] = {}
    for lk in model.links:
        pieces = []
        for v in model.visuals.get(lk, []):
            if lk == TOOL_LINK:
                m = pusher_mesh.copy()
            elif v.mesh_uri is not None:
                src = src_by_dest[v.mesh_uri]
                if src not in cache:
                    cache[src] = _load_mesh(src)
                m = cache[src].copy()
                if not np.allclose(v.scale, 1.0):
                    m.apply_transform(np.diag([*v.scale, 1.0]))
            else:
                m = _primitive(v.primitive or "box", v.params)
            m.apply_transform(v.T_link_visual)
            pieces.append(m)
        if pieces:
            meshes[lk] = float32_exact(
                trimesh.util.concatenate(pieces) if len(pieces) > 1 else pieces[0]
            )
    colors = {
        lk: _PALETTE[i % len(_PALETTE)]
        for i, lk in enumerate(x for x in model.links if x in meshes)
    }
    colors[TOOL_LINK] = LINK_COLORS[TOOL_LINK]
    return RobotAssets(
        text, files, model, meshes, colors, source=str(urdf_path), extra={"flange_link": flange}
    )

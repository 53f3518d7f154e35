"""Safe URDF loading with confined mesh-URI resolution.

The XML is parsed by lxml with entity expansion, DTD loading and network access off, and any
document that declares entities (billion laughs, XXE) is rejected. The parsed ``<robot>`` is
handed to yourdfpy (https://github.com/clemense/yourdfpy) to build the model and its trimesh
scene.

Mesh URIs resolve inside an *allowed root* only:

* ``package://NAME/rest``: ``rest`` under the package root of ``NAME``, taken from
  ``package_roots[NAME]`` when given, else found by searching the allowed root for a folder
  named ``NAME`` or a folder whose ``package.xml`` says ``<name>NAME</name>`` (the allowed root
  itself counts). The result must stay inside that package root.
* a relative path: against the URDF's folder; the result must stay inside the allowed root.
* ``file://``, other URI schemes, and absolute paths are refused (:class:`PathEscapeError`).

Paths are compared after :meth:`pathlib.Path.resolve`, so ``..`` and symbolic links that lead
outside are caught. The default allowed root is the URDF's folder, or its parent when that folder
is named ``urdf`` (the ROS package layout ``<package>/urdf/robot.urdf``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yourdfpy
from lxml import etree

from robogs.format.errors import FormatError, InputError, PathEscapeError, RobogsError

__all__ = [
    "Capsule",
    "capsules",
    "MeshRef",
    "MESH_SUFFIXES",
    "load_urdf",
    "parse_urdf_robot",
    "parse_urdf_xml",
    "resolve_mesh_file",
    "resolve_mesh_uri",
    "mesh_refs",
    "default_allowed_root",
]

MESH_SUFFIXES: frozenset[str] = frozenset({".dae", ".stl", ".obj", ".ply", ".glb", ".gltf"})
"""Mesh file suffixes (lower case) that :func:`load_urdf` accepts."""

_MAX_XML_BYTES = 64 * 1024 * 1024
_MAX_MESH_BYTES = 1024 * 1024 * 1024
_MAX_SEARCH_DEPTH = 8
_MAX_SEARCH_DIRS = 20000
_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://")
_WINDOWS_ABS = re.compile(r"^[A-Za-z]:[\\/]")


@dataclass(frozen=True)
class MeshRef:
    """One ``<mesh filename=...>`` of a URDF.

    Attributes:
        link: name of the link that holds the geometry.
        kind: ``"visual"`` or ``"collision"``.
        uri: the ``filename`` attribute as written in the URDF.
        path: the resolved file (``None`` when not resolved).
    """

    link: str
    kind: str
    uri: str
    path: Path | None = None


@dataclass(frozen=True)
class Capsule:
    """One ``<capsule radius length>`` geometry (the SDFormat / Gazebo primitive, also read by
    MuJoCo's and Drake's URDF parsers): a cylinder of ``length`` with hemispherical caps,
    its axis along z of ``origin`` (total extent ``length + 2 radius``).

    Attributes:
        link: the link that holds it.
        kind: ``"visual"`` or ``"collision"``.
        origin: [4, 4] T_link_geometry (the element's ``<origin>``).
        radius, length: [m].
    """

    link: str
    kind: str
    origin: Any
    radius: float
    length: float


# --------------------------------------------------------------------------- XML


def _safe_parser(*, verbatim: bool = False, keep_blank_text: bool = False) -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        huge_tree=False,
        load_dtd=False,
        dtd_validation=False,
        remove_comments=not verbatim,
        remove_pis=not verbatim,
        remove_blank_text=not keep_blank_text,
    )


def _parse_xml_bytes(
    data: bytes, path: Path, what: str, *, verbatim: bool = False, keep_blank_text: bool = False
) -> etree._Element:
    """Parse XML with entities refused; raise FormatError on anything unsafe or malformed."""
    doctype = data.find(b"<!DOCTYPE")
    if doctype >= 0 and b"<!ENTITY" in data[doctype:]:
        _raise_entities(path, what)
    try:
        root = etree.fromstring(
            data, parser=_safe_parser(verbatim=verbatim, keep_blank_text=keep_blank_text)
        )
    except etree.XMLSyntaxError as exc:
        line = getattr(exc, "lineno", None)
        where = f"line {line}" if line else None
        raise FormatError(
            f"{what} is not well-formed XML ({exc.msg})",
            path=path,
            where=where,
            hint="the file may be truncated or not XML; re-export it",
        ) from None
    docinfo = root.getroottree().docinfo
    dtd = docinfo.internalDTD
    entities = list(dtd.iterentities()) if dtd is not None else []
    if entities or docinfo.system_url or _has_entity_nodes(root):
        _raise_entities(path, what)
    return root


def _raise_entities(path: Path, what: str) -> None:
    raise FormatError(
        f"{what} declares XML entities or an external DTD, which robogs refuses to expand",
        path=path,
        where="<!DOCTYPE>",
        hint="remove the DOCTYPE/ENTITY declarations (xacro output never needs them)",
    )


def _has_entity_nodes(root: etree._Element) -> bool:
    return any(isinstance(n, etree._Entity) for n in root.iter(etree.Entity))


def _read_limited(path: Path, what: str, limit: int = _MAX_XML_BYTES) -> bytes:
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise InputError(f"{what} not found", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot read {what}: {exc.strerror}", path=path) from None
    if not path.is_file():
        raise InputError(f"{what} is not a regular file", path=path)
    if size > limit:
        raise FormatError(
            f"{what} is {size} bytes, over the {limit} byte limit",
            path=path,
            hint="files this large are not supported",
        )
    return path.read_bytes()


def parse_urdf_xml(
    path: str | os.PathLike[str],
    *,
    what: str = "URDF",
    verbatim: bool = False,
    keep_blank_text: bool = False,
) -> etree._Element:
    """The hardened XML parse of a URDF (size limit, no entities, no DTD, no network).

    Use it to read or rewrite the XML itself; :func:`parse_urdf_robot` also checks the robot.

    Args:
        path: the file.
        what: its name in error messages.
        verbatim: keep comments and processing instructions (for files that are written back).
        keep_blank_text: keep whitespace-only text (the original indentation).

    Returns:
        The root element (``.getroottree()`` for the document).

    Raises:
        InputError: the file is missing, unreadable or not a regular file.
        FormatError: over the size limit, malformed XML, entity or DTD declarations.
    """
    path = Path(path)
    return _parse_xml_bytes(
        _read_limited(path, what), path, what, verbatim=verbatim, keep_blank_text=keep_blank_text
    )


def parse_urdf_robot(path: str | os.PathLike[str]) -> yourdfpy.Robot:
    """Parse a URDF file into yourdfpy's ``Robot`` record without loading meshes.

    Args:
        path: the ``.urdf`` file.

    Returns:
        ``yourdfpy.Robot`` (links, joints, materials as parsed by yourdfpy).

    Raises:
        InputError: the file is missing or unreadable.
        FormatError: malformed XML, entity declarations, no ``<robot>`` root, broken tree.
    """
    path = Path(path)
    root = _parse_xml_bytes(_read_limited(path, "URDF"), path, "URDF")
    etree.cleanup_namespaces(root)
    if etree.QName(root).localname != "robot":
        raise FormatError(
            f"root element is <{etree.QName(root).localname}>, expected <robot>",
            path=path,
            hint="is this a URDF (xacro files must be expanded first)?",
        )
    if root.get("name") is None:
        raise FormatError("<robot> has no name attribute", path=path, where="<robot>")
    _check_elements(root, path)
    caps = _take_capsules(root, path)
    try:
        # yourdfpy's own parser entry point (URDF.load calls it after an unsafe parse).
        robot = yourdfpy.URDF._parse_robot(xml_element=root)
    except (AttributeError, KeyError, ValueError, TypeError, IndexError) as exc:
        raise FormatError(
            f"URDF content could not be parsed ({type(exc).__name__}: {exc})",
            path=path,
            hint="check numeric attributes (xyz, rpy, axis, limits) and required tags",
        ) from None
    _check_tree(robot, path)
    robot.robogs_capsules = caps
    return robot


def _origin_matrix(el: etree._Element | None, path: Path, where: str) -> Any:
    import numpy as np

    from robogs.format.frames import rpy_to_matrix

    T = np.eye(4)
    if el is None:
        return T
    try:
        xyz = [float(x) for x in (el.get("xyz") or "0 0 0").split()]
        rpy = [float(x) for x in (el.get("rpy") or "0 0 0").split()]
        if len(xyz) != 3 or len(rpy) != 3:
            raise ValueError("three numbers expected")
    except ValueError as exc:
        raise FormatError(f"bad <origin> ({exc})", path=path, where=where) from None
    T[:3, :3] = np.asarray(rpy_to_matrix(np.array(rpy)))
    T[:3, 3] = xyz
    return T


def _take_capsules(root: etree._Element, path: Path) -> list[Capsule]:
    """Read every ``<capsule>`` geometry and remove its element from ``root`` (yourdfpy
    refuses the tag). Raises FormatError for a missing, non-finite or negative size."""
    import math

    out: list[Capsule] = []
    for link in root.findall("link"):
        for kind in ("visual", "collision"):
            for el in link.findall(kind):
                cap = el.find("geometry/capsule")
                if cap is None:
                    continue
                where = f"link '{link.get('name')}' {kind} capsule"
                try:
                    r, length = float(cap.get("radius", "nan")), float(cap.get("length", "nan"))
                except ValueError:
                    r = length = math.nan
                if not (math.isfinite(r) and math.isfinite(length) and r > 0 and length >= 0):
                    raise FormatError(
                        "capsule needs radius > 0 and length >= 0 (metres)",
                        path=path,
                        where=where,
                        hint='e.g. <capsule radius="0.01" length="0.04"/>',
                    )
                T = _origin_matrix(el.find("origin"), path, where)
                out.append(Capsule(str(link.get("name")), kind, T, r, length))
                link.remove(el)
    return out


def capsules(
    robot: yourdfpy.Robot | yourdfpy.URDF, kind: str | None = "collision"
) -> list[Capsule]:
    """The ``<capsule>`` geometries of a robot parsed by :func:`parse_urdf_robot` (or loaded
    by :func:`load_urdf`), of one ``kind`` (``collision``, ``visual``; None: both)."""
    rob = getattr(robot, "robot", robot)
    caps = list(getattr(rob, "robogs_capsules", []) or [])
    return [c for c in caps if kind is None or c.kind == kind]


def _check_elements(root: etree._Element, path: Path) -> None:
    for tag in ("link", "joint"):
        for i, el in enumerate(root.findall(tag)):
            if not el.get("name"):
                raise FormatError(f"<{tag}> #{i} has no name", path=path, where=f"<{tag}> #{i}")
    for j in root.findall("joint"):
        name = j.get("name")
        for sub in ("parent", "child"):
            el = j.find(sub)
            if el is None or not el.get("link"):
                raise FormatError(
                    f"joint has no <{sub} link=...>",
                    path=path,
                    where=f"joint '{name}'",
                )
        if j.get("type") is None:
            raise FormatError("joint has no type", path=path, where=f"joint '{name}'")


def _check_tree(robot: yourdfpy.Robot, path: Path) -> None:
    """Unique names, known links, one parent per link, exactly one root, no cycles."""
    link_names = [lk.name for lk in robot.links]
    joint_names = [j.name for j in robot.joints]
    for kind, names in (("link", link_names), ("joint", joint_names)):
        seen: set[str] = set()
        for n in names:
            if n in seen:
                raise FormatError(f"duplicate {kind} name", path=path, where=f"{kind} '{n}'")
            seen.add(n)
    if not link_names:
        raise FormatError("URDF has no links", path=path, where="<robot>")
    links = set(link_names)
    parent_of: dict[str, str] = {}
    allowed_types = {"revolute", "continuous", "prismatic", "fixed", "floating", "planar"}
    for j in robot.joints:
        if j.type not in allowed_types:
            raise FormatError(
                f"unknown joint type '{j.type}'",
                path=path,
                where=f"joint '{j.name}'",
                hint=f"use one of {sorted(allowed_types)}",
            )
        for end in (j.parent, j.child):
            if end not in links:
                raise FormatError(
                    f"joint refers to unknown link '{end}'", path=path, where=f"joint '{j.name}'"
                )
        if j.child in parent_of:
            raise FormatError(
                f"link '{j.child}' is the child of two joints",
                path=path,
                where=f"joint '{j.name}'",
                hint="a URDF must be a tree",
            )
        parent_of[j.child] = j.name
    roots = [n for n in link_names if n not in parent_of]
    if len(roots) != 1:
        raise FormatError(
            f"URDF must have exactly one root link, found {len(roots)}: {roots[:5]}",
            path=path,
            hint="connect every link through a joint (a cycle also leaves no root)",
        )
    children: dict[str, list[str]] = {}
    for j in robot.joints:
        children.setdefault(j.parent, []).append(j.child)
    reached = {roots[0]}
    stack = [roots[0]]
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in reached:
                reached.add(c)
                stack.append(c)
    if len(reached) != len(links):
        missing = sorted(links - reached)[:5]
        raise FormatError(
            f"links not reachable from root '{roots[0]}': {missing}",
            path=path,
            hint="the joint graph has a cycle",
        )


# --------------------------------------------------------------------------- URIs


def default_allowed_root(urdf_path: str | os.PathLike[str]) -> Path:
    """The allowed root used when none is given.

    Args:
        urdf_path: the URDF file.

    Returns:
        The URDF's folder, or its parent when the folder is named ``urdf``; resolved.
    """
    folder = Path(urdf_path).resolve().parent
    return folder.parent if folder.name == "urdf" else folder


def _within(path: Path, base: Path) -> bool:
    return path == base or path.is_relative_to(base)


def _package_xml_name(pkg_xml: Path) -> str | None:
    try:
        data = pkg_xml.read_bytes()
        if len(data) > 1024 * 1024:
            return None
        root = _parse_xml_bytes(data, pkg_xml, "package.xml")
    except (OSError, RobogsError):
        return None
    el = root.find("name")
    return el.text.strip() if el is not None and el.text else None


def _find_package_root(name: str, root: Path) -> Path:
    """Search ``root`` (depth-limited, no symlink following) for the package ``name``."""
    by_xml: list[Path] = []
    by_name: list[Path] = []
    visited = 0
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        visited += 1
        if visited > _MAX_SEARCH_DIRS:
            raise FormatError(
                f"gave up searching for package '{name}' after {_MAX_SEARCH_DIRS} folders",
                path=root,
                hint=f"pass package_roots={{'{name}': <folder>}}",
            )
        here = Path(dirpath)
        depth = len(here.relative_to(root).parts)
        if depth >= _MAX_SEARCH_DEPTH:
            dirnames[:] = []
        dirnames[:] = [d for d in dirnames if not d.startswith(".")]
        # Symlinked folders are listed but not walked; a link named like the package counts
        # (and is caught below if it leads outside the root).
        by_name.extend(here / d for d in dirnames if d == name and (here / d).is_symlink())
        if "package.xml" in filenames and _package_xml_name(here / "package.xml") == name:
            by_xml.append(here)
        elif here.name == name:
            by_name.append(here)
    candidates = by_xml or by_name
    resolved = sorted({c.resolve() for c in candidates})
    if not resolved:
        raise FormatError(
            f"package '{name}' not found under the allowed root",
            path=root,
            hint=f"pass package_roots={{'{name}': <folder>}} or root=<folder containing it>",
        )
    if len(resolved) > 1:
        raise FormatError(
            f"package '{name}' is ambiguous: {[str(p) for p in resolved[:4]]}",
            path=root,
            hint=f"pass package_roots={{'{name}': <folder>}}",
        )
    found = resolved[0]
    if not _within(found, root):
        raise PathEscapeError(
            f"package '{name}' resolves outside the allowed root (to {found})",
            path=root,
            hint="a symbolic link leads out of the dataset",
        )
    return found


def resolve_mesh_file(
    uri: str,
    urdf_path: str | os.PathLike[str],
    root: str | os.PathLike[str] | None,
    package_roots: Mapping[str, str | os.PathLike[str]] | None,
    *,
    where: str,
    missing_hint: str,
    cache: dict[str, Path] | None = None,
) -> Path:
    """:func:`resolve_mesh_uri` for a mesh that must exist: errors name the URDF and ``where``
    (the link and the URI); a missing file says ``missing_hint``."""
    try:
        resolved = resolve_mesh_uri(uri, urdf_path, root, package_roots, _cache=cache)
    except RobogsError as exc:
        raise type(exc)(exc.message, path=urdf_path, where=where, hint=exc.hint) from None
    if not resolved.is_file():
        raise FormatError(
            f"mesh file not found (resolved to {resolved})",
            path=urdf_path,
            where=where,
            hint=missing_hint,
        )
    return resolved


def resolve_mesh_uri(
    uri: str,
    urdf_path: str | os.PathLike[str],
    root: str | os.PathLike[str] | None = None,
    package_roots: Mapping[str, str | os.PathLike[str]] | None = None,
    *,
    _cache: dict[str, Path] | None = None,
) -> Path:
    """Resolve a URDF mesh URI to a file inside the allowed root.

    Existence is not checked here (see :func:`load_urdf`).

    Args:
        uri: the ``<mesh filename>`` value (``package://NAME/rest`` or a relative path).
        urdf_path: the URDF file the URI comes from.
        root: allowed root folder; default :func:`default_allowed_root`.
        package_roots: explicit ``{package name: folder}`` map.

    Returns:
        The resolved absolute path.

    Raises:
        PathEscapeError: ``file://``, absolute paths, network URIs, or a result outside the
            allowed root (after resolving ``..`` and symbolic links).
        FormatError: empty URI, unsupported scheme, unknown or ambiguous package.
    """
    urdf_path = Path(urdf_path)
    allowed = Path(root).resolve() if root is not None else default_allowed_root(urdf_path)
    if not uri or "\x00" in uri or not uri.strip():
        raise FormatError("empty or invalid mesh URI", path=urdf_path, where=repr(uri))
    uri = uri.strip()
    m = _SCHEME.match(uri)
    if m:
        scheme = m.group(1).lower()
        if scheme != "package":
            raise PathEscapeError(
                f"mesh URI scheme '{scheme}://' is not allowed",
                path=urdf_path,
                where=uri,
                hint="use package://NAME/... or a path relative to the URDF",
            )
        rest = uri[len(m.group(0)) :]
        name, _, sub = rest.partition("/")
        if not name or not sub:
            raise FormatError("package URI needs package://NAME/path", path=urdf_path, where=uri)
        if package_roots is not None and name in package_roots:
            base = Path(package_roots[name]).resolve()
            if not base.is_dir():
                raise InputError(f"package root for '{name}' is not a folder", path=base, where=uri)
        else:
            if _cache is not None and name in _cache:
                base = _cache[name]
            else:
                base = _find_package_root(name, allowed)
                if _cache is not None:
                    _cache[name] = base
        if sub.startswith("/") or _WINDOWS_ABS.match(sub):
            raise PathEscapeError("absolute path inside package URI", path=urdf_path, where=uri)
        target = (base / sub).resolve()
        if not _within(target, base):
            raise PathEscapeError(
                f"mesh URI escapes its package root {base}",
                path=urdf_path,
                where=uri,
                hint="remove '..' components and symbolic links that lead outside",
            )
        return target
    if uri.startswith(("/", "\\")) or _WINDOWS_ABS.match(uri):
        raise PathEscapeError(
            "absolute mesh paths are not allowed",
            path=urdf_path,
            where=uri,
            hint="use package://NAME/... or a path relative to the URDF",
        )
    target = (urdf_path.resolve().parent / uri).resolve()
    if not _within(target, allowed):
        raise PathEscapeError(
            f"mesh path escapes the allowed root {allowed}",
            path=urdf_path,
            where=uri,
            hint="keep meshes inside the dataset (or pass root=)",
        )
    return target


def mesh_refs(robot: yourdfpy.Robot | yourdfpy.URDF) -> list[MeshRef]:
    """All ``<mesh>`` references of a robot, visual first then collision, in link order.

    Args:
        robot: a ``yourdfpy.Robot`` or ``yourdfpy.URDF``.

    Returns:
        One unresolved :class:`MeshRef` per mesh element.
    """
    rb = robot.robot if isinstance(robot, yourdfpy.URDF) else robot
    out: list[MeshRef] = []
    for kind in ("visual", "collision"):
        for link in rb.links:
            items: Iterable = link.visuals if kind == "visual" else link.collisions
            for item in items:
                geom = item.geometry
                if geom is not None and geom.mesh is not None:
                    out.append(MeshRef(link.name, kind, geom.mesh.filename))
    return out


def _check_dae(path: Path) -> None:
    """COLLADA is XML and pycollada expands entities: refuse them before it parses the file."""
    data = _read_limited(path, "COLLADA mesh", _MAX_MESH_BYTES)
    suspicious = (
        data[:2] in (b"\xff\xfe", b"\xfe\xff")  # UTF-16: byte search below would miss markup
        or b"\x00" in data[:64]
        or b"<!DOCTYPE" in data
        or b"<!ENTITY" in data
    )
    if suspicious:
        _parse_xml_bytes(data, path, "COLLADA mesh")


class _CheckedURDF(yourdfpy.URDF):
    """yourdfpy.URDF that refuses mesh files which load as empty (trimesh skips broken ones)."""

    def __init__(
        self, *args: Any, robogs_path: Path, robogs_uris: Mapping[str, str], **kwargs: Any
    ) -> None:
        self._robogs_path = robogs_path
        self._robogs_uris = robogs_uris
        super().__init__(*args, **kwargs)

    def _geometry2trimeshscene(
        self, geometry: yourdfpy.Geometry, load_file: bool, force_mesh: bool, skip_materials: bool
    ) -> Any:
        scene = super()._geometry2trimeshscene(geometry, load_file, force_mesh, skip_materials)
        if geometry.mesh is not None and load_file and (scene is None or not scene.geometry):
            uri = geometry.mesh.filename
            raise FormatError(
                "mesh file holds no readable geometry",
                path=self._robogs_path,
                where=f"mesh '{uri}' ({self._robogs_uris.get(uri, '?')})",
                hint="the file may be corrupt or empty; re-export it",
            )
        return scene


def load_urdf(
    path: str | os.PathLike[str],
    *,
    root: str | os.PathLike[str] | None = None,
    package_roots: Mapping[str, str | os.PathLike[str]] | None = None,
    load_meshes: bool = True,
) -> yourdfpy.URDF:
    """Load a URDF safely, resolving and loading its meshes inside the allowed root.

    Args:
        path: the ``.urdf`` file (xacro must be expanded first).
        root: allowed root folder (dataset root or robot folder); default
            :func:`default_allowed_root`.
        package_roots: explicit ``{package name: folder}`` map for ``package://`` URIs.
        load_meshes: load visual and collision meshes (trimesh; COLLADA via pycollada). When
            False, mesh URIs are neither resolved nor checked and only the kinematic model
            and primitive geometry are built.

    Returns:
        ``yourdfpy.URDF`` with its visual scene (and collision scene when meshes are loaded).
        The resolved mesh references are stored as ``urdf.robogs_mesh_refs``
        (list of :class:`MeshRef`).

    Raises:
        InputError: the URDF is missing.
        FormatError: malformed/hostile XML, broken tree, missing or unreadable mesh files.
        PathEscapeError: a mesh URI points outside the allowed root.
    """
    path = Path(path)
    robot = parse_urdf_robot(path)
    refs: list[MeshRef] = []
    mapping: dict[str, str] = {}
    if load_meshes:
        cache: dict[str, Path] = {}
        for ref in mesh_refs(robot):
            where = f"link '{ref.link}' {ref.kind} mesh '{ref.uri}'"
            resolved = resolve_mesh_file(
                ref.uri,
                path,
                root,
                package_roots,
                where=where,
                missing_hint="check package_roots/root, or pass load_meshes=False to skip meshes",
                cache=cache,
            )
            if resolved.suffix.lower() not in MESH_SUFFIXES:
                raise FormatError(
                    f"unsupported mesh type '{resolved.suffix}'",
                    path=path,
                    where=where,
                    hint=f"use one of {sorted(MESH_SUFFIXES)}",
                )
            if resolved.suffix.lower() == ".dae":
                _check_dae(resolved)
            refs.append(MeshRef(ref.link, ref.kind, ref.uri, resolved))
            mapping[ref.uri] = str(resolved)

    current: list[str] = []

    def _handler(fname: str) -> str:
        current[:] = [fname]
        if fname not in mapping:
            raise PathEscapeError("unresolved mesh URI", path=path, where=fname)
        return mapping[fname]

    try:
        urdf = _CheckedURDF(
            robot=robot,
            robogs_path=path,
            robogs_uris=mapping,
            build_scene_graph=True,
            build_collision_scene_graph=load_meshes,
            load_meshes=load_meshes,
            load_collision_meshes=load_meshes,
            filename_handler=_handler,
        )
    except RobogsError:
        raise
    except Exception as exc:  # trimesh/pycollada raise many types on corrupt files
        where = f"mesh '{current[0]}'" if current else None
        raise FormatError(
            f"could not build the robot model ({type(exc).__name__}: {exc})",
            path=path,
            where=where,
            hint="a mesh file may be corrupt; re-export it",
        ) from None
    urdf.robogs_mesh_refs = refs
    return urdf

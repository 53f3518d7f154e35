"""Copy a robot URDF and its meshes into ``robot/`` of the dataset being written.

Mesh URIs (``package://NAME/...`` or relative) are resolved with
:func:`robogs.format.urdf.resolve_mesh_uri`, which refuses anything outside the allowed roots.
The folder of each ``package://NAME`` is ``--package NAME=DIR`` when given, else found the way ROS
and yourdfpy find it (:mod:`robogs.format.packages`); where each package and each mesh
was found is recorded in ``provenance.robot``.
Each mesh is copied under ``robot/meshes/`` keeping its path relative to the deepest folder
common to all meshes, and the copied URDF refers to it by that relative path, so the dataset
is self-contained. Image textures of COLLADA meshes are copied along, at the same place relative
to their mesh (:mod:`robogs.convert.ingest.dae_textures`); a texture that is missing or would come
from outside the mesh's package is left out and named in the provenance.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from lxml import etree

from robogs.format.errors import InputError, RobogsError
from robogs.format.packages import PackageRoot, find_packages, package_uris, package_xml_name
from robogs.format.urdf import mesh_refs, parse_urdf_robot, parse_urdf_xml, resolve_mesh_uri

from .context import IngestContext
from .dae_textures import dae_texture_refs, texture_uri

__all__ = ["attach_robot", "attach_robot_description", "sibling_packages", "urdf_root_link"]

URDF_REL = "robot/robot.urdf"


def urdf_root_link(urdf_path: Path) -> str:
    """Name of the URDF's root link (the one link that is no joint's child)."""
    robot = parse_urdf_robot(urdf_path)
    children = {j.child for j in robot.joints}
    roots = [link.name for link in robot.links if link.name not in children]
    return roots[0] if roots else robot.links[0].name


def attach_robot(
    ctx: IngestContext,
    urdf_path: Path,
    *,
    package_roots: dict[str, Path] | None = None,
    search_from: Path | None = None,
    known: dict[str, PackageRoot] | None = None,
) -> None:
    """Copy ``urdf_path`` and every mesh it uses into the dataset; declare the robot.

    Args:
        ctx: the conversion context.
        urdf_path: the URDF file.
        package_roots: ``--package NAME=DIR`` folders (they win over any search).
        search_from: folder whose ancestors are searched for packages (default: the URDF's).
        known: packages found beforehand (e.g. beside the source), tried before the search.

    Raises:
        RobogsError: malformed URDF, mesh URI escaping its root, missing mesh file.
    """
    urdf_path = Path(urdf_path)
    if not urdf_path.is_file():
        raise InputError("URDF file not found", path=urdf_path)
    robot = parse_urdf_robot(urdf_path)
    uris = package_uris("\n".join(ref.uri for ref in mesh_refs(robot)))
    found = find_packages(
        uris,
        urdf_path.resolve().parent if search_from is None else search_from,
        explicit=package_roots,
        known=known,
    )
    roots = {k: str(v.path) for k, v in found.items()}
    resolved: dict[str, Path] = {}
    for ref in mesh_refs(robot):
        if ref.uri in resolved:
            continue
        try:
            p = resolve_mesh_uri(ref.uri, urdf_path, None, roots or None)
        except RobogsError as exc:
            raise type(exc)(
                exc.message,
                path=urdf_path,
                where=f"link {ref.link} mesh {ref.uri}",
                hint=_package_hint(exc.hint, ref.uri, found),
            ) from None
        if not p.is_file():
            raise InputError(
                f"mesh file not found (resolved to {p})",
                path=urdf_path,
                where=f"link {ref.link} mesh {ref.uri}",
                hint="pass --package NAME=FOLDER for package:// URIs",
            )
        resolved[ref.uri] = p
    textures = _textures(ctx, urdf_path, resolved, roots)
    files = list(resolved.values()) + list(textures)
    common = Path(os.path.commonpath([str(p.parent) for p in files])) if files else None
    new_rel: dict[str, str] = {}
    for uri, p in sorted(resolved.items()):
        assert common is not None
        rel = "meshes/" + p.relative_to(common).as_posix()
        ctx.writer.copy_file(f"robot/{rel}", p)
        new_rel[uri] = rel
    for p in sorted(textures):
        assert common is not None
        ctx.writer.copy_file(f"robot/meshes/{p.relative_to(common).as_posix()}", p)
    tree = parse_urdf_xml(urdf_path, verbatim=True, keep_blank_text=True).getroottree()
    for mesh in tree.getroot().iter("mesh"):
        fn = mesh.get("filename")
        if fn in new_rel:
            mesh.set("filename", new_rel[fn])
    ctx.writer.write_bytes(URDF_REL, etree.tostring(tree, xml_declaration=True, encoding="utf-8"))
    root = urdf_root_link(urdf_path)
    ctx.writer.set_robot(URDF_REL, base_link=root)
    ctx.provenance.extra["robot"] = {
        "urdf": urdf_path.name,
        "meshes": len(resolved),
        "textures": len(textures),
        "root_link": root,
    }
    if found:
        ctx.provenance.extra["robot"]["packages"] = {k: v.to_dict() for k, v in found.items()}
        ctx.provenance.extra["robot"]["mesh_files"] = {
            u: str(p) for u, p in sorted(resolved.items())
        }
        for name, pkg in sorted(found.items()):
            if pkg.how != "--package":
                ctx.provenance.note(f"package://{name} found at {pkg.path} ({pkg.how})")


def _package_hint(hint: str | None, uri: str, found: dict[str, PackageRoot]) -> str:
    """The hint for a mesh URI that did not resolve."""
    name = uri[len("package://") :].split("/", 1)[0] if uri.startswith("package://") else None
    if name and name not in found:
        return (
            f"package {name!r} is neither among the URDF's ancestors nor on ROS_PACKAGE_PATH; "
            f"pass --package {name}=FOLDER"
        )
    return hint or "pass --package NAME=FOLDER for package:// URIs"


def _textures(
    ctx: IngestContext, urdf_path: Path, meshes: dict[str, Path], roots: dict[str, str]
) -> set[Path]:
    """Image files referenced by the COLLADA meshes, resolved like mesh URIs (see module doc)."""
    out: set[Path] = set()
    for uri, mesh in sorted(meshes.items()):
        if mesh.suffix.lower() != ".dae":
            continue
        for ref in dae_texture_refs(mesh):
            try:
                p = resolve_mesh_uri(texture_uri(uri, ref), urdf_path, None, roots or None)
            except RobogsError as exc:
                ctx.provenance.note(
                    f"texture {ref!r} of mesh {uri} not copied: {exc.message}"
                    + (f" ({exc.hint})" if exc.hint else "")
                )
                continue
            if not p.is_file():
                ctx.provenance.note(f"texture {ref!r} of mesh {uri} not copied: file not found")
                continue
            out.add(p)
    return out


def sibling_packages(source: Path, text: str) -> dict[str, Path]:
    """``package://NAME`` roots found beside ``source``: a folder ``NAME`` next to it whose
    ``package.xml`` names ``NAME`` (how ``robogs export mcap`` ships the robot package)."""
    out: dict[str, Path] = {}
    for name in sorted(set(re.findall(r"package://([A-Za-z0-9_]+)/", text))):
        folder = Path(source).parent / name
        if package_xml_name(folder / "package.xml") == name:
            out[name] = folder
    return out


def attach_robot_description(
    ctx: IngestContext,
    text: str,
    *,
    package_roots: dict[str, Path] | None = None,
    source: Path | None = None,
) -> bool:
    """Use a ``/robot_description`` URDF string; returns False (with a note) when unusable.

    Packages are looked for beside ``source`` (:func:`sibling_packages`), then among its
    ancestors and on ``ROS_PACKAGE_PATH``; ``package_roots`` win."""
    known = None
    if source is not None:
        known = {
            n: PackageRoot(n, p, "beside the source")
            for n, p in sibling_packages(source, text).items()
        }
    with tempfile.TemporaryDirectory(prefix="robogs-urdf-") as tmp:
        path = Path(tmp) / "robot_description.urdf"
        path.write_text(text, encoding="utf-8")
        try:
            attach_robot(
                ctx,
                path,
                package_roots=package_roots,
                search_from=Path(source).resolve().parent if source is not None else Path(tmp),
                known=known,
            )
        except RobogsError as exc:
            ctx.writer.remove("robot")
            ctx.provenance.note(
                f"robot_description from the source not used: {exc.message}"
                + (f" ({exc.where})" if exc.where else "")
                + "; pass --urdf (and --package NAME=FOLDER) to add the robot"
            )
            return False
    ctx.provenance.extra["robot"]["urdf"] = "robot_description topic"
    return True

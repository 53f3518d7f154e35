"""Image textures referenced by COLLADA (``.dae``) meshes, resolved inside the mesh's package.

A COLLADA file names its textures in ``<library_images><image><init_from>`` (COLLADA 1.4: the
text; 1.5: an ``<init_from><ref>`` child), as URIs relative to the ``.dae`` file
(https://www.khronos.org/collada/). A reference is joined to the mesh's own URDF URI
(``package://NAME/meshes/a.dae`` + ``tex/a.png`` -> ``package://NAME/meshes/tex/a.png``) and then
resolved by :func:`robogs.format.urdf.resolve_mesh_uri`, so it obeys the same rules as a mesh:
no scheme, no absolute path, nothing outside the package (or the URDF's allowed root), symbolic
links included. The mesh file is not changed, so the copy keeps each texture at the same place
relative to its mesh.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path
from urllib.parse import unquote

from robogs.format.errors import FormatError, PathEscapeError

__all__ = ["dae_texture_refs", "texture_uri"]

_MAX_DAE_BYTES = 256 * 1024 * 1024
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")
_PACKAGE = re.compile(r"^package://([^/]+)/(.+)$")


def dae_texture_refs(path: Path) -> list[str]:
    """The ``init_from`` values of the ``<image>`` elements of a COLLADA file, in order.

    Raises:
        FormatError: an unreadable, oversized or malformed file (entities are refused).
    """
    import defusedxml.ElementTree as ET
    from defusedxml import DefusedXmlException

    try:
        if path.stat().st_size > _MAX_DAE_BYTES:
            raise FormatError("COLLADA mesh is too large to scan for textures", path=path)
        root = ET.parse(str(path)).getroot()
    except (OSError, ET.ParseError, DefusedXmlException, ValueError) as exc:
        raise FormatError(
            f"COLLADA mesh cannot be parsed ({type(exc).__name__})", path=path
        ) from None
    out: list[str] = []
    for el in root.iter():
        if not isinstance(el.tag, str) or el.tag.rsplit("}", 1)[-1] != "image":
            continue
        for init in el:
            if not isinstance(init.tag, str) or init.tag.rsplit("}", 1)[-1] != "init_from":
                continue
            ref = next(
                (c.text for c in init if isinstance(c.tag, str) and c.tag.endswith("ref")),
                init.text,
            )
            if ref and ref.strip() and ref.strip() not in out:
                out.append(ref.strip())
    return out


def texture_uri(mesh_uri: str, ref: str) -> str:
    """The URDF-style URI of texture ``ref`` of the mesh at ``mesh_uri``.

    Raises:
        PathEscapeError: a scheme (``file://`` ...), an absolute path, or a path leaving the
            mesh's package.
    """
    rel = unquote(ref).strip().replace("\\", "/")
    if _SCHEME.match(rel) or rel.startswith("/"):
        raise PathEscapeError(
            "texture path is absolute or has a URI scheme",
            where=ref,
            hint="make the texture path relative to the .dae file",
        )
    m = _PACKAGE.match(mesh_uri.strip())
    if m:
        sub = posixpath.normpath(posixpath.join(posixpath.dirname(m.group(2)), rel))
        if sub == ".." or sub.startswith("../"):
            raise PathEscapeError("texture path leaves the mesh's package", where=ref)
        return f"package://{m.group(1)}/{sub}"
    return posixpath.normpath(posixpath.join(posixpath.dirname(mesh_uri.strip()), rel))

"""The one mesh loader: trimesh behind a single error policy (metres, the file's own frame)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import FormatError, RobogsError

if TYPE_CHECKING:
    import trimesh

__all__ = ["MESH_FORMATS_HINT", "MAX_MESH_BYTES", "MAX_MESH_VERTICES", "load_mesh"]

MESH_FORMATS_HINT = "re-export the mesh as STL, OBJ, PLY, GLB or DAE"

#: largest mesh read (bytes, after decompression for zip-based containers such as .zae/.3mf):
#: trimesh holds a few times the file in memory while parsing
MAX_MESH_BYTES = 256 * 1024 * 1024
#: most vertices a loaded mesh may have (a 20 M-vertex mesh is 480 MB of float64 positions)
MAX_MESH_VERTICES = 20_000_000


def _check_budget(p: Path, error: type[RobogsError], where: str | None) -> None:
    """Refuse, before parsing, a mesh whose bytes (unpacked, for zip containers) exceed the budget."""
    import zipfile

    size = p.stat().st_size
    what = f"{size} bytes"
    if zipfile.is_zipfile(p):
        try:
            with zipfile.ZipFile(p) as zf:
                size = sum(max(i.file_size, 0) for i in zf.infolist())
        except (zipfile.BadZipFile, OSError, ValueError) as exc:
            raise error(f"unreadable mesh archive ({exc})", path=p, where=where) from None
        what = f"{size} bytes unpacked from {p.stat().st_size}"
    if size > MAX_MESH_BYTES:
        raise error(
            f"mesh is {what}, over the {MAX_MESH_BYTES}-byte budget",
            path=p,
            where=where,
            hint="decimate the mesh (a collision or visual mesh rarely needs more than 1 M "
            "triangles), or it is a decompression bomb",
        )


def load_mesh(
    path: str | Path,
    *,
    error: type[RobogsError] = FormatError,
    where: str | None = None,
    triangles: bool = True,
    process: bool = False,
) -> trimesh.Trimesh | Any:
    """Load one mesh file as a single mesh (``force="mesh"``).

    Args:
        path: mesh file (STL, OBJ, PLY, GLB, DAE, ...).
        error: the :class:`RobogsError` subclass to raise (``InputError`` for user-given sources).
        where: place in the referring document, for the error.
        triangles: require a ``trimesh.Trimesh`` with at least one face; False returns whatever
            trimesh gives (callers that only need vertices check them themselves).
        process: trimesh's ``process`` (merge duplicate vertices, drop degenerate faces).

    Raises:
        error: the file is missing, over :data:`MAX_MESH_BYTES` (checked before parsing, unpacked
            size for zip containers) or :data:`MAX_MESH_VERTICES`, cannot be parsed, or
            (``triangles``) has no triangles.
    """
    import trimesh

    p = Path(path)
    if not p.is_file():
        raise error("mesh file not found", path=p, where=where)
    _check_budget(p, error, where)
    try:
        mesh = trimesh.load(p, force="mesh", process=process)
    except Exception as exc:  # trimesh raises many types on bad files
        raise error(
            f"unreadable mesh ({type(exc).__name__}: {str(exc)[:200]})",
            path=p,
            where=where,
            hint=MESH_FORMATS_HINT,
        ) from None
    n_vertices = len(getattr(mesh, "vertices", ()))
    if n_vertices > MAX_MESH_VERTICES:
        raise error(
            f"mesh has {n_vertices} vertices, over the {MAX_MESH_VERTICES} budget",
            path=p,
            where=where,
            hint="decimate the mesh",
        )
    if triangles and (not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0):
        raise error(
            "mesh has no triangles",
            path=p,
            where=where,
            hint="the file is empty or corrupt; re-export the mesh",
        )
    return mesh

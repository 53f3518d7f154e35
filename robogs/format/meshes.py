"""The one mesh loader: trimesh behind a single error policy (metres, the file's own frame)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import FormatError, RobogsError

if TYPE_CHECKING:
    import trimesh

__all__ = ["MESH_FORMATS_HINT", "load_mesh"]

MESH_FORMATS_HINT = "re-export the mesh as STL, OBJ, PLY, GLB or DAE"


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
        error: the file is missing, cannot be parsed, or (``triangles``) has no triangles.
    """
    import trimesh

    p = Path(path)
    if not p.is_file():
        raise error("mesh file not found", path=p, where=where)
    try:
        mesh = trimesh.load(p, force="mesh", process=process)
    except Exception as exc:  # trimesh raises many types on bad files
        raise error(
            f"unreadable mesh ({type(exc).__name__}: {str(exc)[:200]})",
            path=p,
            where=where,
            hint=MESH_FORMATS_HINT,
        ) from None
    if triangles and (not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0):
        raise error(
            "mesh has no triangles",
            path=p,
            where=where,
            hint="the file is empty or corrupt; re-export the mesh",
        )
    return mesh

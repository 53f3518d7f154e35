"""Object shapes for the engines: which object meshes of a dataset are their box, which are not.

A rigid object of physics.json is a box of ``size_m`` to the planar model. A dataset may also
carry the object's mesh (``assets/<object>/mesh``, object frame, metres); the MuJoCo engine
collides a mesh through its convex hull (:func:`robogs.format.mjcf.collision_hull`). A mesh
that *is* the box (the synthetic scene writes its box as a mesh) must keep the box model and its
numbers; a genuinely different shape (a mug, a cylinder) must reach MuJoCo as its hull.

The rule (:func:`box_distance_m`): the Hausdorff distance between the mesh's convex hull and
the box of ``size_m`` centred on the object frame's origin, both as solids. Both are convex, so
the distance is attained at vertices: the farthest hull vertex from the box (closed form) and
the farthest box corner from the hull (inside: 0; outside: the nearest hull triangle). A mesh
within the dataset's ``geometry.box3d_mm`` budget (default 2 mm: "object mesh may stick out of
its 3D box by this much", :mod:`robogs.format.budgets`, overridable in the manifest) is the box;
beyond it the object has a mesh shape. The budget is the dataset's own statement of how far a
mesh and its box may disagree, so the rule has no tuned constant; it is also about the pose noise
of tracked objects, below which a shape difference could not be seen in the residuals anyway.
A rigid object with a mesh and no ``size_m`` has a mesh shape.

Only rigid objects are considered (static objects other than the table stay as physics.json
says: the fitting engine places no static meshes).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["BOX_BUDGET", "Shapes", "box_distance_m", "load_object_meshes", "object_shapes"]

BOX_BUDGET = "geometry.box3d_mm"
"""The dataset budget [mm] within which an object's mesh counts as its ``size_m`` box."""


def load_object_meshes(ds: Any) -> dict[str, Any]:
    """Meshes of the rigid objects of a dataset's physics.json that have a mesh asset of the
    same name: name -> ``trimesh.Trimesh`` (object frame, m), read with
    :meth:`robogs.format.dataset.Dataset.mesh` (the path is resolved inside the dataset root:
    an escaping path is a :class:`~robogs.format.errors.FormatError` naming the asset)."""
    if not ds.manifest.get("physics") or not ds.assets:
        return {}  # nothing to load (a dataset without physics.json fails where it is read)
    objects = ds.physics().get("objects") or {}
    assets = ds.assets
    out = {}
    for name, entry in objects.items():
        if name in ("table", "pusher") or not isinstance(entry, Mapping):
            continue
        if entry.get("equation") == "rigid" and "mesh" in (assets.get(name) or {}):
            out[name] = ds.mesh(name)
    return out


def box_distance_m(mesh: Any, size: Any) -> float:
    """Hausdorff distance [m] between the convex hull of ``mesh`` (its vertices, object frame)
    and the box of edges ``size`` [3] m centred on the origin, both as solids (module
    docstring)."""
    import trimesh

    verts = np.asarray(mesh.vertices, dtype=np.float64)
    half = 0.5 * np.asarray(size, dtype=np.float64).reshape(3)
    hull = trimesh.convex.convex_hull(verts)
    hv = np.asarray(hull.vertices)
    out_of_box = float(np.max(np.linalg.norm(np.maximum(np.abs(hv) - half, 0.0), axis=1)))
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    tri = np.asarray(hull.triangles)  # [F, 3, 3]
    normals = np.asarray(hull.face_normals)  # outward
    far = 0.0
    for c in corners:
        if np.all(np.einsum("fj,fj->f", normals, c - tri[:, 0]) <= 1e-12):
            continue  # inside the hull
        near = trimesh.triangles.closest_point(tri, np.repeat(c[None], len(tri), 0))
        far = max(far, float(np.min(np.linalg.norm(near - c, axis=1))))
    return max(out_of_box, far)


@dataclass
class Shapes:
    """The object meshes an engine gets, and what was said about them.

    Attributes:
        meshes: object name -> mesh, only the objects whose mesh is not their box.
        boxes: object name -> Hausdorff distance [m] of the meshes kept as boxes.
        notes: one line per object with a mesh shape (why, and the collision hull's
            substitution note when MuJoCo gets a different mesh than the dataset's).
    """

    meshes: dict[str, Any] = field(default_factory=dict)
    boxes: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def why(self, name: str) -> str:
        """The first note of object ``name`` (empty when it has none)."""
        return next((n for n in self.notes if n.startswith(f"object {name!r}")), "")


def object_shapes(
    physics: Mapping[str, Any], meshes: Mapping[str, Any] | None, budget_mm: float | None = None
) -> Shapes:
    """Split a recording's object meshes into boxes and mesh shapes (module docstring).

    Args:
        physics: the physics.json document.
        meshes: object name -> mesh (:attr:`robogs.physics.recording.Recording.meshes`).
        budget_mm: the dataset's ``geometry.box3d_mm`` (default: the format's default).

    Raises:
        FormatError: a mesh with no volume (:func:`robogs.format.mjcf.collision_hull`).
    """
    from robogs.format.budgets import DEFAULT_BUDGETS
    from robogs.format.mjcf import collision_hull

    if budget_mm is None:
        budget_mm = DEFAULT_BUDGETS[BOX_BUDGET].value
    objects = physics.get("objects") or {}
    out = Shapes()
    for name, mesh in sorted((meshes or {}).items()):
        entry = objects.get(name)
        if not isinstance(entry, Mapping) or entry.get("equation") != "rigid":
            continue
        hull, sub = collision_hull(mesh, name)  # a flat mesh fails here, naming the object
        if "size_m" in entry:
            d = box_distance_m(mesh, entry["size_m"])  # the full hull, not the decimated one
            if d * 1e3 <= budget_mm:
                out.boxes[name] = d
                continue
            why = (
                f"its convex hull is {d * 1e3:.1f} mm from the box of size_m "
                f"(> {BOX_BUDGET} {budget_mm:g} mm)"
            )
        else:
            why = "no size_m"
        out.meshes[name] = mesh
        out.notes.append(
            f"object {name!r} has a mesh shape ({why}): simulated as its convex hull "
            f"({len(hull.vertices)} vertices, {hull.volume * 1e6:.1f} cm^3)"
        )
        if sub:
            out.notes.append(sub)
    return out

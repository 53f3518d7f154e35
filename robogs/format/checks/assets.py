"""Facts about asset meshes that several checks share: the convex hull, and whether a mesh
looks like millimetres. Read through :class:`~robogs.format.checks.context.CheckContext`
(cached there once per asset)."""

from __future__ import annotations

import numpy as np

from .context import CheckContext, InputReported

__all__ = ["MM_SUSPECT_EXTENT_M", "hull_vertices", "mesh_unit_problem"]

#: an object or table mesh larger than this (m) was almost surely exported in mm
MM_SUSPECT_EXTENT_M = 10.0


def hull_vertices(ctx: CheckContext, name: str) -> np.ndarray:
    """[V, 3] convex-hull vertices of an asset mesh (asset frame, m); bounds the mesh.

    Raises:
        InputReported: the asset has no mesh, or its path is unsafe or missing.
        RobogsError: the mesh does not load (G006 reports it).
    """

    def build() -> np.ndarray:
        mesh = ctx.asset_mesh(name)
        try:
            return np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
        except Exception:  # degenerate (flat) meshes have no 3D hull
            return np.asarray(mesh.vertices, dtype=np.float64)

    return ctx.cached(("hull", name), build, reported=False)


def mesh_unit_problem(ctx: CheckContext, name: str) -> str | None:
    """Why an asset mesh looks like millimetres (None if it looks like metres).

    Two signs: an object/table mesh larger than :data:`MM_SUSPECT_EXTENT_M`, or a mesh
    100-10000x larger than the ``size_m`` physics.json gives it.
    """

    def build() -> str | None:
        extent = float(np.max(np.ptp(hull_vertices(ctx, name), axis=0)))
        if ctx.asset_kind(name) in ("object", "table") and extent > MM_SUSPECT_EXTENT_M:
            return f"mesh extent {extent:.4g} m exceeds {MM_SUSPECT_EXTENT_M:g} m"
        try:
            size = (ctx.physics().get("objects") or {}).get(name, {}).get("size_m")
        except InputReported:
            size = None
        if size:
            ratio = extent / max(float(max(size)), 1e-12)
            if 100.0 <= ratio <= 10000.0:
                return (
                    f"mesh extent {extent:.4g} m is {ratio:.0f}x the physics size {max(size):.4g} m"
                )
        return None

    return ctx.cached(("mm", name), build, reported=False)

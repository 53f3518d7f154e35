"""Helpers shared by the check modules: unit factors, column reads, stream tables, meshes and
rigid-body sanity.

numpy only (trimesh is imported where a hull is built): importing the check modules, as
``--quick`` does, must stay cheap.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from ..frames import quat_to_matrix_np
from .assets import hull_vertices, mesh_unit_problem
from .context import CheckContext, InputReported

__all__ = [
    "MM",
    "MS",
    "column",
    "stack_columns",
    "frame_stamps",
    "stream_tables",
    "usable_mesh",
    "quat_to_matrix_np",
    "inertia_problem",
    "fmt3",
    "hull_distance_outside",
    "com_outside_mm",
]

#: metres -> millimetres
MM = 1000.0
#: nanoseconds -> milliseconds
MS = 1e-6


# --------------------------------------------------------------------------- tables


def column(tab: Any, name: str, rows: np.ndarray | None = None) -> np.ndarray:
    """One column of a pyarrow table as a numpy array (optionally only ``rows``)."""
    values = tab.column(name).to_numpy(zero_copy_only=False)
    return values if rows is None else values[rows]


def stack_columns(tab: Any, names: tuple[str, ...], rows: np.ndarray | None = None) -> np.ndarray:
    """[N, len(names)] columns side by side, e.g. ``("x", "y", "z")`` or ``("qw", ..., "qz")``."""
    return np.stack([column(tab, c, rows) for c in names], axis=1)


def frame_stamps(tab: Any) -> tuple[np.ndarray, np.ndarray]:
    """([F] int64 ``t_ns``, [F] int64 ``frame_index``) of a camera frame table."""
    return (
        column(tab, "t_ns").astype(np.int64),
        column(tab, "frame_index").astype(np.int64),
    )


def stream_tables(
    ctx: CheckContext, kind: str, columns: tuple[str, ...] | None = None
) -> Iterator[tuple[Any, str, str, Any]]:
    """``(episode, stream name, path, table)`` of every readable stream table of ``kind``.

    Streams without a path, and tables that are unreadable or off their schema (reported by the
    integrity and schema checks), are skipped.
    """
    for ep, name, st in ctx.streams((kind,)):
        rel = st.get("path")
        if not isinstance(rel, str):
            continue
        try:
            tab = ctx.table(rel, columns=columns)
        except InputReported:
            continue
        yield ep, name, rel, tab


def usable_mesh(ctx: CheckContext, name: str) -> np.ndarray | None:
    """Hull vertices [V, 3] (m, asset frame) of an asset whose mesh loads and is in metres."""
    try:
        if mesh_unit_problem(ctx, name):
            return None  # reported by G006
        return hull_vertices(ctx, name)
    except InputReported:
        return None


# --------------------------------------------------------------------------- rigid bodies


def inertia_problem(inertia: np.ndarray, rel: float) -> str | None:
    """Why a 3x3 inertia tensor (kg m^2) is not physical, or None.

    A rigid body's inertia is symmetric positive definite and its principal
    moments satisfy the triangle inequality ``I_a + I_b >= I_c``; ``rel`` is the
    slack relative to the trace.
    """
    inertia = np.asarray(inertia, np.float64)
    if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
        return "inertia is not a finite 3x3 matrix"
    scale = max(float(np.abs(np.trace(inertia))), 1e-300)
    if np.max(np.abs(inertia - inertia.T)) > rel * scale:
        return "inertia is not symmetric"
    ev = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    if ev[0] <= 0:
        return f"inertia is not positive definite (principal moments {fmt3(ev)} kg m^2)"
    if ev[0] + ev[1] < ev[2] - rel * scale:
        return f"principal moments {fmt3(ev)} kg m^2 violate the triangle inequality I1 + I2 >= I3"
    return None


def fmt3(v: np.ndarray) -> str:
    """``[a, b, c]`` with 4 significant digits each."""
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"


def hull_distance_outside(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (m) of points outside the convex hull of ``vertices`` (0 inside).

    Uses the largest signed distance to the hull's facet planes, a lower bound of
    the Euclidean distance that is exact where the nearest feature is a facet.

    Args:
        vertices: [V, 3] points spanning the hull, metres.
        points: [P, 3] query points, same frame.
    """
    import trimesh

    hull = trimesh.convex.convex_hull(np.asarray(vertices, np.float64))
    normals = np.asarray(hull.face_normals)
    offsets = np.einsum("fj,fj->f", normals, np.asarray(hull.triangles_center))
    d = np.asarray(points, np.float64) @ normals.T - offsets
    return np.maximum(d.max(axis=1), 0.0)


def com_outside_mm(vertices: np.ndarray, com: Any) -> float | None:
    """Distance (mm) of a centre of mass [3] (m) outside the hull of ``vertices``; None when no
    hull can be built (too few or degenerate vertices) or ``com`` is not a 3-vector."""
    try:
        return float(hull_distance_outside(vertices, np.asarray(com, np.float64)[None])[0]) * MM
    except Exception:  # trimesh/qhull raise several types on degenerate input
        return None

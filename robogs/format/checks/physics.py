"""Physics checks (P0xx): the attributes in ``physics.json`` describe physical bodies.

These read only ``physics.json`` (schema-valid; violations are S002) and the
asset meshes. Masses are kg, inertias kg m^2 about the CoM in the object frame,
the CoM in metres in the object (mesh) frame.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from ..findings import Finding
from ._common import com_outside_mm, inertia_problem, usable_mesh
from .context import CheckContext
from .registry import Check, check

__all__: list[str] = []

_DYNAMIC = ("rigid", "articulated")


def _objects(ctx: CheckContext) -> Iterator[tuple[str, dict, str]]:
    doc = ctx.physics()
    rel = ctx.manifest["physics"]
    for name, obj in sorted((doc.get("objects") or {}).items()):
        if isinstance(obj, dict):
            yield name, obj, rel


@check(
    "P001",
    group="physics",
    severity="error",
    title="object inertias are positive definite and satisfy the triangle inequality",
    quantity="inertia tensor",
    budget="geometry.inertia_rel",
    hint="inertia_kgm2 is the 3x3 tensor about the CoM in kg m^2; recompute it from the mesh and mass",
)
def _inertia(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    rel_slack = ctx.budget("geometry.inertia_rel")
    for name, obj, rel in _objects(ctx):
        if "inertia_kgm2" in obj:
            problem = inertia_problem(np.asarray(obj["inertia_kgm2"], dtype=np.float64), rel_slack)
            if problem:
                yield chk.finding(
                    problem, file=rel, where=f"/objects/{name}/inertia_kgm2", object=name
                )


@check(
    "P002",
    group="physics",
    severity="error",
    title="dynamic friction does not exceed static friction",
    quantity="friction_dynamic - friction_static",
    unit="",
    hint="Coulomb friction has friction_dynamic <= friction_static; swap or re-fit them",
)
def _friction(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for name, obj, rel in _objects(ctx):
        mu_s, mu_d = obj.get("friction_static"), obj.get("friction_dynamic")
        if isinstance(mu_s, int | float) and isinstance(mu_d, int | float) and mu_d > mu_s:
            yield chk.finding(
                f"friction_dynamic {mu_d:g} > friction_static {mu_s:g}",
                value=mu_d - mu_s,
                budget=0,
                file=rel,
                where=f"/objects/{name}",
                object=name,
            )


@check(
    "P003",
    group="physics",
    severity="warning",
    title="dynamic objects declare mass and inertia",
    quantity="missing attributes",
    hint="add mass_kg, com_m and inertia_kgm2 for objects whose equation is rigid or articulated",
)
def _complete(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for name, obj, rel in _objects(ctx):
        if obj.get("equation") in _DYNAMIC:
            missing = [k for k in ("mass_kg", "inertia_kgm2") if k not in obj]
            if missing:
                yield chk.finding(
                    f"{obj['equation']} object lacks {', '.join(missing)}",
                    file=rel,
                    where=f"/objects/{name}",
                    object=name,
                )


@check(
    "P004",
    group="physics",
    severity="error",
    title="object CoM lies inside the object's mesh",
    quantity="CoM distance outside the mesh's convex hull",
    unit="mm",
    budget="geometry.com_outside_mm",
    hint="com_m is in the object (mesh) frame, in metres",
)
def _com(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("geometry.com_outside_mm")
    assets = set(ctx.asset_names())
    for name, obj, rel in _objects(ctx):
        com = obj.get("com_m")
        if com is None or name not in assets:
            continue
        verts = usable_mesh(ctx, name)  # None: unreadable or in mm, reported by G006
        d_mm = None if verts is None else com_outside_mm(verts, com)
        if d_mm is not None and d_mm > budget:
            yield chk.finding(
                f"CoM {list(com)} m is {d_mm:.4g} mm outside the mesh",
                value=d_mm,
                budget=budget,
                file=rel,
                where=f"/objects/{name}/com_m",
                object=name,
            )

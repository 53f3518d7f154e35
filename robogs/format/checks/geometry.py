"""Geometry checks (G0xx): URDF sanity, units, joint limits, kinematics and boxes.

Measured values are in the units of the budgets: mm for lengths, px for image
boxes, rad (or m for prismatic joints) for joint limits.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FormatError, RobogsError
from ..findings import Finding
from ..meshes import load_mesh
from ._common import (
    MM,
    column,
    com_outside_mm,
    fmt3,
    inertia_problem,
    quat_to_matrix_np,
    stack_columns,
    stream_tables,
    usable_mesh,
)
from .assets import MM_SUSPECT_EXTENT_M, hull_vertices, mesh_unit_problem
from .context import CheckContext, InputReported
from .registry import Check, check
from .streaming import MedianSketch, SampleWindow, batches

__all__: list[str] = []

#: end-effector rows per forward-kinematics batch (bounds the [rows, links, 4, 4] poses)
_FK_ROWS = 1 << 13


# --------------------------------------------------------------------------- shared helpers


@dataclass(frozen=True)
class _LinkGeometry:
    """Vertices of one link's geometry in the link frame, and where they came from."""

    link: str
    vertices: np.ndarray  # [V, 3] link frame, metres
    sources: tuple[str, ...]
    mm_problem: str | None


def _load_mesh_file(path: Path, scale: Any) -> np.ndarray:
    mesh = load_mesh(path, triangles=False)
    v = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), np.float64)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise FormatError(
            "mesh has no (finite) vertices",
            path=path,
            hint="the file is empty or corrupt; re-export the mesh",
        )
    if scale is not None:
        v = v * np.broadcast_to(np.asarray(scale, np.float64), (3,))
    return v


def _mesh_vertices(ctx: CheckContext, path: Path, scale: Any) -> np.ndarray:
    v = ctx.cached(("mesh-file", str(path)), lambda: _load_mesh_file(path, None), reported=False)
    return v * np.broadcast_to(np.asarray(scale, np.float64), (3,)) if scale is not None else v


def _primitive_vertices(geom: Any) -> np.ndarray | None:
    import trimesh

    if geom.box is not None:
        return np.asarray(trimesh.creation.box(extents=geom.box.size).vertices)
    if geom.cylinder is not None:
        return np.asarray(
            trimesh.creation.cylinder(
                radius=geom.cylinder.radius, height=geom.cylinder.length, sections=16
            ).vertices
        )
    if geom.sphere is not None:
        return np.asarray(
            trimesh.creation.icosphere(subdivisions=1, radius=geom.sphere.radius).vertices
        )
    return None


def link_geometry(ctx: CheckContext, *, prefer: str = "collision") -> dict[str, _LinkGeometry]:
    """Per link: its geometry as link-frame vertices (cached).

    Args:
        prefer: ``"collision"`` (for mass properties) or ``"visual"`` (for images);
            the other kind is used when a link has none of the preferred one.
    """
    return ctx.cached(
        ("link-geometry", prefer), lambda: _link_geometry(ctx, prefer), reported=False
    )


def _link_geometry(ctx: CheckContext, prefer: str) -> dict[str, _LinkGeometry]:
    from ..urdf import MESH_SUFFIXES, resolve_mesh_uri

    urdf = ctx.urdf()
    urdf_path = ctx.urdf_path()
    uri_cache: dict[str, Path] = {}
    out: dict[str, _LinkGeometry] = {}
    for link in urdf.robot.links:
        for kind in (prefer, "visual" if prefer == "collision" else "collision"):
            items = link.collisions if kind == "collision" else link.visuals
            parts: list[np.ndarray] = []
            sources: list[str] = []
            problem = None
            for item in items:
                geom = item.geometry
                if geom is None:
                    continue
                if geom.mesh is not None:
                    where = f"link '{link.name}' {kind} mesh '{geom.mesh.filename}'"
                    try:
                        path = resolve_mesh_uri(
                            geom.mesh.filename, urdf_path, ctx.root, _cache=uri_cache
                        )
                    except RobogsError as exc:
                        raise type(exc)(
                            exc.message, path=urdf_path, where=where, hint=exc.hint
                        ) from None
                    if not path.is_file() or path.suffix.lower() not in MESH_SUFFIXES:
                        raise FormatError(
                            "mesh file not found or of an unsupported type",
                            path=urdf_path,
                            where=where,
                            hint=f"use an existing {sorted(MESH_SUFFIXES)} file",
                        )
                    v = _mesh_vertices(ctx, path, geom.mesh.scale)
                    sources.append(ctx.rel(path) or str(path))
                    if v.size:
                        ext = float(np.max(np.ptp(v, axis=0)))
                        if ext > MM_SUSPECT_EXTENT_M:
                            problem = f"{kind} mesh {sources[-1]} spans {ext:.4g} m"
                else:
                    v = _primitive_vertices(geom)
                    if v is None:
                        continue
                    sources.append(f"{kind} primitive")
                if v.size == 0:
                    continue
                T = np.asarray(item.origin if item.origin is not None else np.eye(4), np.float64)
                parts.append(v @ T[:3, :3].T + T[:3, 3])
            if parts:
                out[link.name] = _LinkGeometry(
                    link.name, np.concatenate(parts), tuple(sources), problem
                )
                break
    return out


def _robot_or_skip(ctx: CheckContext) -> None:
    if not ctx.has_robot():
        raise InputReported("robot")


# --------------------------------------------------------------------------- URDF sanity


def _moving_links(ctx: CheckContext) -> set[str]:
    return {j.child for j in ctx.urdf().robot.joints if j.type not in ("fixed",)}


def _mass(link: Any) -> float | None:
    """A link's declared mass (kg), or None without an <inertial>/<mass>."""
    inertial = link.inertial
    return None if inertial is None or inertial.mass is None else float(inertial.mass)


def _bodies(ctx: CheckContext) -> dict[str, tuple[str, bool, float]]:
    """Per link: (rigid body it belongs to, whether that body moves, the body's mass in kg).

    Links joined by fixed joints form one rigid body, named after its top link; simulators
    lump them (URDF importers of MuJoCo, PyBullet and Isaac merge fixed children into their
    parent). A body moves when a non-fixed joint carries its top link; the body at the root
    is fixed to the world (the robot's base is bolted down, FORMAT.md §4). Its mass is the
    sum of the positive finite masses of its links.
    """
    robot = ctx.urdf().robot
    parent = {j.child: j for j in robot.joints}
    top: dict[str, str] = {}
    for link in robot.links:
        name = link.name
        while name in parent and parent[name].type == "fixed":
            name = parent[name].parent
        top[link.name] = name
    mass: dict[str, float] = {}
    for link in robot.links:
        m = _mass(link)
        if m is not None and np.isfinite(m) and m > 0:
            mass[top[link.name]] = mass.get(top[link.name], 0.0) + m
    return {
        link.name: (top[link.name], top[link.name] in parent, mass.get(top[link.name], 0.0))
        for link in robot.links
    }


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "G001",
    group="geometry",
    severity="error",
    title="the robot URDF and its meshes load",
    quantity="load errors",
    hint="fix the URDF element or mesh named in the message; mesh paths stay inside the dataset",
)
def _urdf_loads(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    _robot_or_skip(ctx)
    rel = ctx.manifest["robot"]["urdf"]
    ctx.existing(rel)
    try:
        ctx.chain()
        link_geometry(ctx)
    except RobogsError as exc:
        yield chk.finding(
            exc.message,
            file=ctx.rel(exc.path) if exc.path else rel,
            where=exc.where,
            hint=exc.hint or chk.hint,
        )


@check(
    "G002",
    group="geometry",
    severity="error",
    title="URDF link masses are positive",
    quantity="link mass",
    unit="kg",
    hint="give every moving body an <inertial> with mass > 0 kg (not grams); massless frame "
    "links (base, tool0, ee_link) are normal and merge into the body they are fixed to",
)
def _link_mass(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    """Graded by consequence: a negative or non-finite mass, or a moving body without any mass,
    breaks simulation (error); a link of mass 0 fixed to a body that has mass, or to the world,
    is a frame (note; without <inertial> it is not mentioned); a moving body with no <inertial>
    at all cannot be simulated (warning)."""
    _robot_or_skip(ctx)
    urdf_rel = ctx.manifest["robot"]["urdf"]
    bodies = _bodies(ctx)
    for link in ctx.urdf().robot.links:
        m = _mass(link)
        where = {"file": urdf_rel, "where": f"link '{link.name}'", "link": link.name}
        top, moving, body_mass = bodies[link.name]
        if m is not None and (not np.isfinite(m) or m < 0):
            yield chk.finding(f"mass is {m:g} kg", value=m, budget=0, **where)
            continue
        if m is not None and m > 0:
            continue
        if moving and body_mass <= 0:
            if m is None:
                yield chk.finding(
                    f"moving body '{top}' has no <inertial>; dynamics cannot be simulated",
                    severity="warning",
                    **where,
                )
            else:
                yield chk.finding(
                    f"mass is 0 kg and the moving body '{top}' it belongs to has no mass: "
                    "a simulator cannot integrate it",
                    value=m,
                    budget=0,
                    **where,
                )
            continue
        if m is None:
            continue  # a frame written without <inertial>: the usual spelling, nothing to say
        lumped = (
            f"merges into the moving body '{top}' ({body_mass:.4g} kg)"
            if moving
            else "is fixed to the world (its mass is not simulated)"
        )
        yield chk.finding(
            f"massless frame link (mass 0 kg): it {lumped}",
            value=m,
            budget=0,
            severity="info",
            **where,
        )


@check(
    "G003",
    group="geometry",
    severity="error",
    title="URDF link inertias are positive definite and satisfy the triangle inequality",
    quantity="inertia tensor",
    budget="geometry.inertia_rel",
    hint="take the inertia from the mesh and density (or a CAD tool); ixx, iyy, izz are > 0 kg m^2",
)
def _link_inertia(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    """A link with mass needs a physical inertia (simulators reject the others when they load
    the model); an all-zero inertia is a note on a massless frame link (G002 says so) or on a
    body fixed to the world, and an error on a moving body (a point mass cannot rotate)."""
    _robot_or_skip(ctx)
    urdf_rel = ctx.manifest["robot"]["urdf"]
    rel = ctx.budget("geometry.inertia_rel")
    bodies = _bodies(ctx)
    for link in ctx.urdf().robot.links:
        inertial = link.inertial
        if inertial is None or inertial.inertia is None:
            continue
        inertia = np.asarray(inertial.inertia, np.float64)
        problem = inertia_problem(inertia, rel)
        if not problem:
            continue
        m = _mass(link)
        where = {"file": urdf_rel, "where": f"link '{link.name}' <inertia>", "link": link.name}
        zero = inertia.shape == (3, 3) and np.all(inertia == 0)
        if zero and (m is None or m == 0):
            continue  # a massless frame link: G002 notes it
        if zero and not bodies[link.name][1]:
            yield chk.finding(
                problem + "; the link is fixed to the world, so it is not simulated",
                severity="info",
                **where,
            )
            continue
        yield chk.finding(problem, **where)


@check(
    "G004",
    group="geometry",
    severity="error",
    title="URDF link CoM lies inside the link's geometry",
    quantity="CoM distance outside the convex hull",
    unit="mm",
    budget="geometry.com_outside_mm",
    hint="the <inertial><origin> is in the link frame, in metres; check its sign and units",
)
def _link_com(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    _robot_or_skip(ctx)
    urdf_rel = ctx.manifest["robot"]["urdf"]
    budget = ctx.budget("geometry.com_outside_mm")
    geoms = link_geometry(ctx)
    for link in ctx.urdf().robot.links:
        g = geoms.get(link.name)
        if link.inertial is None or g is None or g.mm_problem or len(g.vertices) < 4:
            continue
        T = np.asarray(link.inertial.origin if link.inertial.origin is not None else np.eye(4))
        com = T[:3, 3]
        d_mm = com_outside_mm(g.vertices, com)
        if d_mm is not None and d_mm > budget:
            # a CoM left at the link origin is the URDF default: a placeholder, not a sign or
            # unit error, and simulation still runs (with approximate gravity torques)
            at_origin = bool(np.all(com == 0)) and bool(link.visuals)
            yield chk.finding(
                f"CoM {fmt3(com)} m is {d_mm:.4g} mm outside the link's geometry"
                + (" (left at the link origin, the URDF default)" if at_origin else ""),
                value=d_mm,
                budget=budget,
                severity="info" if at_origin else None,
                file=urdf_rel,
                where=f"link '{link.name}' <inertial>",
                link=link.name,
            )


@check(
    "G005",
    group="geometry",
    severity="error",
    title="URDF meshes are in metres",
    quantity="mesh extent",
    unit="m",
    hint='the mesh was exported in millimetres: rescale it by 0.001 or set <mesh scale="0.001 0.001 0.001">',
)
def _link_units(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    _robot_or_skip(ctx)
    urdf_rel = ctx.manifest["robot"]["urdf"]
    for name, g in sorted(link_geometry(ctx).items()):
        if g.mm_problem:
            ext = float(np.max(np.ptp(g.vertices, axis=0)))
            yield chk.finding(
                f"{g.mm_problem}: looks like millimetres",
                value=ext,
                budget=MM_SUSPECT_EXTENT_M,
                file=urdf_rel,
                where=f"link '{name}'",
                link=name,
            )


@check(
    "G006",
    group="geometry",
    severity="error",
    title="asset meshes load and are in metres",
    quantity="mesh extent",
    unit="m",
    hint="the mesh was exported in millimetres: rescale its vertices by 0.001",
)
def _asset_units(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for name in ctx.asset_names():
        try:
            problem = mesh_unit_problem(ctx, name)
        except InputReported:
            continue
        except RobogsError as exc:
            yield chk.finding(
                exc.message,
                file=ctx.rel(exc.path),
                where=exc.where,
                object=name,
                hint=exc.hint or "re-export the mesh as PLY, OBJ, STL or GLB",
            )
            continue
        if problem:
            ext = float(np.max(np.ptp(hull_vertices(ctx, name), axis=0)))
            yield chk.finding(
                f"{problem}: looks like millimetres",
                value=ext,
                budget=MM_SUSPECT_EXTENT_M,
                file=ctx.manifest["assets"][name]["mesh"],
                object=name,
            )


# --------------------------------------------------------------------------- joints and kinematics


def joint_positions(
    ctx: CheckContext, ep: Any, stream: str, joints: list[str]
) -> tuple[np.ndarray, np.ndarray]:
    """([N] int64 t_ns, [N, J] positions) of the named joints from a joint_states stream."""
    rel = ep.streams[stream]["path"]
    names = ctx.footer(rel).schema.to_arrow_schema().names
    cols = [f"position.{j}" for j in joints]
    if any(c not in names for c in cols) or "t_ns" not in names:
        raise InputReported("joint columns")  # reported by S003/S007
    tab = ctx.table(rel, columns=("t_ns", *cols))
    t = np.array(column(tab, "t_ns"), dtype=np.int64)
    q = stack_columns(tab, tuple(cols)) if cols else np.zeros((t.size, 0))
    return t, q.astype(np.float64, copy=False)


@check(
    "G007",
    group="geometry",
    severity="error",
    title="recorded joints stay within their URDF limits",
    quantity="excess beyond the limit",
    unit="rad",
    budget="geometry.joint_limit_rad",
    hint="check the joint offset/sign convention and the URDF <limit>; prismatic joints are in metres",
)
def _joint_limits(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    _robot_or_skip(ctx)
    budget = ctx.budget("geometry.joint_limit_rad")
    chain = ctx.chain()
    urdf_rel = ctx.manifest["robot"]["urdf"]
    for ep, name, st in ctx.streams(("joint_states",)):
        rel = st.get("path")
        try:
            names = ctx.footer(rel).schema.to_arrow_schema().names
        except InputReported:
            continue
        present = [j for j in chain.joint_names if f"position.{j}" in names]
        if not present or "t_ns" not in names:
            continue
        idx = [chain.joint_names.index(j) for j in present]
        lo, hi = chain.joint_lower[idx], chain.joint_upper[idx]
        worst = np.full(len(present), -np.inf)  # streamed: largest excess, its value, stamp, row
        at_q, at_t, at_row = (
            np.zeros(len(present)),
            np.zeros(len(present), np.int64),
            np.zeros(len(present), np.int64),
        )
        n_over = np.zeros(len(present), np.int64)
        offset = 0
        try:
            for b in batches(ctx, rel, ("t_ns", *(f"position.{j}" for j in present))):
                t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
                q = np.stack(
                    [b.column(k + 1).to_numpy(zero_copy_only=False) for k in range(len(present))],
                    axis=1,
                ).astype(np.float64, copy=False)
                excess = np.maximum(lo[None] - q, q - hi[None])  # [B, J]
                excess = np.where(np.isfinite(excess), excess, 0.0)
                n_over += np.sum(excess > budget, axis=0)
                i = np.argmax(excess, axis=0)
                best = excess[i, np.arange(len(present))]
                better = best > worst
                worst[better] = best[better]
                at_q[better] = q[i, np.arange(len(present))][better]
                at_t[better] = t[i][better]
                at_row[better] = offset + i[better]
                offset += t.size
        except InputReported:
            continue
        for k, j in enumerate(present):
            if worst[k] > budget:
                unit = (
                    "m"
                    if chain.joint_types[chain.tree_joint_names.index(j)] == "prismatic"
                    else "rad"
                )
                yield chk.finding(
                    f"joint {j!r} reaches {at_q[k]:.6g} {unit}, outside [{lo[k]:.6g}, {hi[k]:.6g}] "
                    f"({urdf_rel}) in {int(n_over[k])} samples",
                    value=float(worst[k]),
                    budget=budget,
                    unit=unit,
                    file=rel,
                    episode=ep.id,
                    stream=name,
                    link=j,
                    t_ns=int(at_t[k]),
                    where=f"row {int(at_row[k])}",
                )


def _world_from_root(ctx: CheckContext, T_root: Any, chain: Any) -> Any:
    """Re-express FK poses (root frame, [..., L, 4, 4] torch) in the world frame (origin at the robot base)."""
    import torch

    robot = ctx.manifest.get("robot") or {}
    base = robot.get("base_link")
    if not isinstance(base, str) or base == chain.link_names[0] or base not in chain.link_names:
        return T_root
    T_root_base = T_root[..., chain.link_index(base), :, :]
    return torch.linalg.inv(T_root_base)[..., None, :, :] @ T_root


def _strictly_increasing(ctx: CheckContext, rel: str) -> tuple[int, int] | None:
    """(first, last) stamp of a table whose ``t_ns`` strictly increases; None otherwise."""
    first = last = None
    for b in batches(ctx, rel, ("t_ns",)):
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        if t.size == 0:
            continue
        if last is not None and t[0] <= last or not np.all(np.diff(t) > 0):
            return None
        first = int(t[0]) if first is None else first
        last = int(t[-1])
    return None if first is None else (first, last)


def _ordered_links(ctx: CheckContext, rel: str) -> dict[str, bool]:
    """Per link of an ee_poses table: whether its stamps strictly increase (table order)."""
    last: dict[str, int] = {}
    ok: dict[str, bool] = {}
    for b in batches(ctx, rel, ("t_ns", "link")):
        t = b.column(0).to_numpy(zero_copy_only=False).astype(np.int64, copy=False)
        links = column(b, "link").astype(str)
        for link in np.unique(links).tolist():
            tl = t[links == link]
            if link in last:
                tl = np.concatenate(([last[link]], tl))
            ok[link] = ok.get(link, True) and bool(np.all(np.diff(tl) > 0))
            last[link] = int(tl[-1])
    return ok


@dataclass
class _FkError:
    """Streamed error statistics of one link."""

    n: int = 0
    over: int = 0
    worst_mm: float = -np.inf
    at_t: int = 0
    at_row: int = 0
    worst_deg: float = -np.inf
    median: MedianSketch = field(default_factory=MedianSketch)


@check(
    "G008",
    group="geometry",
    severity="error",
    title="recorded end-effector poses match forward kinematics",
    quantity="position error |FK(q(t)) - recorded|",
    unit="mm",
    budget="geometry.fk_ee_mm",
    hint="check the URDF (link lengths, joint offsets), the joint sign convention and the ee_poses "
    "link frame; fitted joint offsets (robogs fit --add kinematic_offsets) are applied",
)
def _fk_ee(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    import torch

    from ..interp import interp_linear

    _robot_or_skip(ctx)
    budget = ctx.budget("geometry.fk_ee_mm")
    chain, fk_note = ctx.fitted_chain()
    qcols = tuple(f"position.{j}" for j in chain.joint_names)
    for ep, name, st in ctx.streams(("ee_poses",)):
        js = ctx.find_stream(ep, "joint_states")
        rel = st.get("path")
        if js is None or not isinstance(rel, str):
            continue
        js_rel = ep.streams[js]["path"]
        try:
            js_names = ctx.footer(js_rel).schema.to_arrow_schema().names
            if any(c not in js_names for c in qcols) or "t_ns" not in js_names:
                continue  # reported by S003/S007
            js_range = _strictly_increasing(ctx, js_rel)
            if js_range is None:
                continue  # reported by T001
            ok = _ordered_links(ctx, rel)  # unordered links are reported by T001
            todo = {link for link, good in ok.items() if good and link in chain.link_names}
            stats = {link: _FkError() for link in todo}
            window = SampleWindow(ctx, js_rel, qcols)
            offset = 0
            cols = ("t_ns", "link", "x", "y", "z", "qw", "qx", "qy", "qz")
            for b in batches(ctx, rel, cols, batch_rows=_FK_ROWS):
                t_all = column(b, "t_ns").astype(np.int64)
                links = column(b, "link").astype(str)
                rows_all = np.arange(offset, offset + t_all.size)
                offset += t_all.size
                keep = np.isin(links, list(todo)) & (t_all >= js_range[0]) & (t_all <= js_range[1])
                if not keep.any():
                    continue
                t_js, q = window.around(int(t_all[keep].min()), int(t_all[keep].max()))
                for link in sorted(set(links[keep].tolist())):
                    sel = np.flatnonzero(keep & (links == link))
                    t = t_all[sel]
                    qi = torch.as_tensor(interp_linear(t, t_js, q), dtype=torch.float64)
                    k = chain.link_index(link)
                    T = _world_from_root(ctx, chain.forward(qi), chain)[:, k].numpy()
                    xyz = stack_columns(b, ("x", "y", "z"), sel)
                    err_mm = np.linalg.norm(T[:, :3, 3] - xyz, axis=1) * MM
                    R_rec = quat_to_matrix_np(stack_columns(b, ("qw", "qx", "qy", "qz"), sel))
                    cos = (np.einsum("nij,nij->n", T[:, :3, :3], R_rec) - 1.0) / 2.0
                    ang_deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
                    s = stats[link]
                    s.n += t.size
                    s.over += int(np.sum(err_mm > budget))
                    s.median.add(err_mm)
                    s.worst_deg = max(s.worst_deg, float(ang_deg.max()))
                    i = int(np.argmax(err_mm))
                    if err_mm[i] > s.worst_mm:
                        s.worst_mm, s.at_t, s.at_row = (
                            float(err_mm[i]),
                            int(t[i]),
                            int(rows_all[sel[i]]),
                        )
        except InputReported:
            continue
        for link in sorted(stats):
            s = stats[link]
            if s.n and s.worst_mm > budget:
                approx = "" if s.median.exact else "~"
                yield chk.finding(
                    f"link {link!r}: FK differs from the recorded pose by up to {s.worst_mm:.4g} mm "
                    f"(median {approx}{s.median.median():.3g} mm, {s.over} of {s.n} samples over "
                    f"budget; orientation up to {s.worst_deg:.3g} deg"
                    + (f"; {fk_note})" if fk_note else ")"),
                    value=s.worst_mm,
                    budget=budget,
                    file=rel,
                    episode=ep.id,
                    stream=name,
                    link=link,
                    t_ns=s.at_t,
                    where=f"row {s.at_row}",
                )


# --------------------------------------------------------------------------- boxes and objects


@check(
    "G009",
    group="geometry",
    severity="error",
    title="2D boxes match the labelled pixels",
    quantity="largest box edge offset from the label's pixel bounds",
    unit="px",
    budget="geometry.box2d_px",
    hint="2D boxes are pixel edges with x_max/y_max exclusive; re-derive them from the label images",
)
def _boxes2d(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("geometry.box2d_px")
    cols = ("t_ns", "camera", "frame_index", "label_id", "x_min", "y_min", "x_max", "y_max")
    for ep, name, rel, boxes in stream_tables(ctx, "boxes2d", cols):
        cam_col = column(boxes, "camera").astype(str)
        for sname, cst in ep.streams.items():
            if (
                not isinstance(cst, dict)
                or cst.get("kind") != "camera"
                or not isinstance(cst.get("labels"), str)
            ):
                continue
            rows = np.flatnonzero(cam_col == cst.get("camera"))
            if rows.size == 0:
                continue
            try:
                lb = ctx.label_boxes(ep, sname)
            except InputReported:
                continue
            yield from _compare_boxes(chk, ctx, boxes, rows, lb, budget, rel, ep.id, name)


def _compare_boxes(
    chk: Check,
    ctx: CheckContext,
    boxes: Any,
    rows: np.ndarray,
    lb: Any,
    budget: float,
    rel: str,
    ep_id: str,
    stream: str,
) -> Iterator[Finding]:
    def col(c: str) -> np.ndarray:
        return column(boxes, c, rows)

    fi, lid = col("frame_index").astype(np.int64), col("label_id").astype(np.int64)
    labelled = np.isin(fi, lb.frames)
    key_l = lb.frame_index * 65536 + lb.label_id
    order = np.argsort(key_l)
    key_b = fi * 65536 + lid
    pos = np.clip(np.searchsorted(key_l[order], key_b), 0, max(key_l.size - 1, 0))
    found = (
        (key_l.size > 0) & (key_l[order][pos] == key_b) if key_l.size else np.zeros(fi.size, bool)
    )
    found = np.asarray(found, bool) & labelled
    absent = labelled & ~found
    loc = {"file": rel, "episode": ep_id, "stream": stream}
    if absent.any():
        k = int(np.flatnonzero(absent)[0])
        yield chk.finding(
            f"{int(absent.sum())} boxes name labels absent from their label image "
            f"(first: label {int(lid[k])})",
            frame=int(fi[k]),
            t_ns=int(col("t_ns")[k]),
            where=f"row {int(rows[k])}",
            **loc,
        )
    if not found.any():
        return
    j = order[pos[found]]
    diff = np.stack(
        [
            col("x_min")[found] - lb.x_min[j],
            col("y_min")[found] - lb.y_min[j],
            col("x_max")[found] - lb.x_max[j],
            col("y_max")[found] - lb.y_max[j],
        ],
        axis=1,
    )
    err = np.abs(diff).max(axis=1)
    k = int(np.argmax(err))
    if err[k] > budget:
        idx = np.flatnonzero(found)[k]
        yield chk.finding(
            f"{int(np.sum(err > budget))} boxes differ from their label's pixel bounds by more than the budget; "
            f"worst: label {int(lid[idx])} edges off by {fmt3(diff[k])[1:-1]} px (x_min, y_min, x_max, y_max)",
            value=float(err[k]),
            budget=budget,
            frame=int(fi[idx]),
            t_ns=int(col("t_ns")[idx]),
            where=f"row {int(rows[idx])}",
            **loc,
        )


def object_poses(
    ctx: CheckContext, ep: Any, obj: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """([N] t_ns, [N, 3] position m, [N, 4] wxyz) of one object in an episode, or None."""
    stream = ctx.find_stream(ep, "object_poses")
    if stream is None:
        return None
    tab = ctx.stream_table(
        ep, stream, columns=("t_ns", "object", "x", "y", "z", "qw", "qx", "qy", "qz")
    )

    def index() -> dict[str, np.ndarray]:
        names = column(tab, "object").astype(str)
        return {n: np.flatnonzero(names == n) for n in np.unique(names)}

    rows = ctx.cached(("object-rows", ep.id, stream), index).get(obj)
    if rows is None or rows.size == 0:
        return None
    t = np.array(column(tab, "t_ns", rows), dtype=np.int64)
    if not np.all(np.diff(t) > 0):
        raise InputReported("object stamps")  # reported by T001
    return (
        t,
        stack_columns(tab, ("x", "y", "z"), rows),
        stack_columns(tab, ("qw", "qx", "qy", "qz"), rows),
    )


@check(
    "G010",
    group="geometry",
    severity="error",
    title="3D boxes contain their object's mesh",
    quantity="mesh protrusion beyond the box",
    unit="mm",
    budget="geometry.box3d_mm",
    hint="boxes3d hold the centre pose and full edge lengths in metres; re-derive them from the mesh and pose",
)
def _boxes3d(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    from ..interp import interp_pose

    budget = ctx.budget("geometry.box3d_mm")
    for ep, name, rel, boxes in stream_tables(ctx, "boxes3d"):
        objs = column(boxes, "object").astype(str)
        for obj in sorted(set(objs.tolist())):
            verts = usable_mesh(ctx, obj)
            try:
                poses = object_poses(ctx, ep, obj) if verts is not None else None
            except InputReported:
                continue
            if poses is None:
                continue
            rows = np.flatnonzero(objs == obj)

            t = column(boxes, "t_ns", rows).astype(np.int64)
            p, qo = interp_pose(t, poses[0], poses[1], poses[2], outside="nan")
            ok = np.all(np.isfinite(p), axis=1)
            if not ok.any():
                continue
            R_o = quat_to_matrix_np(qo[ok])
            world = np.einsum("nij,vj->nvi", R_o, verts) + p[ok][:, None, :]  # [N, V, 3]
            c = stack_columns(boxes, ("x", "y", "z"), rows)[ok]
            R_b = quat_to_matrix_np(stack_columns(boxes, ("qw", "qx", "qy", "qz"), rows)[ok])
            local = np.einsum("nji,nvj->nvi", R_b, world - c[:, None, :])
            half = 0.5 * stack_columns(boxes, ("size_x", "size_y", "size_z"), rows)[ok]
            out_mm = (np.abs(local) - half[:, None, :]).max(axis=(1, 2)) * MM
            k = int(np.argmax(out_mm))
            if out_mm[k] > budget:
                idx = np.flatnonzero(ok)[k]
                yield chk.finding(
                    f"object {obj!r} sticks out of its 3D box by up to {out_mm[k]:.4g} mm "
                    f"({int(np.sum(out_mm > budget))} of {out_mm.size} boxes)",
                    value=float(out_mm[k]),
                    budget=budget,
                    file=rel,
                    episode=ep.id,
                    stream=name,
                    object=obj,
                    t_ns=int(t[idx]),
                    where=f"row {int(rows[idx])}",
                )


def _static_pose(ctx: CheckContext, name: str) -> np.ndarray | None:
    """[7] (x, y, z, qw, qx, qy, qz) of a static asset from ``assets.<name>.pose``, if declared."""
    pose = ((ctx.manifest.get("assets") or {}).get(name) or {}).get("pose")
    if isinstance(pose, list) and len(pose) == 7:
        return np.asarray(pose, np.float64)
    return None


def _table_top(
    ctx: CheckContext, ep: Any, table: str
) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(top z in m, xy min, xy max) of a table asset in the world.

    The table is static: its pose is the first ``object_poses`` sample, else the
    asset's declared ``pose``, else the identity.
    """
    verts = usable_mesh(ctx, table)
    if verts is None:
        return None
    poses = object_poses(ctx, ep, table)
    if poses is not None:
        pose = np.concatenate([poses[1][0], poses[2][0]])
    else:
        pose = _static_pose(ctx, table)
    if pose is not None:
        verts = verts @ quat_to_matrix_np(pose[None, 3:])[0].T + pose[:3]
    return float(verts[:, 2].max()), verts[:, :2].min(axis=0), verts[:, :2].max(axis=0)


@check(
    "G011",
    group="geometry",
    severity="error",
    title="objects do not sink into the table",
    quantity="depth of the object's lowest point below the table top",
    unit="mm",
    budget="geometry.penetration_mm",
    hint="the object pose or mesh origin is off (or the table pose); objects rest on the top, not in it",
)
def _penetration(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("geometry.penetration_mm")
    tables = ctx.asset_names(("table",))
    for ep in ctx.episodes:
        stream = ctx.find_stream(ep, "object_poses")
        if stream is None:
            continue
        rel = ep.streams[stream]["path"]
        for table in tables:
            try:
                top = _table_top(ctx, ep, table)
            except InputReported:
                continue
            if top is None:
                continue
            z_top, xy_lo, xy_hi = top
            for obj in ctx.asset_names(("object",)):
                verts = usable_mesh(ctx, obj)
                try:
                    poses = object_poses(ctx, ep, obj) if verts is not None else None
                except InputReported:
                    continue
                if poses is None:
                    continue
                t, p, q = poses
                R = quat_to_matrix_np(q)
                zmin = (np.einsum("nj,vj->nv", R[:, 2, :], verts) + p[:, 2:3]).min(axis=1)
                over = np.all((p[:, :2] >= xy_lo) & (p[:, :2] <= xy_hi), axis=1)
                depth_mm = np.where(over, (z_top - zmin) * MM, -np.inf)
                k = int(np.argmax(depth_mm))
                if depth_mm[k] > budget:
                    yield chk.finding(
                        f"object {obj!r} is {depth_mm[k]:.4g} mm below the top of {table!r} "
                        f"(z_top {z_top:.4g} m) in {int(np.sum(depth_mm > budget))} of {t.size} poses",
                        value=float(depth_mm[k]),
                        budget=budget,
                        file=rel,
                        episode=ep.id,
                        stream=stream,
                        object=obj,
                        t_ns=int(t[k]),
                    )

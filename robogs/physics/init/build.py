"""``robogs physics init``: a physics.json revision built from what a dataset holds.

Order of the sources, per value (the first that exists wins; each value's source is recorded in
``sources`` of physics.json, see :mod:`robogs.physics.init.provenance`):

* **object geometry** - the object's mesh asset (``mesh``), its ``boxes3d`` annotation
  (``annotation``), ``--object NAME=box:LxWxH|mesh:FILE`` (``user``), else estimated from the
  data (``estimated``): the half height is the resting height of the centre above the support
  plane, the half extent along a pushed axis is the pusher-centre distance from the object
  centre along that axis, minus the pusher radius, while the pusher drives the object;
* **support plane** - ``--object table=plane:Z`` (``user``), the top face of a ``table`` mesh
  asset under the objects (``mesh``), else a robust plane through the objects' bottom-face
  centres at rest (``estimated``, needs the object heights);
* **pusher** - the robot link whose collision geometry comes closest to the objects while they
  are pushed (``--pusher LINK`` overrides), its URDF collision shape as the model's sphere or
  capsule (``urdf``); ``--object pusher=sphere:R|capsule:R,L`` (``user``);
* **mass, inertia, friction** - volume x density and the friction coefficients of the object's
  material from a :class:`~robogs.physics.init.priors.PriorProvider` (``prior(<material>)``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robogs.format.errors import FormatError, InputError, RobogsError
from robogs.physics.init.priors import (
    DEFAULT_MATERIAL,
    MaterialTable,
    PriorProvider,
    box_mass_properties,
    mesh_mass_properties,
)
from robogs.physics.init.provenance import Entry
from robogs.physics.init.pusher import Shape, collision_shapes, segment_param, shape_distance
from robogs.physics.init.support import Plane, fit_plane, plane_from_mesh
from robogs.physics.init.tracks import (
    WINDOW_S,
    ObjectTrack,
    link_paths,
    object_tracks,
    windowed_velocity,
)

__all__ = ["ObjectSpec", "InitResult", "parse_object_specs", "build_physics"]

RESERVED = ("table", "pusher")
"""physics.json object names the model reads for the support plane and the end effector."""


@dataclass
class ObjectSpec:
    """What the user said about one name (``--object NAME=...``, repeatable)."""

    box: tuple[float, float, float] | None = None
    mesh: Path | None = None
    material: str | None = None
    sphere: float | None = None
    capsule: tuple[float, float] | None = None
    plane_z: float | None = None


@dataclass
class InitResult:
    """The new physics document, the source of every value, and notes for the user."""

    physics: dict[str, Any]
    entries: list[Entry]
    notes: list[str] = field(default_factory=list)


def _floats(text: str, n: int | None, what: str, sep: str) -> list[float]:
    try:
        vals = [float(v) for v in text.lower().split(sep)]
    except ValueError:
        vals = []
    if (
        not vals
        or (n is not None and len(vals) != n)
        or not all(np.isfinite(vals))
        or min(vals) <= 0
    ):
        raise InputError(
            f"cannot read {what} {text!r}",
            where="--object",
            hint="e.g. box=box:0.1x0.06x0.05, box=mesh:box.ply, box=material:wood, "
            "pusher=sphere:0.01, pusher=capsule:0.01,0.06, table=plane:0.75",
        )
    return vals


def parse_object_specs(items: list[str]) -> dict[str, ObjectSpec]:
    """``NAME=box:LxWxH | mesh:FILE | material:NAME | sphere:R | capsule:R,L | plane:Z``."""
    specs: dict[str, ObjectSpec] = {}
    for item in items:
        name, _, rest = item.partition("=")
        kind, _, arg = rest.partition(":")
        if not name or not arg:
            raise InputError(f"cannot read --object {item!r}", hint="write NAME=KIND:VALUE")
        s = specs.setdefault(name.strip(), ObjectSpec())
        kind = kind.strip().lower()
        if kind == "box":
            s.box = tuple(_floats(arg, 3, "box size (m)", "x"))  # type: ignore[assignment]
        elif kind == "mesh":
            s.mesh = Path(arg)
        elif kind == "material":
            s.material = arg.strip()
        elif kind == "sphere":
            s.sphere = _floats(arg, 1, "sphere radius (m)", ",")[0]
        elif kind == "capsule":
            s.capsule = tuple(_floats(arg, 2, "capsule radius,length (m)", ","))  # type: ignore[assignment]
        elif kind == "plane":
            try:
                s.plane_z = float(arg)
            except ValueError:
                raise InputError(f"cannot read plane height {arg!r}", where="--object") from None
        else:
            raise InputError(
                f"unknown --object kind {kind!r}",
                where=item,
                hint="box, mesh, material (objects); sphere, capsule (pusher); plane (table)",
            )
    return specs


# --------------------------------------------------------------------------- inputs


def _require_inputs(
    ds: Any, specs: dict[str, ObjectSpec]
) -> tuple[list[ObjectTrack], Any, Path | None]:
    """Tracks, the URDF (or None) and its path; one clear error for what is missing."""
    tracks = [t for t in object_tracks(ds) if t.name not in RESERVED]
    if not tracks:
        raise InputError(
            "dataset has no tracked object (no object_poses stream): physics init needs one",
            path=ds.root,
            hint="convert with an object pose topic: robogs convert SRC OUT "
            "--topic object_pose:NAME=TOPIC (or --tf-object NAME=FRAME)",
        )
    robot = ds.manifest.get("robot") or {}
    user_pusher = "pusher" in specs and (specs["pusher"].sphere or specs["pusher"].capsule)
    has_ee = any(ep.has("ee_poses") for ep in ds.episodes)
    if not isinstance(robot.get("urdf"), str):
        if user_pusher and has_ee:
            return tracks, None, None
        raise InputError(
            "dataset has no robot (manifest.robot.urdf): physics init needs the URDF to find "
            "the pusher and its collision geometry",
            path=ds.manifest_path,
            where="robot",
            hint="convert with the robot: robogs convert SRC OUT --urdf ROBOT.urdf",
        )
    path = ds.resolve(robot["urdf"], where="robot/urdf")
    if not path.is_file():
        raise InputError(
            f"the robot URDF {robot['urdf']} is missing from the dataset",
            path=ds.root,
            where="robot/urdf",
            hint="convert again with the robot: robogs convert SRC OUT --urdf ROBOT.urdf",
        )
    return tracks, ds.urdf(load_meshes=False), path


def _mesh_loader(ds: Any, urdf_path: Path):
    def load(uri: str):
        from robogs.format.meshes import load_mesh
        from robogs.format.urdf import resolve_mesh_uri

        p = resolve_mesh_uri(uri, urdf_path, ds.root)
        if not p.is_file():
            raise FormatError(f"collision mesh not found ({p})", path=urdf_path, where=uri)
        return load_mesh(p, where=uri, triangles=False)

    return load


# --------------------------------------------------------------------------- the pusher


@dataclass
class _Pusher:
    link: str
    shape: Shape | None
    offset: np.ndarray  # model point in the link frame [m]
    radius: float
    length: float
    kind: str  # sphere | capsule (the model's shape)
    source: str
    detail: str
    paths: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]]  # (episode, object) -> centre, vel


def _contact_samples(tracks: list[ObjectTrack]) -> list[tuple[ObjectTrack, np.ndarray]]:
    return [(tr, np.flatnonzero(tr.moving)) for tr in tracks if tr.moving.any()]


def _named_frames_on_links(ds: Any, chain: Any) -> dict[str, tuple[str, np.ndarray]]:
    """Named frames (``robot.frames``) fixed to links of ``chain``: name -> (link, T_link_frame)."""
    from robogs.format.named_frames import frame_in_link

    if chain is None:
        return {}
    links = set(chain.link_names)
    out = {}
    for name in ds.named_frames:
        try:
            out[name] = frame_in_link(ds.named_frames, name, links)
        except RobogsError:
            continue  # hangs from something that is not a robot link: not a pusher candidate
    return out


def _choose_pusher(
    ds: Any,
    tracks: list[ObjectTrack],
    chain: Any,
    shapes: list[Shape],
    spec: ObjectSpec | None,
    link: str | None,
) -> _Pusher:
    moving = _contact_samples(tracks)
    if not moving:
        raise InputError(
            "no tracked object ever moves: there is no contact phase to find the pusher from",
            path=ds.root,
            hint="physics init needs episodes where the pusher moves the object",
        )
    ee_links: set[str] = set()
    for ep in ds.episodes:
        if ep.has("ee_poses"):
            ee_links |= set(ep.table("ee_poses", columns=["link"]).column("link").to_pylist())
    on_links = _named_frames_on_links(ds, chain)
    frame_pick = link is not None and link in on_links and link not in set(chain.link_names)
    if frame_pick:
        on_links = {link: on_links[link]}  # --pusher NAMED_FRAME
        link = on_links[link][0]
    user = spec is not None and (spec.sphere is not None or spec.capsule is not None)
    if user:
        r, length = (spec.sphere, 0.0) if spec.sphere is not None else spec.capsule  # type: ignore[misc]
        half = 0.5 * float(length)
        links = {link} if link else ee_links | set(chain.link_names if chain is not None else [])
        a, b = np.array([0.0, -half, 0.0]), np.array([0.0, half, 0.0])
        # the user's shape centred at the named frames kept from the source (spec 1.1.0), which
        # mark a tool where no link origin is; at the link origins when there are none (or
        # when --pusher names a link)
        cands = {}
        for name, (lk, T) in on_links.items():
            if link is None or (lk == link and frame_pick):
                p = T[:3, 3]
                note = f"centred at named frame {name}"
                cands.setdefault(lk, []).append(Shape(lk, "user", p + a, p + b, float(r), note))
        if not cands:
            cands = {lk: [Shape(lk, "user", a, b, float(r))] for lk in links}
    else:
        cands = {}
        for s in shapes:
            if link is None or s.link == link:
                cands.setdefault(s.link, []).append(s)
        if not cands:
            raise InputError(
                f"link {link!r} has no collision geometry in the URDF"
                if link
                else "the robot URDF has no collision geometry to take the pusher's shape from",
                path=ds.urdf_path,
                hint="add a <collision> to the pusher link, or give the shape: "
                "--pusher LINK --object pusher=sphere:R",
            )
    # distance of each candidate shape from the moving objects' centres
    cache: dict[tuple[str, str], dict[str, tuple[np.ndarray, np.ndarray, str]]] = {}
    score: dict[tuple[str, int], list[float]] = {}
    for tr, idx in moving:
        paths = link_paths(ds, tr.episode, tr.t_ns[idx], chain, sorted(cands))
        cache[(tr.episode, tr.name)] = paths
        for lk, shs in cands.items():
            if lk not in paths:
                continue
            p, R, _ = paths[lk]
            for k, s in enumerate(shs):
                a = np.einsum("nij,j->ni", R, s.a) + p
                b = np.einsum("nij,j->ni", R, s.b) + p
                score.setdefault((lk, k), []).extend(shape_distance(tr.pos[idx], a, b, s.radius))
    if not score:
        raise InputError(
            "no candidate pusher link has a pose (neither ee_poses nor joint_states for it)",
            path=ds.root,
            hint="record joint_states of the URDF's joints or ee_poses of the pusher link",
        )
    (lk, k), _ = min(score.items(), key=lambda kv: float(np.median(kv[1])))
    shape = cands[lk][k]
    how = {h for paths in cache.values() if lk in paths for h in [paths[lk][2]]}
    # the model's point, radius and length for that shape during contact
    axis_l = shape.b - shape.a
    radius = shape.radius
    detail = ""
    if shape.length < 1e-9 or shape.kind == "user":
        offset, length, kind = (
            0.5 * (shape.a + shape.b),
            shape.length,
            "sphere" if shape.length < 1e-9 else "capsule",
        )
    else:
        uz, ts = [], []
        for tr, idx in moving:
            p, R, _ = cache[(tr.episode, tr.name)][lk]
            uz.append(np.abs(np.einsum("nij,j->ni", R, axis_l / shape.length)[:, 2]))
            local = np.einsum("nji,nj->ni", R, tr.pos[idx] - p)  # object centre in the link frame
            ts.append(segment_param(local, shape.a, shape.b))
        t_star = float(np.median(np.concatenate(ts)))
        vertical = float(np.median(np.concatenate(uz))) > np.cos(np.radians(30.0))
        along_y = abs(axis_l[1]) / shape.length > 0.98
        if vertical:
            offset, length, kind = shape.a + t_star * axis_l, 0.0, "sphere"
            detail = "vertical axis: a disc in the push plane, at the objects' height"
        elif along_y:
            offset, length, kind = 0.5 * (shape.a + shape.b), shape.length, "capsule"
        else:
            offset, length, kind = shape.a + t_star * axis_l, 0.0, "sphere"
            detail = "axis not along the link's y axis (the model's capsule axis): a sphere at its closest point"
    # the model point's path and velocity at every object stamp
    paths_all: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    for tr in tracks:
        got = link_paths(ds, tr.episode, tr.t_ns, chain, [lk])
        if lk in got:
            p, R, _ = got[lk]
            c = np.einsum("nij,j->ni", R, offset) + p
            paths_all[(tr.episode, tr.name)] = (c, windowed_velocity(tr.t, c))
    src = "user" if user else "urdf"
    what = f"{shape.kind} collision of {lk}" if not user else "--object pusher"
    note = f"{what}; posed by {' and '.join(sorted(how)) or 'FK'}"
    if shape.note:
        note += f"; {shape.note}"
    if detail:
        note += f"; {detail}"
    return _Pusher(lk, shape, offset, radius, length, kind, src, note, paths_all)


# --------------------------------------------------------------------------- objects


@dataclass
class _Geometry:
    size: np.ndarray | None = None
    sigma: np.ndarray | None = None
    source: str = ""
    detail: str = ""
    mesh: Any = None  # trimesh for mass properties, or None (a box)


def _annotation_size(ds: Any, name: str) -> np.ndarray | None:
    sizes = []
    for ep in ds.episodes:
        for sname, st in ep.entry.get("streams", {}).items():
            if st.get("kind") == "boxes3d":
                tab = ep.table(sname)
                sel = np.asarray(tab.column("object").to_pylist()) == name
                if sel.any():
                    sizes.append(
                        np.stack(
                            [tab.column(c).to_numpy()[sel] for c in ("size_x", "size_y", "size_z")],
                            1,
                        )
                    )
    if not sizes:
        return None
    return np.median(np.concatenate(sizes), axis=0)


def _known_geometry(ds: Any, name: str, spec: ObjectSpec | None) -> _Geometry:
    entry = ds.assets.get(name) or {}
    if "mesh" in entry:
        mesh = ds.mesh(name)
        return _mesh_geometry(mesh, "mesh", f"assets/{name}/mesh")
    ann = _annotation_size(ds, name)
    if ann is not None:
        return _Geometry(ann, None, "annotation", "median of the boxes3d rows")
    if spec is not None and spec.box is not None:
        return _Geometry(np.asarray(spec.box, dtype=float), None, "user", "--object box:")
    if spec is not None and spec.mesh is not None:
        from robogs.format.meshes import load_mesh

        mesh = load_mesh(
            spec.mesh, error=InputError, where=f"--object {name}=mesh:", triangles=False
        )
        return _mesh_geometry(mesh, "user", f"--object mesh:{spec.mesh.name}")
    return _Geometry()


def _mesh_geometry(mesh: Any, source: str, detail: str) -> _Geometry:
    v = np.asarray(mesh.vertices, dtype=float)
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = 0.5 * (lo + hi)
    if np.linalg.norm(centre) > 1e-3:
        detail += f"; box centre {np.round(centre * 1000, 1).tolist()} mm off the object frame"
    return _Geometry(hi - lo, None, source, detail + " (bounding box)", mesh)


def _robust_sigma(x: np.ndarray, n_eff: float) -> float:
    mad = 1.4826 * float(np.median(np.abs(x - np.median(x))))
    return mad / np.sqrt(max(n_eff, 1.0))


def _estimate_extents(
    name: str, tracks: list[ObjectTrack], pusher: _Pusher
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Half extents (x, y) [m], their sigmas and the sample counts, from pushes (see module doc)."""
    vals: list[list[np.ndarray]] = [[], []]
    for tr in tracks:
        if tr.name != name or (tr.episode, tr.name) not in pusher.paths:
            continue
        c, vp = pusher.paths[(tr.episode, tr.name)]
        vb = np.einsum("nji,nj->ni", tr.R, tr.vel)  # object velocity in the object frame
        db = np.einsum("nji,nj->ni", tr.R, c - tr.pos)  # pusher point in the object frame
        rel = np.einsum("nji,nj->ni", tr.R, vp - tr.vel)
        planar = np.linalg.norm(vb[:, :2], axis=1)
        for a in (0, 1):
            ok = (
                tr.moving
                & (np.abs(vb[:, a]) >= np.cos(np.radians(25.0)) * planar)
                & (db[:, a] * vb[:, a] < 0)  # the pusher is behind the object
                & (np.abs(rel[:, a]) < np.maximum(0.01, 0.25 * planar))  # and moving with it
                & (np.abs(db[:, 2]) < 0.1)
            )
            if ok.any():
                vals[a].append(np.abs(db[ok, a]) - pusher.radius)
    half, sig, counts = np.full(2, np.nan), np.full(2, np.nan), [0, 0]
    for a in (0, 1):
        if not vals[a]:
            continue
        x = np.concatenate(vals[a])
        counts[a] = len(x)
        per_window = max(1.0, WINDOW_S / np.median([np.median(np.diff(t.t)) for t in tracks]))
        half[a] = float(np.median(x))
        sig[a] = _robust_sigma(x, len(x) / per_window)
    return half, sig, counts


def _up_axes(tracks: list[ObjectTrack], name: str) -> np.ndarray:
    z = np.concatenate([tr.R[tr.rest, :, 2] for tr in tracks if tr.name == name])
    return z


def _support(
    ds: Any, tracks: list[ObjectTrack], geom: dict[str, _Geometry], specs: dict[str, ObjectSpec]
) -> tuple[Plane, str, str]:
    """The support plane, its source and a detail line."""
    rest_pts = np.concatenate([tr.pos[tr.rest] for tr in tracks]) if tracks else np.zeros((0, 3))
    if len(rest_pts) == 0:
        raise InputError(
            "no tracked object is ever at rest: the support plane cannot be found",
            path=ds.root,
            hint="give it: --object table=plane:Z",
        )
    centre = np.median(rest_pts, axis=0)
    t = specs.get("table")
    if t is not None and t.plane_z is not None:
        n = np.array([0.0, 0.0, 1.0])
        return (
            Plane(n, t.plane_z, 0.0, np.array([centre[0], centre[1], t.plane_z])),
            "user",
            "horizontal, --object table=plane:",
        )
    for name, entry in ds.assets.items():
        if entry.get("kind") == "table" and "mesh" in entry:
            from robogs.format.frames import quat_to_matrix

            mesh = ds.mesh(name)
            pose = np.asarray(entry.get("pose", [0, 0, 0, 1, 0, 0, 0]), dtype=float)
            R = np.asarray(quat_to_matrix(pose[3:] / np.linalg.norm(pose[3:])))
            v = np.asarray(mesh.vertices, dtype=float) @ R.T + pose[:3]
            plane = plane_from_mesh(v, np.asarray(mesh.faces), centre)
            if plane is not None:
                return plane, "mesh", f"top face of assets/{name} under the objects"
    pts, ups = [], []
    for tr in tracks:
        g = geom.get(tr.name)
        if g is None or g.size is None or not tr.rest.any():
            continue
        up = tr.R[tr.rest, :, 2]
        pts.append(tr.pos[tr.rest] - 0.5 * g.size[2] * up)
        ups.append(up)
    if not pts:
        raise InputError(
            "neither the support plane nor any object's height is known, and poses alone cannot "
            "give both",
            path=ds.root,
            hint=f"give one: --object table=plane:Z, --object {tracks[0].name}=box:LxWxH, "
            "or a table mesh asset",
        )
    hint = np.concatenate(ups).mean(axis=0)
    plane = fit_plane(np.concatenate(pts), normal_hint=hint)
    known = sorted(
        {tr.name for tr in tracks if geom.get(tr.name) and geom[tr.name].size is not None}
    )
    return (
        plane,
        "estimated",
        f"robust plane through the resting bottom faces of {', '.join(known)} ({plane.n_points} samples)",
    )


def build_physics(
    ds: Any,
    *,
    specs: dict[str, ObjectSpec] | None = None,
    pusher_link: str | None = None,
    provider: PriorProvider | None = None,
) -> InitResult:
    """Build the physics document of dataset ``ds`` (nothing is written; see module docstring).

    Raises:
        InputError: no object stream, no robot or URDF, an unknown material, or a quantity that
            neither the dataset nor the user gives (each names what supplies it).
    """
    from robogs.format.kinematics import Chain

    specs = dict(specs or {})
    provider = provider or MaterialTable()
    for s in specs.values():  # an unknown material fails before any work
        if s.material is not None:
            provider.material(s.material)
    tracks, urdf, urdf_path = _require_inputs(ds, specs)
    names = sorted({tr.name for tr in tracks})
    unknown = [n for n in specs if n not in names and n not in RESERVED]
    if unknown:
        raise InputError(
            f"--object names {', '.join(unknown)}, which no object_poses stream tracks",
            hint=f"tracked objects: {', '.join(names)}",
        )
    chain = Chain.from_urdf(urdf, floating_as_fixed=True) if urdf is not None else None
    shapes = (
        collision_shapes(urdf, urdf_path, mesh_loader=_mesh_loader(ds, urdf_path))
        if urdf is not None
        else []
    )
    notes: list[str] = []
    entries: list[Entry] = []
    for n in names:
        up = _up_axes(tracks, n)
        if len(up) and float(np.median(up[:, 2])) < np.cos(np.radians(30.0)):
            raise InputError(
                f"object {n!r}: its frame's z axis is not up while it rests "
                f"({np.degrees(np.arccos(np.clip(np.median(up[:, 2]), -1, 1))):.0f} deg from +z)",
                hint="the planar model needs z up: rotate the object's frame on conversion",
            )
    pusher = _choose_pusher(ds, tracks, chain, shapes, specs.get("pusher"), pusher_link)
    geom = {n: _known_geometry(ds, n, specs.get(n)) for n in names}
    plane, plane_src, plane_detail = _support(ds, tracks, geom, specs)
    for n in names:
        g = geom[n]
        if g.size is not None:
            continue
        half, sig, counts = _estimate_extents(n, tracks, pusher)
        missing = [ax for ax, h in zip("xy", half, strict=True) if not np.isfinite(h) or h <= 0]
        if missing:
            raise InputError(
                f"object {n!r} has no mesh, box annotation or size, and no push along its "
                f"{' and '.join(missing)} axis to estimate its extent from",
                hint=f"give it: --object {n}=box:LxWxH (or =mesh:FILE), or push it along that axis",
            )
        rest = [tr for tr in tracks if tr.name == n and tr.rest.any()]
        hz = np.concatenate([tr.pos[tr.rest] @ plane.normal - plane.offset for tr in rest])
        size = np.array([2 * half[0], 2 * half[1], 2 * float(np.median(hz))])
        sz = 2 * np.hypot(_robust_sigma(hz, len(hz)), plane.sigma)
        g.size, g.sigma = size, np.array([2 * sig[0], 2 * sig[1], sz])
        g.source = "estimated"
        g.detail = (
            f"x, y: pusher distance while pushing ({counts[0]}, {counts[1]} samples); "
            f"z: rest height above the support ({len(hz)} samples)"
        )
    doc_objects: dict[str, Any] = {}
    for n in names:
        g = geom[n]
        spec = specs.get(n)
        mat_name = spec.material if spec and spec.material else DEFAULT_MATERIAL
        mat = provider.material(mat_name)
        prior = f"prior({mat.name}{', default' if not (spec and spec.material) else ''})"
        size = [float(s) for s in g.size]  # type: ignore[union-attr]
        com = [0.0, 0.0, 0.0]
        if g.mesh is not None:
            mass, com_v, inertia, mnote = mesh_mass_properties(g.mesh, mat.density_kgm3)
            volume = mass / mat.density_kgm3
            com = [float(c) for c in com_v]
            how = "mesh volume x density" + (f"; {mnote}" if mnote else "")
        else:
            mass, inertia = box_mass_properties(tuple(size), mat.density_kgm3)  # type: ignore[arg-type]
            volume = float(np.prod(size))
            how = "box volume x density"
        key = f"objects.{n}"
        doc_objects[n] = {
            "equation": "rigid",
            "size_m": size,
            "mass_kg": float(mass),
            "com_m": com,
            "inertia_kgm2": np.asarray(inertia).tolist(),
            "friction_static": mat.friction_static,
            "friction_dynamic": mat.friction_dynamic,
            "material": mat.name,
        }
        sigma = None if g.sigma is None else [float(s) for s in g.sigma]
        entries += [
            Entry(f"{key}.equation", "rigid", "default", None, "a tracked object"),
            Entry(f"{key}.size_m", size, g.source, sigma, g.detail),
            Entry(
                f"{key}.mass_kg",
                float(mass),
                prior,
                None,
                f"{how} ({volume * 1e6:.1f} cm^3 x {mat.density_kgm3:g} kg/m^3)",
                [volume * mat.density_bounds[0], volume * mat.density_bounds[1]],
            ),
            Entry(
                f"{key}.com_m",
                com,
                g.source if g.mesh is not None else "default",
                None,
                "mesh centre of mass" if g.mesh is not None else "box centre",
            ),
            Entry(f"{key}.inertia_kgm2", doc_objects[n]["inertia_kgm2"], prior, None, how),
            Entry(
                f"{key}.friction_static",
                mat.friction_static,
                prior,
                None,
                mat.source,
                list(mat.friction_bounds),
            ),
            Entry(
                f"{key}.friction_dynamic",
                mat.friction_dynamic,
                prior,
                None,
                mat.source,
                list(mat.friction_bounds),
            ),
            Entry(
                f"{key}.material",
                mat.name,
                "user" if spec and spec.material else "default",
                None,
                "",
            ),
        ]
    xy = np.median(np.concatenate([tr.pos[tr.rest] for tr in tracks if tr.rest.any()]), axis=0)[:2]
    z0 = float(plane.height_at(xy))
    doc_objects["table"] = {
        "equation": "static",
        "plane_z_m": z0,
        "normal": [float(v) for v in plane.normal],
        "point_m": [float(xy[0]), float(xy[1]), z0],
    }
    psig = plane.sigma if plane_src == "estimated" else None
    entries += [
        Entry("objects.table.equation", "static", "default", None, "the support"),
        Entry(
            "objects.table.plane_z_m",
            z0,
            plane_src,
            psig,
            f"{plane_detail}; height at the objects' median rest (x, y)",
        ),
        Entry(
            "objects.table.normal",
            doc_objects["table"]["normal"],
            plane_src,
            None,
            f"tilt {plane.tilt_deg:.2f} deg",
        ),
        Entry(
            "objects.table.point_m",
            doc_objects["table"]["point_m"],
            plane_src,
            None,
            "where plane_z_m holds",
        ),
    ]
    if plane.tilt_deg > 1.0:
        notes.append(
            f"the support plane is tilted {plane.tilt_deg:.1f} deg; the planar model uses the "
            "horizontal plane z = plane_z_m"
        )
    doc_objects["pusher"] = {
        "equation": "kinematic",
        "link": pusher.link,
        "shape": pusher.kind,
        "radius_m": float(pusher.radius),
        "length_m": float(pusher.length),
    }
    entries += [
        Entry("objects.pusher.equation", "kinematic", "default", None, "moves as measured"),
        Entry(
            "objects.pusher.link",
            pusher.link,
            "estimated" if not pusher_link else "user",
            None,
            "the link that comes closest to the objects while they move",
        ),
        Entry("objects.pusher.shape", pusher.kind, pusher.source, None, pusher.detail),
        Entry("objects.pusher.radius_m", float(pusher.radius), pusher.source, None, pusher.detail),
        Entry(
            "objects.pusher.length_m",
            float(pusher.length),
            pusher.source,
            None,
            "capsule along the link's y axis; 0 = sphere",
        ),
    ]
    if np.linalg.norm(pusher.offset) > 1e-9:
        doc_objects["pusher"]["offset_m"] = [float(v) for v in pusher.offset]
        entries.append(
            Entry(
                "objects.pusher.offset_m",
                doc_objects["pusher"]["offset_m"],
                pusher.source,
                None,
                "the shape's centre in the link frame",
            )
        )
    if len(names) > 1:
        notes.append(f"{len(names)} rigid objects; compare/diagnose/fit model one at a time")
    physics = {"gravity_mps2": [0.0, 0.0, -9.81], "objects": doc_objects}
    entries.append(
        Entry(
            "gravity_mps2", physics["gravity_mps2"], "default", None, "standard gravity, world -z"
        )
    )
    return InitResult(physics, entries, notes)

"""Stream roles after conversion: list them, and re-role a decoded ``generic`` stream.

A converter decodes every topic it has a definition for; a topic it could not place (a custom
pose message, a wrench on an unexpected type) lands in a ``generic`` table
(``episodes/<ep>/streams/<topic>.parquet``, one column per dotted leaf field). :func:`set_role`
turns such a stream into the role the user names:

* ``ee_pose:<link>`` and ``object_pose:<name>``: the table's pose columns (a prefix ``P`` with
  ``P.position.{x,y,z}`` and ``P.orientation.{x,y,z,w}``, or ``P.translation.*`` and
  ``P.rotation.*``) become rows of ``ee_poses`` / ``object_poses`` (``T_world_<entity>``, m,
  quaternion w, x, y, z), merged into the episode's stream of that kind when there is one;
* ``wrench:<frame>``: ``P.force.{x,y,z}`` and ``P.torque.{x,y,z}`` (N, N·m) become a
  ``wrenches`` stream (``wrenches/<topic>`` beside an existing one, one stream per topic);
* ``ignore``: the stream and its table leave the dataset.

Poses are moved into the world (:func:`static_frame`): the frame they are expressed in (the
table's ``header.frame_id``, or ``frame=``) must be the world, the robot's base link, a link
fixed to it, or a named frame (``robot.frames``, FORMAT.md §5.2) hung from one of those; its
``T_world_frame`` is applied. An ``ee_pose`` entity may be a named frame fixed to a link (a
marker, a pusher tip): its ``T_link_frame`` is removed, and the rows are the link's. So
``T_world_link = T_world_frame · T_frame_tracked · T_link_tracked^-1``.

The change is a new version of the dataset, written by :class:`~robogs.format.writer.
DatasetWriter` (atomic, refused when the dataset changed since it was read), and recorded in
``provenance.topics[<topic>]`` (role and reason).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from .dataset import Dataset, Episode
from .errors import FormatError
from .frames import matrix_to_quat_np, quat_to_matrix_np
from .named_frames import frame_in_link

__all__ = [
    "StreamRole",
    "RoleChange",
    "ROLE_KINDS",
    "list_roles",
    "parse_role",
    "set_role",
    "static_frame",
]

#: role prefix -> stream kind it produces (``ignore`` removes the stream)
ROLE_KINDS: dict[str, str | None] = {
    "ee_pose": "ee_poses",
    "object_pose": "object_poses",
    "wrench": "wrenches",
    "ignore": None,
}
_ENTITY = {"ee_poses": "link", "object_poses": "object", "wrenches": "frame"}
_POSE_FORMS = (("position", "orientation"), ("translation", "rotation"))
_NAME = re.compile(r"^[A-Za-z0-9_.:/-]{1,128}$")


@dataclass(frozen=True)
class StreamRole:
    """One stream as ``robogs roles`` lists it.

    Attributes:
        episode, stream: where it is.
        kind: stream kind (``generic`` for a decoded table without a role).
        role: the role (``kind`` plus its entities, e.g. ``object_poses: box``).
        source: topic, column or file it came from (``""`` when not recorded).
        reason: why it got that role, as recorded at conversion (``""`` when not recorded).
    """

    episode: str
    stream: str
    kind: str
    role: str
    source: str
    reason: str


@dataclass(frozen=True)
class RoleChange:
    """What :func:`set_role` changed: one line per edit in ``lines``."""

    episode: str
    stream: str
    role: str
    new_stream: str | None
    rows: int
    dropped: int
    lines: tuple[str, ...]


def _topics(manifest: dict[str, Any]) -> dict[str, Any]:
    prov = manifest.get("provenance")
    topics = prov.get("topics") if isinstance(prov, dict) else None
    return topics if isinstance(topics, dict) else {}


def list_roles(ds: Dataset) -> list[StreamRole]:
    """Every stream of every episode with its role and the reason recorded at conversion."""
    topics = _topics(ds.manifest)
    out = []
    for ep in ds.episodes:
        for name, st in sorted(ep.streams.items()):
            kind = str(st.get("kind", ""))
            source = str(st.get("source", ""))
            recs = [topics.get(s.strip()) for s in source.split(",")] if source else []
            reasons = [str(r["reason"]) for r in recs if isinstance(r, dict) and r.get("reason")]
            roles = sorted({str(r["role"]) for r in recs if isinstance(r, dict) and r.get("role")})
            role = ", ".join(roles) if roles else kind
            out.append(StreamRole(ep.id, name, kind, role, source, "; ".join(reasons)))
    return out


def parse_role(text: str) -> tuple[str | None, str]:
    """``"object_pose:box"`` -> ``("object_poses", "box")``; ``"ignore"`` -> ``(None, "")``.

    Raises:
        FormatError: an unknown role, or a missing or malformed entity name.
    """
    head, _, name = text.partition(":")
    if head not in ROLE_KINDS:
        raise FormatError(
            f"unknown role {text!r}",
            where="ROLE",
            hint="one of ee_pose:<link>, object_pose:<name>, wrench:<frame>, ignore",
        )
    kind = ROLE_KINDS[head]
    if kind is None:
        if name:
            raise FormatError(f"role 'ignore' takes no name (got {text!r})", where="ROLE")
        return None, ""
    if not _NAME.match(name):
        raise FormatError(
            f"role {text!r} needs a name of 1-128 characters [A-Za-z0-9_.:/-]",
            where="ROLE",
            hint=f"e.g. {head}:{'tool0' if head == 'ee_pose' else 'box'}",
        )
    return kind, name


def _find(ds: Dataset, target: str, episode: str | None) -> list[tuple[Episode, str]]:
    """Streams named ``target`` (``streams/<topic>``, the bare name or the source topic)."""
    hits = []
    for ep in ds.episodes:
        if episode is not None and ep.id != episode:
            continue
        for name, st in ep.streams.items():
            if target in (name, f"streams/{target.strip('/')}") or st.get("source") == target:
                hits.append((ep, name))
    return hits


def _columns(names: list[str], kind: str) -> tuple[str, ...] | None:
    """The source columns of ``kind``'s values (x, y, z, qw, qx, qy, qz or fx..tz), or None."""

    def all_in(cols: tuple[str, ...]) -> bool:
        return all(c in names for c in cols)

    found = []
    # "" covers a flat Pose / Wrench message ("position.x"); "pose." a PoseStamped, and so on
    for prefix in sorted({n.rsplit(".", 2)[0] + "." if n.count(".") >= 2 else "" for n in names}):
        if kind == "wrenches":
            cols = tuple(f"{prefix}{g}.{a}" for g in ("force", "torque") for a in "xyz")
            if all_in(cols):
                found.append(cols)
            continue
        for pos, rot in _POSE_FORMS:
            cols = (
                *(f"{prefix}{pos}.{a}" for a in "xyz"),
                *(f"{prefix}{rot}.{a}" for a in "wxyz"),
            )
            if all_in(cols):
                found.append(cols)
    if len(found) > 1:
        raise FormatError(
            f"the table holds {len(found)} candidate sets of columns: "
            + "; ".join(c[0].rsplit(".", 1)[0] for c in found),
            hint="re-convert with --topic TOPIC=ROLE, or split the message",
        )
    return found[0] if found else None


def _values(tab: pa.Table, cols: tuple[str, ...]) -> np.ndarray:
    out = []
    for c in cols:
        col = tab.column(c)
        if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)):
            raise FormatError(f"column {c!r} is {col.type}, not a number", where=c)
        out.append(col.to_numpy(zero_copy_only=False).astype(np.float64))
    return np.stack(out, axis=1)


def _rate_hz(t: np.ndarray) -> float | None:
    d = np.diff(t[:2001])
    d = d[d > 0]
    return float(1e9 / np.median(d)) if d.size else None


def set_role(
    root: str | Path,
    target: str,
    role: str,
    *,
    episode: str | None = None,
    frame: str | None = None,
) -> list[RoleChange]:
    """Give a ``generic`` stream a role and commit the dataset as a new version.

    Args:
        root: dataset folder.
        target: the stream (``streams/<topic>`` or its name) or the source topic.
        role: ``ee_pose:<link>``, ``object_pose:<name>``, ``wrench:<frame>`` or ``ignore``.
        episode: only this episode (default: every episode holding the stream).
        frame: the frame the pose values are expressed in (default: the table's
            ``header.frame_id``; none recorded: the world).

    Returns:
        One change per episode.

    Raises:
        FormatError: unknown stream, not a generic stream, a role whose columns the table lacks,
            an entity already present in the stream it would join; nothing is written then.
        ConcurrentEditError: the dataset changed on disk while this ran (nothing written).
    """
    kind, entity = parse_role(role)
    ds = Dataset.open(root)
    hits = _find(ds, target, episode)
    if not hits:
        generic = sorted(
            {n for ep in ds.episodes for n, s in ep.streams.items() if s.get("kind") == "generic"}
        )
        raise FormatError(
            f"no stream or topic {target!r}" + (f" in episode {episode!r}" if episode else ""),
            path=ds.manifest_path,
            where="episodes/*/streams",
            hint=f"generic streams: {', '.join(generic) or 'none'} (robogs roles DATASET lists all)",
        )
    for ep, name in hits:
        if ep.streams[name].get("kind") != "generic":
            raise FormatError(
                f"stream {name!r} is {ep.streams[name].get('kind')!r}, not a decoded generic table",
                path=ds.manifest_path,
                where=f"episodes/{ep.id}/streams/{name}",
                hint="only generic streams are re-roled; re-convert to change the others",
            )
    if frame is not None and kind in (None, "wrenches"):
        raise FormatError(
            f"--frame applies to pose roles, not {role!r}",
            where="--frame",
            hint="a wrench role names its frame (wrench:<frame>)",
        )
    if kind == "ee_poses" and ds.manifest.get("robot"):
        links = set(ds.urdf(load_meshes=False).link_map)
        named = ds.named_frames
        if entity not in links and entity not in named:
            raise FormatError(
                f"link {entity!r} is not in the robot URDF (nor a named frame)",
                path=ds.urdf_path,
                hint=f"links: {', '.join(sorted(links))}"
                + (f"; named frames: {', '.join(sorted(named))}" if named else ""),
            )
    plans = [_plan(ds, ep, name, kind, entity, role, frame) for ep, name in hits]  # checked first
    with ds.edit() as w:
        for plan in plans:
            plan.apply(w)
        topics = w.manifest.setdefault("provenance", {}).setdefault("topics", {})
        for plan in plans:
            rec = topics.setdefault(plan.source, {}) if plan.source else None
            if isinstance(rec, dict):
                was = rec.get("reason")
                rec["role"] = role
                rec["reason"] = "set by robogs roles set" + (f" (was: {was})" if was else "")
                if plan.frames:
                    rec["frames"] = plan.frames
        w.commit()
    return [p.change for p in plans]


@dataclass
class _Plan:
    """One stream's edit, computed (and so checked) before anything is written."""

    ep: Episode
    name: str
    source: str
    new_stream: str | None
    entry: dict[str, Any] | None
    table: pa.Table | None
    change: RoleChange
    new_object: str | None = None
    frames: str = ""

    def apply(self, w: Any) -> None:
        streams = {e["id"]: e for e in w.manifest.get("episodes", []) if isinstance(e, dict)}[
            self.ep.id
        ]["streams"]
        old = streams.pop(self.name)
        w.remove(old["path"])
        if self.new_stream is not None and self.entry is not None and self.table is not None:
            w.write_table(self.entry["path"], self.table, kind=self.entry["kind"])
            streams[self.new_stream] = self.entry
        if self.new_object is not None and self.new_object not in w.manifest.get("assets", {}):
            w.set_asset(self.new_object, kind="object")


def _plan(
    ds: Dataset,
    ep: Episode,
    name: str,
    kind: str | None,
    entity: str,
    role: str,
    frame: str | None = None,
) -> _Plan:
    st = ep.streams[name]
    source = str(st.get("source", ""))
    where = f"episodes/{ep.id}/streams/{name}"
    if kind is None:
        lines = (f"{ep.id}: removed {name!r} ({st['path']}) - role ignore",)
        return _Plan(
            ep, name, source, None, None, None, RoleChange(ep.id, name, role, None, 0, 0, lines)
        )
    tab = ep.table(name)
    try:
        cols = _columns(tab.column_names, kind)
    except FormatError as exc:
        raise FormatError(
            exc.message, path=ep.table_path(name), where=where, hint=exc.hint
        ) from None
    if cols is None:
        want = (
            "<P>.force.{x,y,z} and <P>.torque.{x,y,z}"
            if kind == "wrenches"
            else "<P>.position.{x,y,z} and <P>.orientation.{x,y,z,w} (or translation/rotation)"
        )
        raise FormatError(
            f"stream {name!r} has no columns for role {role!r}",
            path=ep.table_path(name),
            where=where,
            hint=f"needs {want}; it has {', '.join(tab.column_names[:12])}"
            + (" ..." if tab.num_columns > 12 else ""),
        )
    t = tab.column("t_ns").to_numpy(zero_copy_only=False).astype(np.int64)
    try:
        v = _values(tab, cols)
    except FormatError as exc:
        raise FormatError(exc.message, path=ep.table_path(name), where=exc.where) from None
    ok = np.all(np.isfinite(v), axis=1)
    frame_lines: list[str] = []
    if kind != "wrenches":
        qn = np.linalg.norm(v[:, 3:], axis=1)
        ok &= qn > 1e-9
        v[ok, 3:] /= qn[ok, None]
        parent = frame if frame is not None else _recorded_frame(tab, ep, name, where)
        T_wp, how = static_frame(ds, parent, where=where)
        frame_lines.append(
            f"{ep.id}: values in frame {parent}: {how}" if parent else f"{ep.id}: {how}"
        )
        T_lt = np.eye(4)
        if kind == "ee_poses" and ds.manifest.get("robot") and entity in ds.named_frames:
            links = set(ds.urdf(load_meshes=False).link_map)
            if entity not in links:
                link, T_lt = frame_in_link(ds.named_frames, entity, links)
                frame_lines.append(
                    f"{ep.id}: {entity!r} is a named frame on link {link!r}: T_{link}_{entity} "
                    f"removed, the rows are the link's poses"
                )
                entity = link
        v[ok] = _compose(T_wp, v[ok], np.linalg.inv(T_lt))
    order = np.argsort(t[ok], kind="stable")
    t, v = t[ok][order], v[ok][order]
    if t.size == 0:
        raise FormatError(f"stream {name!r} has no finite {role} rows", path=ep.table_path(name))
    value_names = (
        ("fx", "fy", "fz", "tx", "ty", "tz")
        if kind == "wrenches"
        else ("x", "y", "z", "qw", "qx", "qy", "qz")
    )
    ent_col = _ENTITY[kind]
    new = pa.table(
        {
            "t_ns": pa.array(t, pa.int64()),
            ent_col: pa.array([entity] * t.size, pa.string()),
            **{c: pa.array(v[:, i], pa.float64()) for i, c in enumerate(value_names)},
        }
    )
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", name.rsplit("/", 1)[-1]).strip("_") or "stream"
    ep_dir = str(st["path"]).rsplit("/", 2)[0]
    rate = _rate_hz(t)
    existing = next(
        (
            n
            for n, s in ep.streams.items()
            if s.get("kind") == kind and isinstance(s.get("path"), str)
        ),
        None,
    )
    merge = False
    if existing is not None and kind != "wrenches":
        old = ep.table(existing)
        if entity in set(old.column(ent_col).to_pylist()):
            raise FormatError(
                f"{kind} stream {existing!r} already holds {ent_col} {entity!r}",
                path=ep.table_path(existing),
                where=where,
                hint=f"choose another name, e.g. {role.split(':')[0]}:{entity}_{stem}",
            )
        theirs = ep.streams[existing].get("nominal_rate_hz")
        merge = rate is None or not theirs or abs(rate / float(theirs) - 1.0) < 0.1
    if merge and existing is not None:
        old = ep.table(existing).select(new.column_names).cast(new.schema)
        both = pa.concat_tables([old, new])
        idx = np.argsort(both.column("t_ns").to_numpy(), kind="stable")
        table = both.take(pa.array(idx))
        new_stream = existing
        entry = dict(ep.streams[existing])
        entry["source"] = ", ".join(s for s in (entry.get("source"), source) if s)
    else:
        table = new
        new_stream = kind if existing is None else f"{kind}/{stem}"
        path = f"{ep_dir}/{kind}.parquet" if existing is None else f"{ep_dir}/{kind}_{stem}.parquet"
        if new_stream in ep.streams or ds.files.get(path) is not None:
            raise FormatError(f"stream {new_stream!r} or {path} already exists", where=where)
        entry = {
            "kind": kind,
            "path": path,
            "stamp_source": st.get("stamp_source", "log_time"),
            "offset_ns": int(st.get("offset_ns", 0)),
            "nominal_rate_hz": rate,
            "source": source or name,
        }
    dropped = int((~ok).sum())
    lines = [
        f"{ep.id}: {name!r} -> {new_stream!r} as {ent_col} {entity!r}: {t.size} rows from "
        f"{cols[0].rsplit('.', 1)[0]}.* / {cols[-1].rsplit('.', 1)[0]}.*"
        + (f", merged into {entry['path']}" if merge else f", written to {entry['path']}"),
        f"{ep.id}: removed {st['path']}",
    ]
    if dropped:
        lines.append(f"{ep.id}: {dropped} rows with non-finite values or a zero quaternion dropped")
    lines.extend(frame_lines)
    new_object = entity if kind == "object_poses" and entity not in ds.assets else None
    if new_object is not None:
        lines.append(f"declared asset {entity!r} (kind object, no mesh yet)")
    change = RoleChange(ep.id, name, role, new_stream, int(t.size), dropped, tuple(lines))
    frames = "; ".join(x.split(": ", 1)[1] for x in frame_lines)
    return _Plan(ep, name, source, new_stream, entry, table, change, new_object, frames)


def _recorded_frame(tab: pa.Table, ep: Episode, name: str, where: str) -> str | None:
    """The one ``header.frame_id`` of a decoded pose table (None when it records none)."""
    if "header.frame_id" not in tab.column_names:
        return None
    frames = sorted({str(f).lstrip("/") for f in tab.column("header.frame_id").to_pylist() if f})
    if len(frames) > 1:
        raise FormatError(
            f"stream {name!r} records poses in {len(frames)} frames: {', '.join(frames[:5])}",
            path=ep.table_path(name),
            where=where,
            hint="give the frame with --frame, or split the topic",
        )
    return frames[0] if frames else None


def _fixed_to(urdf: Any, link: str, base: str) -> np.ndarray | None:
    """``T_base_link`` [4, 4] when only fixed joints lead from ``base`` to ``link``, else None."""
    by_child = {j.child: j for j in urdf.robot.joints}
    T = np.eye(4)
    cur = link
    while cur != base:
        j = by_child.get(cur)
        if j is None or j.type != "fixed":
            return None
        T = (np.eye(4) if j.origin is None else np.asarray(j.origin, np.float64)) @ T
        cur = j.parent
    return T


def static_frame(ds: Dataset, frame: str | None, *, where: str = "") -> tuple[np.ndarray, str]:
    """``T_world_frame`` [4, 4] (m) of a frame fixed in the world, and how it was found.

    The world is the robot's base link (FORMAT.md §3). A frame is known when it is the world
    (``conventions.world_frame.name`` or ``world``; None: none recorded, taken as the world),
    the base link, a URDF link joined to it by fixed joints only, or a named frame
    (``robot.frames``) hung from one of those.

    Raises:
        FormatError: an unknown frame, or one a joint moves (a named frame on a moving link).
    """
    world = str(((ds.manifest.get("conventions") or {}).get("world_frame") or {}).get("name", ""))
    if frame is None:
        return np.eye(
            4
        ), "no frame recorded: values taken as in the world (--frame FRAME says otherwise)"
    if frame in ("world", world):
        return np.eye(4), "the world"
    robot = ds.manifest.get("robot") or {}
    hint = "give --frame: the world, the robot's base link or a named frame fixed to it"
    if not robot:
        raise FormatError(
            f"unknown frame {frame!r} (the dataset has no robot)", where=where, hint=hint
        )
    urdf = ds.urdf(load_meshes=False)
    links = set(urdf.link_map)
    base = str(robot.get("base_link") or urdf.base_link)
    named = ds.named_frames
    if frame in links:
        link, T_lf, via = frame, np.eye(4), f"link {frame!r}"
    elif frame in named:
        link, T_lf = frame_in_link(named, frame, links)
        src = named[frame].source
        via = f"named frame {frame!r} on link {link!r}" + (f" (from {src})" if src else "")
    else:
        known = sorted(named) + [base]
        raise FormatError(
            f"unknown frame {frame!r}: not the world, a robot link or a named frame",
            path=ds.manifest_path,
            where=where,
            hint=f"{hint} (named frames and base: {', '.join(known)}); or add it to robot.frames",
        )
    T_bl = _fixed_to(urdf, link, base)
    if T_bl is None:
        raise FormatError(
            f"frame {frame!r} is not fixed in the world: a joint moves link {link!r}",
            path=ds.manifest_path,
            where=where,
            hint="poses must be given in a frame fixed to the robot base; " + hint,
        )
    T = T_bl @ T_lf
    if np.allclose(T, np.eye(4), atol=1e-12):
        return T, f"{via}, the world"
    deg = np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1, 1)))
    return T, (
        f"{via}: T_world_{frame} applied ({np.linalg.norm(T[:3, 3]) * 1e3:.4g} mm, {deg:.4g} deg)"
    )


def _compose(T_left: np.ndarray, v: np.ndarray, T_right: np.ndarray) -> np.ndarray:
    """[N, 7] poses ``x y z qw qx qy qz`` as ``T_left · T(v) · T_right`` (identity: unchanged)."""
    if np.array_equal(T_left, np.eye(4)) and np.array_equal(T_right, np.eye(4)):
        return v
    T = np.tile(np.eye(4), (v.shape[0], 1, 1))
    T[:, :3, :3] = quat_to_matrix_np(v[:, 3:7])
    T[:, :3, 3] = v[:, :3]
    T = T_left[None] @ T @ T_right[None]
    q = matrix_to_quat_np(T[:, :3, :3])
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return np.concatenate([T[:, :3, 3], q], axis=1)

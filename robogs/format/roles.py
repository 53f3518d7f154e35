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

__all__ = ["StreamRole", "RoleChange", "ROLE_KINDS", "list_roles", "parse_role", "set_role"]

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
    root: str | Path, target: str, role: str, *, episode: str | None = None
) -> list[RoleChange]:
    """Give a ``generic`` stream a role and commit the dataset as a new version.

    Args:
        root: dataset folder.
        target: the stream (``streams/<topic>`` or its name) or the source topic.
        role: ``ee_pose:<link>``, ``object_pose:<name>``, ``wrench:<frame>`` or ``ignore``.
        episode: only this episode (default: every episode holding the stream).

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
    if kind == "ee_poses" and ds.manifest.get("robot"):
        links = set(ds.urdf(load_meshes=False).link_map)
        if entity not in links:
            raise FormatError(
                f"link {entity!r} is not in the robot URDF",
                path=ds.urdf_path,
                hint=f"links: {', '.join(sorted(links))}",
            )
    plans = [_plan(ds, ep, name, kind, entity, role) for ep, name in hits]  # all checked first
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


def _plan(ds: Dataset, ep: Episode, name: str, kind: str | None, entity: str, role: str) -> _Plan:
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
    if kind != "wrenches":
        qn = np.linalg.norm(v[:, 3:], axis=1)
        ok &= qn > 1e-9
        v[ok, 3:] /= qn[ok, None]
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
    if "header.frame_id" in tab.column_names:
        frames = sorted({str(f) for f in tab.column("header.frame_id").to_pylist() if f})
        if frames:
            lines.append(
                f"{ep.id}: values taken as recorded in frame {', '.join(frames[:3])}: they must "
                "already be in the dataset's world frame (no /tf is applied here)"
            )
    new_object = entity if kind == "object_poses" and entity not in ds.assets else None
    if new_object is not None:
        lines.append(f"declared asset {entity!r} (kind object, no mesh yet)")
    change = RoleChange(ep.id, name, role, new_stream, int(t.size), dropped, tuple(lines))
    return _Plan(ep, name, source, new_stream, entry, table, change, new_object)

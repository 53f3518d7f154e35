"""Writing cleaned log segments into the dataset: one episode per segment.

Each segment becomes an episode with a ``joint_states`` table (and an ``ee_poses`` table when
the log records end-effector poses); ``physics.json`` starts from the URDF's joint dynamics,
and the provenance lists the files, the mapping of each, every drop and every note.
:func:`convert` is the registry entry run by :func:`robogs.convert.ingest.convert.convert_path`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from robogs.format.errors import InputError, RobogsError
from robogs.format.urdf import load_urdf

from .cleaning import FileReport, LogSegment, clean_file
from .column_map import ColumnMap
from .mapping import file_mapping
from .pose import resolve_frame
from .reading import RawLog, log_files, read_log_file
from .user_map import read_mapping

__all__ = ["attach_robot_lenient", "convert", "write_tabular"]

_EXAMPLES = 5


def _episode_id(stem: str, k: int, n: int, used: set[str]) -> str:
    """A unique episode id: ``stem`` (sanitised), ``<stem>_sKK`` when the file has ``n > 1``."""
    base = re.sub(r"[^A-Za-z0-9_.-]", "_", stem)[:56] or "log"
    eid = base if n == 1 else f"{base}_s{k:02d}"
    while eid in used:
        eid = eid + "x"
    used.add(eid)
    return eid


def _joint_table(seg: LogSegment, joint_names: list[str]) -> pa.Table:
    """The ``joint_states`` table of a segment (t_ns; rad or m, rad/s or m/s, N m or N)."""
    cols: dict[str, Any] = {"t_ns": pa.array(seg.t_ns, type=pa.int64())}
    for k, j in enumerate(joint_names):
        cols[f"position.{j}"] = pa.array(seg.q[:, k], type=pa.float64())
    if seg.qd is not None:
        for k, j in enumerate(joint_names):
            cols[f"velocity.{j}"] = pa.array(seg.qd[:, k], type=pa.float64())
    if seg.tau is not None:
        for k, j in enumerate(seg.effort_joints):
            cols[f"effort.{j}"] = pa.array(seg.tau[:, k], type=pa.float64())
    return pa.table(cols)


def _ee_table(seg: LogSegment, link: str) -> pa.Table:
    """The ``ee_poses`` table of a segment: ``T_world_link`` as x y z (m), qw qx qy qz."""
    assert seg.ee is not None and seg.ee_t_ns is not None
    cols: dict[str, Any] = {
        "t_ns": pa.array(seg.ee_t_ns, type=pa.int64()),
        "link": pa.array([link] * len(seg.ee_t_ns), type=pa.string()),
    }
    for k, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz")):
        cols[c] = pa.array(seg.ee[:, k], type=pa.float64())
    return pa.table(cols)


def _physics_from_urdf(urdf: Any) -> dict[str, Any]:
    """A first ``physics.json``: the URDF's joint ``<dynamics damping friction>``, gravity -z."""
    joints: dict[str, dict[str, float]] = {}
    for j in urdf.robot.joints:
        d = j.dynamics
        if j.type == "fixed" or d is None:
            continue
        entry = {}
        for key in ("damping", "friction"):
            v = getattr(d, key, None)
            if v is not None and math.isfinite(float(v)) and float(v) >= 0:
                entry[key] = float(v)
        if entry:
            joints[j.name] = entry
    doc: dict[str, Any] = {"revision": 0, "gravity_mps2": [0.0, 0.0, -9.81], "objects": {}}
    if joints:
        doc["joints"] = joints
    return doc


def _strip_meshes(urdf_path: Path) -> tuple[bytes, int]:
    """URDF bytes with every mesh geometry (visual/collision) removed, and how many."""
    from lxml import etree

    from robogs.format.urdf import parse_urdf_xml

    tree = parse_urdf_xml(urdf_path, verbatim=True, keep_blank_text=True).getroottree()
    n = 0
    for tag in ("visual", "collision"):
        for el in list(tree.getroot().iter(tag)):
            if el.find("geometry/mesh") is not None:
                el.getparent().remove(el)
                n += 1
    return etree.tostring(tree, xml_declaration=True, encoding="utf-8"), n


def attach_robot_lenient(
    writer: Any, urdf_path: Path, package_roots: dict[str, Path] | None, prov: Any
) -> None:
    """Copy the URDF with its meshes; without resolvable meshes copy it mesh-free and say so."""
    from robogs.format.kinematics import Chain

    from ..context import ConvertOptions, IngestContext
    from ..progress import ProgressReporter
    from ..robot import attach_robot

    ctx = IngestContext(writer, ConvertOptions(), prov, ProgressReporter(False))
    try:
        attach_robot(ctx, urdf_path, package_roots=package_roots)
        return
    except RobogsError as exc:
        writer.remove("robot")
        reason = exc.message
    data, n = _strip_meshes(urdf_path)
    writer.write_bytes("robot/robot.urdf", data)
    urdf = load_urdf(urdf_path, load_meshes=False)
    root = Chain.from_urdf(urdf).link_names[0]
    writer.set_robot("robot/robot.urdf", base_link=root)
    prov.note(
        f"robot meshes not copied ({reason}); {n} mesh geometries removed from the URDF "
        "(loaded with load_meshes=False)"
    )
    prov.extra["robot"] = {"urdf": urdf_path.name, "meshes": 0, "root_link": root}


def _report_file(f: Path, raw: RawLog, cmap: ColumnMap, rep: FileReport, prov: Any) -> None:
    """Record one file's counts, drops and notes in the provenance."""
    rec = prov.topic(f.name, f.suffix.lstrip(".").lower(), "joint_states")
    rec.messages += rep.rows
    rec.written += rep.written
    rec.stamp_source = "log_time"
    for reason, lns in rep.dropped.items():
        prov.drop(f.name, reason, len(lns))
        first = ", ".join(str(x) for x in lns[:_EXAMPLES])
        prov.note(
            f"{f.name}: {len(lns)} row(s) dropped: {reason} (line {first}{', ...' if len(lns) > _EXAMPLES else ''})"
        )
    for note in rep.notes:
        prov.note(f"{f.name}: {note}")
    if cmap.layout == "rtde" and any(c.startswith("actual_current_") for c in raw.columns):
        prov.note(
            f"{f.name}: efforts from target_moment_* (N m); actual_current_* (A) ignored "
            "(map them with torque constants to use them)"
        )
    if all(jc.effort is None for jc in cmap.joints.values()):
        prov.note(f"{f.name}: no effort columns")
    if cmap.ee_pose is not None:
        ee_rec = prov.topic(f"{f.name}#ee_pose", f.suffix.lstrip(".").lower(), "ee_poses")
        ee_rec.messages += rep.ee_rows
        ee_rec.written += rep.ee_written
        ee_rec.stamp_source = "log_time"
        if rep.ee_dropped:
            reason = "empty, NaN or unparseable pose value"
            prov.drop(f"{f.name}#ee_pose", reason, len(rep.ee_dropped))
            first = ", ".join(str(x) for x in rep.ee_dropped[:_EXAMPLES])
            prov.note(
                f"{f.name}: {len(rep.ee_dropped)} end-effector pose(s) dropped: {reason} "
                f"(line {first}{', ...' if len(rep.ee_dropped) > _EXAMPLES else ''}; "
                "the joint rows are kept)"
            )
    if cmap.hold:
        prov.note(
            f"{f.name}: joints not in the log, held at a constant position (rad or m): "
            + ", ".join(f"{j} = {v:g}" for j, v in cmap.hold.items())
        )


def _write_segments(
    writer: Any,
    f: Path,
    segs: list[LogSegment],
    cmap: ColumnMap,
    joint_names: list[str],
    used: set[str],
    prov: Any,
) -> list[str]:
    """Write each segment of one file as an episode; returns the episode ids."""
    from robogs.format.differentiate import describe_differentiator

    hold = cmap.hold
    named: dict[str | None, int] = {}
    for seg in segs:
        named[seg.name] = named.get(seg.name, 0) + 1
    seen: dict[str | None, int] = {}
    written: list[str] = []
    for seg in segs:
        if seg.name is None:
            eid = _episode_id(f.stem, seg.index, len(segs), used)
            segment = f"{f.name}#{seg.index}"
        else:
            k = seen[seg.name] = seen.get(seg.name, -1) + 1
            eid = _episode_id(seg.name, k, named[seg.name], used)
            segment = seg.name
        rel = f"episodes/{eid}/joint_states.parquet"
        writer.write_table(rel, _joint_table(seg, joint_names), kind="joint_states")
        ee_streams: dict[str, Any] = {}
        if cmap.ee_pose is not None and seg.ee is not None and len(seg.ee):
            ee_rel = f"episodes/{eid}/ee_poses.parquet"
            writer.write_table(ee_rel, _ee_table(seg, cmap.ee_pose.link), kind="ee_poses")
            ee_steps = np.diff(seg.ee_t_ns)
            ee_streams["ee_poses"] = {
                "kind": "ee_poses",
                "path": ee_rel,
                "stamp_source": "log_time",
                "offset_ns": int(cmap.epoch_ns),
                "source": f.name,
                "nominal_rate_hz": float(1e9 / np.median(ee_steps)) if len(ee_steps) else None,
            }
        stream: dict[str, Any] = {
            "kind": "joint_states",
            "path": rel,
            "stamp_source": "log_time",
            "offset_ns": int(cmap.epoch_ns),
            "source": f.name,
        }
        steps = np.diff(seg.t_ns)
        stream["nominal_rate_hz"] = float(1e9 / np.median(steps)) if len(steps) else None
        derived = [f"position.{j}" for j in hold]
        if seg.derived_velocity:
            derived += [f"velocity.{j}" for j in joint_names]
            prov.note(f"velocities derived from positions: {describe_differentiator(1)}")
        elif hold:
            derived += [f"velocity.{j}" for j in hold]
        if derived:
            stream["derived"] = derived
        writer.add_episode(
            eid,
            start_ns=int(seg.t_ns[0]),
            end_ns=int(seg.t_ns[-1]),
            streams={"joint_states": stream, **ee_streams},
            segment=segment,
        )
        written.append(eid)
    return written


def write_tabular(
    writer: Any,
    log_path: Path,
    *,
    urdf_path: Path,
    mapping: Path | None,
    prov: Any,
    gap_s: float | None = None,
) -> list[str]:
    """Read the logs and write episodes and ``physics.json`` through ``writer``.

    Args:
        writer: the dataset writer.
        log_path: a CSV/Parquet file or a folder of them.
        urdf_path: the robot (joint names, order and limits; dynamics for ``physics.json``).
        mapping: YAML column map (None: the automatic layouts).
        prov: the provenance record.
        gap_s: segment split threshold, s (None: the map's, else automatic).

    Returns:
        The episode ids written.

    Raises:
        InputError: unusable logs or mapping (file, row and column named).
    """
    from robogs.format.kinematics import Chain

    urdf = load_urdf(urdf_path, load_meshes=False)
    chain = Chain.from_urdf(urdf)
    joint_names = list(chain.joint_names)
    lower, upper = np.asarray(chain.joint_lower), np.asarray(chain.joint_upper)
    fixed_map = read_mapping(mapping, joint_names) if mapping is not None else None
    hold = fixed_map.hold if fixed_map is not None else {}
    for j, v in hold.items():
        k = joint_names.index(j)
        if not lower[k] - 1e-12 <= v <= upper[k] + 1e-12:
            raise InputError(
                f"held position {v:g} of joint {j!r} is outside its URDF limits "
                f"[{lower[k]:g}, {upper[k]:g}]",
                path=mapping,
                where=f"hold/{j}",
                hint="positions are in rad (revolute) or m (prismatic)",
            )
    logged = [j for j in joint_names if j not in hold]
    if not logged:
        raise InputError("every joint is held; the log maps none", path=mapping, where="hold")
    if fixed_map is not None and fixed_map.ee_pose is not None:
        resolve_frame(fixed_map.ee_pose, chain, mapping)
    files = log_files(Path(log_path))
    used: set[str] = set()
    written: list[str] = []
    maps: dict[str, Any] = {}
    ee_link: str | None = None
    for f in files:
        raw = read_log_file(f)
        cmap = file_mapping(f, raw, fixed_map, logged, chain, prov)
        maps[f.name] = cmap.to_dict()
        segs, rep = clean_file(
            f, raw, cmap, joint_names, lower, upper, gap_s if gap_s is not None else cmap.gap_s
        )
        _report_file(f, raw, cmap, rep, prov)
        written += _write_segments(writer, f, segs, cmap, joint_names, used, prov)
        if cmap.ee_pose is not None and ee_link is None:
            ee_link = cmap.ee_pose.link
    if not written:
        raise InputError("nothing was converted (every row was dropped)", path=log_path)
    prov.extra["mapping"] = maps
    prov.extra["files"] = [f.name for f in files]
    if ee_link is not None:  # the link the kinematic model explains (set_robot keeps it)
        writer.manifest["robot"] = {**(writer.manifest.get("robot") or {}), "ee_link": ee_link}
    writer.set_physics(_physics_from_urdf(urdf), note="joint dynamics from the URDF")
    return written


def convert(src: Path, ctx: Any) -> None:
    """Registry entry, run by ``convert_path``: write the episodes through the driver's writer.

    The driver attaches the robot; with ``meshes_optional`` it is attached here, mesh-free when
    its meshes do not resolve (the driver keeps a robot a converter attached).

    Raises:
        InputError: no URDF (``--urdf``), unusable logs or mapping.
    """
    from .options import from_convert_options

    opts = from_convert_options(ctx.options)
    if ctx.options.urdf is None:
        raise InputError("a joint log needs the robot: pass --urdf URDF", where="--urdf")
    urdf = Path(ctx.options.urdf)
    write_tabular(
        ctx.writer,
        Path(src),
        urdf_path=urdf,
        mapping=opts.mapping,
        prov=ctx.provenance,
        gap_s=opts.gap_s,
    )
    if opts.meshes_optional:
        roots = {k: Path(v) for k, v in (ctx.options.package_roots or {}).items()}
        attach_robot_lenient(ctx.writer, urdf, roots or None, ctx.provenance)

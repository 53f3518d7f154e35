"""What the manifest says about a dataset's layout, as the checks need it (no file is read).

Which stream kinds are periodic, which column names the entity of an interleaved table, which
stream fields name files (and the table kind of each), and every path the manifest names.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = [
    "ENTITY_COLUMNS",
    "PERIODIC_KINDS",
    "STREAM_FILE_FIELDS",
    "PathRef",
    "path_refs",
    "table_kind",
]

#: stream kinds sampled at a (nominal) rate; camera means its frame table
PERIODIC_KINDS: tuple[str, ...] = (
    "joint_states",
    "actions",
    "ee_poses",
    "object_poses",
    "wrenches",
    "camera",
)

#: column naming the entity of each row, for tables that interleave several series
ENTITY_COLUMNS: dict[str, str] = {
    "ee_poses": "link",
    "object_poses": "object",
    "wrenches": "frame",
    "boxes2d": "camera",
    "boxes3d": "object",
}

#: stream fields that name a file, and the table kind of each (None: not a table)
STREAM_FILE_FIELDS: dict[str, str | None] = {
    "path": "",
    "frames": "camera_frames",
    "labels": "camera_labels",
    "extrinsics": "camera_extrinsics",
    "video": None,
}


def table_kind(stream: dict[str, Any], field: str) -> str | None:
    """Table kind (``robogs.format.tables``) of a stream's file field, None for non-tables."""
    kind = STREAM_FILE_FIELDS.get(field)
    if kind == "":
        return str(stream.get("kind", ""))
    return kind


@dataclass(frozen=True)
class PathRef:
    """A path named by the manifest (or a URDF): where it is named and what it is."""

    rel: str
    where: str
    role: str


def path_refs(m: dict[str, Any]) -> list[PathRef]:
    """Every path manifest ``m`` names (files, streams, robot, assets, cameras, physics); values
    of the wrong type are skipped (the schema checks report them)."""
    files = m.get("files")
    refs: list[PathRef] = [
        PathRef(rel, f"/files/{rel}", "file") for rel in (files if isinstance(files, dict) else {})
    ]

    def add(value: Any, where: str, role: str) -> None:
        if isinstance(value, str):
            refs.append(PathRef(value, where, role))

    robot = m.get("robot")
    if isinstance(robot, dict):
        add(robot.get("urdf"), "/robot/urdf", "urdf")
        add(robot.get("mdh"), "/robot/mdh", "mdh")
        if isinstance(robot.get("splats"), dict):
            add(robot["splats"].get("path"), "/robot/splats/path", "splats")
    assets = m.get("assets")
    if isinstance(assets, dict):
        for name, a in assets.items():
            if isinstance(a, dict):
                add(a.get("mesh"), f"/assets/{name}/mesh", "mesh")
                if isinstance(a.get("splats"), dict):
                    add(a["splats"].get("path"), f"/assets/{name}/splats/path", "splats")
    add(m.get("physics"), "/physics", "physics")
    cams = m.get("cameras")
    if isinstance(cams, dict):
        for name, rel in cams.items():
            add(rel, f"/cameras/{name}", "camera")
    eps = m.get("episodes")
    for i, e in enumerate(eps if isinstance(eps, list) else []):
        streams = e.get("streams") if isinstance(e, dict) else None
        if not isinstance(streams, dict):
            continue
        for sname, st in streams.items():
            if isinstance(st, dict):
                for fld in STREAM_FILE_FIELDS:
                    add(st.get(fld), f"/episodes/{i}/streams/{sname}/{fld}", fld)
    return refs

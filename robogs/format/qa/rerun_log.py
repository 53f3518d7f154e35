"""Log a robogs dataset into a Rerun recording (rerun-sdk 0.41).

The recording is built from *layers*, each a function ``fn(ctx: RerunContext) -> None`` that
logs one kind of content. The built-in layers, in order:

========== ===================================================================================
robot      link meshes (``Mesh3D``, static) and ``T_world_link`` per joint-state sample
           (``Transform3D``, downsampled to ``max_hz``) from forward kinematics
objects    asset meshes and ``T_world_object`` from ``object_poses``
splats     robot/asset Gaussians as ``Points3D`` in their bound link/object frame, so they
           move with it
cameras    ``Pinhole`` + ``T_world_cam``, video frames, panoptic labels
           (``SegmentationImage`` + ``AnnotationContext`` from ``segments``), ``Boxes2D``
boxes3d    ``Boxes3D`` per stamp
ee_poses   end-effector frames (``Transform3D`` + axes)
plots      joint positions, velocities, efforts and wrenches (``Scalars``)
findings   validator findings at their stamps (``TextLog`` with level)
========== ===================================================================================

More layers (e.g. ``rerender``, labels re-rendered from the splats) plug in with
:func:`register_layer` or through the entry-point group ``robogs.layers``; they are kept in a
:class:`~robogs.format.plugins.Registry` (:func:`layer_entries` lists them with their status).

Entity tree: ``world/robot/<link>``, ``world/objects/<name>``, ``world/cameras/<cam>`` with
``.../image`` (pinhole) holding ``rgb``, ``segmentation`` and ``boxes``, ``world/boxes3d``,
``world/ee/<link>``, ``plots/joints/{position,velocity,effort}/<joint>``,
``plots/wrench/<frame>/<fx..tz>``, ``logs/findings``. Every sample sits on the timeline
``time`` at the dataset's ``t_ns`` exactly: a timestamp timeline when the clock is an epoch
clock, a duration timeline otherwise (see :func:`time_axis`).

API reference: https://ref.rerun.io/docs/python/0.41.0/common/ (archetypes, ``send_columns``,
``rerun.blueprint``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import rerun as rr
import rerun.blueprint as rrb

from ..dataset import Dataset, Episode
from ..errors import FormatError, RobogsError
from ..plugins import ENTRY_POINT_GROUPS, Entry, Registry

if TYPE_CHECKING:
    import trimesh
    import yourdfpy

    from ..kinematics import Chain

__all__ = [
    "DEFAULT_LAYERS",
    "RerunContext",
    "TimeAxis",
    "available_layers",
    "layer_entries",
    "REGISTRY",
    "default_blueprint",
    "downsample_indices",
    "entity",
    "label_colors",
    "log_dataset",
    "log_scalar_series",
    "register_layer",
    "rest_joint_positions",
    "robot_link_meshes",
    "time_axis",
    "write_rrd",
]

_EPOCH_CLOCKS = {"unix_epoch", "ros_time", "utc", "tai", "gps"}
_EPOCH_THRESHOLD_NS = 10**17  # ~1973: a stamp this large is taken for an epoch clock


# ----------------------------------------------------------------------------- time


@dataclass(frozen=True)
class TimeAxis:
    """The ``time`` timeline: ``timestamp`` (epoch clock) or ``duration`` (any other clock)."""

    kind: Literal["timestamp", "duration"]
    name: str = "time"

    def column(self, t_ns: Iterable[int] | np.ndarray) -> rr.TimeColumn:
        """A time column for ``send_columns``; int64 ns kept exactly."""
        t = np.asarray(t_ns, dtype=np.int64)
        if self.kind == "timestamp":
            return rr.TimeColumn(self.name, timestamp=t.astype("datetime64[ns]"))
        return rr.TimeColumn(self.name, duration=t.astype("timedelta64[ns]"))

    def set(self, rec: rr.RecordingStream, t_ns: int) -> None:
        """Set the recording's current time to ``t_ns``."""
        if self.kind == "timestamp":
            rec.set_time(self.name, timestamp=np.datetime64(int(t_ns), "ns"))
        else:
            rec.set_time(self.name, duration=np.timedelta64(int(t_ns), "ns"))


def time_axis(ds: Dataset) -> TimeAxis:
    """The timeline kind for a dataset: its declared clock, or the size of its stamps."""
    clock = str(ds.manifest.get("conventions", {}).get("clock", "")).lower()
    if clock:
        return TimeAxis("timestamp" if clock in _EPOCH_CLOCKS else "duration")
    starts = [e.start_ns for e in ds.episodes]
    return TimeAxis("timestamp" if starts and min(starts) > _EPOCH_THRESHOLD_NS else "duration")


def downsample_indices(t_ns: np.ndarray, max_hz: float) -> np.ndarray:
    """Indices of samples kept at no more than ``max_hz`` (first of each period, plus the last).

    Args:
        t_ns: [N] int64 sorted stamps.
        max_hz: target rate; ``<= 0`` keeps every sample.

    Returns:
        [K] int64 increasing indices.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    if t.size == 0 or max_hz <= 0:
        return np.arange(t.size)
    period = max(int(round(1e9 / max_hz)), 1)
    _, first = np.unique((t - t[0]) // period, return_index=True)
    return np.union1d(first, [t.size - 1]).astype(np.int64)


# ----------------------------------------------------------------------------- geometry


def robot_link_meshes(
    urdf: yourdfpy.URDF, *, collision: bool = False
) -> dict[str, list[trimesh.Trimesh]]:
    """The visual (or collision) geometry of every link, in the link frame.

    Args:
        urdf: a model loaded with meshes (``Dataset.urdf()``).
        collision: collision geometry instead of visual.

    Returns:
        link name -> triangle meshes (metres, link frame; origins and mesh scales applied).
    """
    import trimesh

    scene = urdf.collision_scene if collision else urdf.scene
    out: dict[str, list[trimesh.Trimesh]] = {}
    if scene is None:
        return out
    graph = scene.graph
    for node in graph.nodes_geometry:
        link = graph.transforms.parents[node]
        T, geom_name = graph.get(frame_to=node, frame_from=link)
        geom = scene.geometry[geom_name]
        if not hasattr(geom, "faces") or len(geom.faces) == 0:
            continue
        mesh = trimesh.Trimesh(
            np.asarray(geom.vertices, dtype=np.float64), np.asarray(geom.faces), process=False
        )
        mesh.apply_transform(np.asarray(T, dtype=np.float64))
        out.setdefault(str(link), []).append(mesh)
    return out


def rest_joint_positions(ds: Dataset, chain: Chain) -> np.ndarray:
    """The robot's rest configuration, [J] rad|m in ``chain.joint_names`` order.

    The splats' declared rest (``robot.splats.rest.joint_positions``) where given, else 0;
    each value clipped into the joint's limits.
    """
    rest = (((ds.manifest.get("robot") or {}).get("splats") or {}).get("rest") or {}).get(
        "joint_positions", {}
    )
    q = np.array([float(rest.get(n, 0.0)) for n in chain.joint_names], dtype=np.float64)
    return np.clip(q, chain.joint_lower, chain.joint_upper)


def _quat_xyzw(R: np.ndarray) -> np.ndarray:
    from ..frames import matrix_to_quat

    q = np.asarray(matrix_to_quat(np.asarray(R, dtype=np.float64)))
    return q[..., [1, 2, 3, 0]]


def label_colors(ids: np.ndarray) -> np.ndarray:
    """Deterministic, well-spread RGB colours for integer ids ([N] -> [N, 3] uint8).

    Hue steps by the golden ratio; HSV to RGB by ``f(n) = V - V S max(0, min(k, 4 - k, 1))``
    with ``k = (n + 6 H) mod 6`` for n = 5, 3, 1.
    """
    h = (np.asarray(ids, dtype=np.float64).reshape(-1, 1) * 0.618033988749895) % 1.0
    s, v = 0.65, 0.95
    k = (np.array([5.0, 3.0, 1.0]) + 6.0 * h) % 6.0
    rgb = v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return np.round(rgb * 255).astype(np.uint8)


def entity(*parts: str) -> str:
    """An entity path from raw name parts (each escaped: '/', spaces and dots are safe)."""
    return "/".join(rr.escape_entity_path_part(str(p)) for p in parts)


# ----------------------------------------------------------------------------- context


@dataclass
class RerunContext:
    """What a layer needs: the recording, the dataset, the episode and the timeline.

    Attributes:
        rec: the recording stream.
        ds: the dataset.
        episode: the episode logged (None if the dataset has none).
        time: the ``time`` timeline.
        max_hz: downsampling rate for transforms and images (``<= 0``: every sample).
        notes: one-line remarks for the user (skipped content).
        options: per-layer options, ``layer name -> {option: value}``.
    """

    rec: rr.RecordingStream
    ds: Dataset
    episode: Episode | None
    time: TimeAxis
    max_hz: float = 60.0
    notes: list[str] = field(default_factory=list)
    options: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def has_robot(self) -> bool:
        return bool((self.ds.manifest.get("robot") or {}).get("urdf"))

    @cached_property
    def urdf(self) -> yourdfpy.URDF:
        return self.ds.urdf(load_meshes=True)

    @cached_property
    def chain(self) -> Chain:
        """The robot chain with the current physics revision's fitted joint offsets."""
        from ..kinematics import Chain, dataset_fitted_chain

        chain, note = dataset_fitted_chain(
            self.ds, Chain.from_urdf(self.urdf, floating_as_fixed=True)
        )
        if note:
            self.notes.append(note)
        return chain

    @cached_property
    def q_rest(self) -> np.ndarray:
        return rest_joint_positions(self.ds, self.chain)

    def table(self, stream: str) -> pa.Table | None:
        """An episode table, or None when the episode lacks the stream."""
        if (
            self.episode is None
            or not self.episode.has(stream)
            or "path" not in self.episode.stream(stream)
        ):
            return None
        return self.episode.table(stream)

    def send(self, path: str, t_ns: np.ndarray, columns: Any) -> None:
        """``send_columns`` on the ``time`` timeline."""
        self.rec.send_columns(path, indexes=[self.time.column(t_ns)], columns=columns)

    def link_path(self, link: str) -> str:
        return "world/robot/" + entity(link)

    def object_path(self, name: str) -> str:
        return "world/objects/" + entity(name)


def _joint_matrix(ctx: RerunContext, js: pa.Table, rows: np.ndarray) -> np.ndarray:
    """[K, J] joint positions of the selected rows (missing joints at their rest value)."""
    q = np.tile(ctx.q_rest, (rows.size, 1))
    for k, name in enumerate(ctx.chain.joint_names):
        col = f"position.{name}"
        if col in js.column_names:
            q[:, k] = js.column(col).to_numpy()[rows]
    return q


def _forward(ctx: RerunContext, q: np.ndarray) -> np.ndarray:
    import torch

    return ctx.chain.forward(torch.from_numpy(np.ascontiguousarray(q, dtype=np.float64))).numpy()


def _log_mesh(
    rec: rr.RecordingStream, path: str, meshes: list[trimesh.Trimesh], color: tuple[int, ...]
) -> None:
    import trimesh

    mesh = meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)
    rec.log(
        path,
        rr.Mesh3D(
            vertex_positions=np.asarray(mesh.vertices, dtype=np.float32),
            triangle_indices=np.asarray(mesh.faces, dtype=np.uint32),
            vertex_normals=np.asarray(mesh.vertex_normals, dtype=np.float32),
            albedo_factor=color,
        ),
        static=True,
    )


def _send_poses(ctx: RerunContext, path: str, t_ns: np.ndarray, T: np.ndarray) -> None:
    ctx.send(
        path,
        t_ns,
        rr.Transform3D.columns(translation=T[:, :3, 3], quaternion=_quat_xyzw(T[:, :3, :3])),
    )


def _pose_rows(table: pa.Table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t_ns [N], positions [N, 3], quats wxyz [N, 4]) of a pose table."""
    t = table.column("t_ns").to_numpy().astype(np.int64)
    p = np.stack([table.column(c).to_numpy() for c in ("x", "y", "z")], -1)
    q = np.stack([table.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
    return t, p, q


def _groups(names: np.ndarray) -> dict[str, np.ndarray]:
    uniq, inv = np.unique(names, return_inverse=True)
    return {str(u): np.flatnonzero(inv == k) for k, u in enumerate(uniq)}


# ----------------------------------------------------------------------------- layers


def _layer_robot(ctx: RerunContext) -> None:
    if not ctx.has_robot:
        ctx.notes.append("no robot: robot layer skipped")
        return
    for link, meshes in robot_link_meshes(ctx.urdf).items():
        _log_mesh(ctx.rec, ctx.link_path(link) + "/visual", meshes, (180, 180, 190, 255))
    js = ctx.table("joint_states")
    if js is None or js.num_rows == 0:
        T = _forward(ctx, ctx.q_rest[None])[0]
        for k, link in enumerate(ctx.chain.link_names):
            ctx.rec.log(
                ctx.link_path(link),
                rr.Transform3D(translation=T[k, :3, 3], mat3x3=T[k, :3, :3]),
                static=True,
            )
        ctx.notes.append("no joint_states: robot shown at its rest configuration")
        return
    t = js.column("t_ns").to_numpy().astype(np.int64)
    rows = downsample_indices(t, ctx.max_hz)
    T = _forward(ctx, _joint_matrix(ctx, js, rows))  # [K, L, 4, 4]
    for k, link in enumerate(ctx.chain.link_names):
        _send_poses(ctx, ctx.link_path(link), t[rows], T[:, k])


def _groups_or_empty(table: pa.Table | None) -> dict[str, np.ndarray]:
    if table is None or table.num_rows == 0:
        return {}
    return _groups(np.asarray(table.column("object").to_pylist(), dtype=object).astype(str))


def _layer_objects(ctx: RerunContext) -> None:
    poses = ctx.table("object_poses")
    groups = _groups_or_empty(poses)
    for name, entry in sorted(ctx.ds.assets.items()):
        if "mesh" not in entry:
            continue
        color = (200, 140, 80, 255) if entry.get("kind") == "object" else (120, 120, 110, 255)
        _log_mesh(ctx.rec, ctx.object_path(name) + "/mesh", [ctx.ds.mesh(name)], color)
        if name not in groups:
            ctx.rec.log(
                ctx.object_path(name), rr.Transform3D(translation=(0.0, 0.0, 0.0)), static=True
            )
    for name, idx in groups.items():
        t, p, q = _pose_rows(poses.take(pa.array(idx)))
        keep = downsample_indices(t, ctx.max_hz)
        ctx.send(
            ctx.object_path(name),
            t[keep],
            rr.Transform3D.columns(translation=p[keep], quaternion=q[keep][:, [1, 2, 3, 0]]),
        )


def _splat_points(splats: Any, sel: np.ndarray, T_inv: np.ndarray) -> rr.Points3D:
    from ..render.sh import SH_C0

    x = splats.means[sel].astype(np.float64)
    local = x @ T_inv[:3, :3].T + T_inv[:3, 3]
    rgb = np.clip(0.5 + SH_C0 * splats.sh[sel, 0, :], 0.0, 1.0)
    alpha = 1.0 / (1.0 + np.exp(-splats.opacity_logits[sel].astype(np.float64)))
    colors = np.round(np.concatenate([rgb, alpha[:, None]], -1) * 255).astype(np.uint8)
    radii = np.exp(splats.log_scales[sel].max(axis=1)).astype(np.float32)
    return rr.Points3D(local.astype(np.float32), colors=colors, radii=radii)


def _layer_splats(ctx: RerunContext) -> None:
    from ..frames import make_T, quat_to_matrix

    if ctx.has_robot and "splats" in (ctx.ds.manifest.get("robot") or {}):
        entry = ctx.ds.splat_entry("robot")
        splats = ctx.ds.splats("robot")
        T_rest = _forward(ctx, ctx.q_rest[None])[0]
        targets = list(entry.get("targets", []))
        for b, link in enumerate(targets):
            sel = np.flatnonzero(splats.bind_id == b)
            if sel.size == 0 or link not in ctx.chain.link_names:
                continue
            T_inv = np.linalg.inv(T_rest[ctx.chain.link_index(link)])
            ctx.rec.log(
                ctx.link_path(link) + "/splats", _splat_points(splats, sel, T_inv), static=True
            )
    for name, asset in sorted(ctx.ds.assets.items()):
        if "splats" not in asset:
            continue
        entry = ctx.ds.splat_entry(name)
        splats = ctx.ds.splats(name)
        rest = (entry.get("rest") or {}).get("object_poses", {})
        for b, target in enumerate(entry.get("targets", [])):
            sel = np.flatnonzero(splats.bind_id == b)
            if sel.size == 0:
                continue
            pose = np.asarray(rest.get(target, (0, 0, 0, 1, 0, 0, 0)), dtype=np.float64)
            T = np.asarray(make_T(quat_to_matrix(pose[3:7]), pose[:3]))
            ctx.rec.log(
                ctx.object_path(target) + "/splats",
                _splat_points(splats, sel, np.linalg.inv(T)),
                static=True,
            )


def _annotation_context(segments: pa.Table) -> rr.AnnotationContext:
    ids = segments.column("label_id").to_numpy()
    cats = segments.column("category").to_pylist()
    inst = segments.column("instance").to_pylist()
    targets = segments.column("target").to_pylist()
    colors = label_colors(ids)
    infos = [
        rr.AnnotationInfo(
            id=int(i), label=f"{c}:{n}" + (f" ({t})" if t else ""), color=tuple(int(v) for v in col)
        )
        for i, c, n, t, col in zip(ids, cats, inst, targets, colors, strict=True)
    ]
    return rr.AnnotationContext([rr.ClassDescription(info=a) for a in infos])


def _layer_cameras(ctx: RerunContext) -> None:
    import cv2

    segments = ctx.table("segments")
    if segments is not None and segments.num_rows:
        ctx.rec.log("world", _annotation_context(segments), static=True)
    boxes = ctx.table("boxes2d")
    for cam_name in ctx.ds.camera_names:
        cam = ctx.ds.camera(cam_name)
        base = "world/cameras/" + entity(cam_name)
        if cam.T_world_cam is not None:
            T = cam.T_world_cam
            ctx.rec.log(base, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True)
        ctx.rec.log(
            base + "/image",
            rr.Pinhole(
                image_from_camera=cam.K,
                resolution=[cam.width, cam.height],
                camera_xyz=rr.ViewCoordinates.RDF,
            ),
            static=True,
        )
        if cam.distortion_model != "none" and any(cam.distortion):
            ctx.notes.append(
                f"camera {cam_name}: distortion ({cam.distortion_model}) is not shown by the pinhole"
            )
        ep = ctx.episode
        if ep is None or cam_name not in ep.camera_streams:
            continue
        stream = ep.camera_streams[cam_name]
        if "frames" not in stream:
            continue
        frames = ep.frames(cam_name)
        stamp = dict(
            zip(
                frames.column("frame_index").to_pylist(),
                frames.column("t_ns").to_pylist(),
                strict=True,
            )
        )
        order = np.array(sorted(stamp), dtype=np.int64)
        keep = set(
            order[downsample_indices(np.array([stamp[i] for i in order]), ctx.max_hz)].tolist()
        )
        if "video" in stream:
            for i, rgb in enumerate(ep.iter_video(cam_name)):
                if i not in keep:
                    continue
                ok, buf = cv2.imencode(
                    ".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90]
                )
                if not ok:
                    raise FormatError("JPEG encoding failed", where=f"{cam_name} frame {i}")
                ctx.time.set(ctx.rec, stamp[i])
                ctx.rec.log(
                    base + "/image/rgb",
                    rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg"),
                )
        if "labels" in stream:
            for i, lab in ep.iter_labels(cam_name):
                if i in keep and i in stamp:
                    ctx.time.set(ctx.rec, stamp[i])
                    ctx.rec.log(
                        base + "/image/segmentation", rr.SegmentationImage(lab, opacity=0.5)
                    )
        if boxes is not None and boxes.num_rows:
            mine = boxes.filter(pc.equal(boxes.column("camera"), cam_name))
            if mine.num_rows:
                _send_boxes2d(ctx, base + "/image/boxes", mine)
    ctx.rec.reset_time()


def _send_boxes2d(ctx: RerunContext, path: str, boxes: pa.Table) -> None:
    boxes = boxes.sort_by("t_ns")
    t = boxes.column("t_ns").to_numpy().astype(np.int64)
    lo = np.stack([boxes.column("x_min").to_numpy(), boxes.column("y_min").to_numpy()], -1)
    hi = np.stack([boxes.column("x_max").to_numpy(), boxes.column("y_max").to_numpy()], -1)
    stamps, counts = np.unique(t, return_counts=True)
    cols = rr.Boxes2D.columns(
        centers=0.5 * (lo + hi),
        half_sizes=0.5 * (hi - lo),
        class_ids=boxes.column("label_id").to_numpy(),
    ).partition(counts)
    ctx.send(path, stamps, cols)


def _layer_boxes3d(ctx: RerunContext) -> None:
    boxes = ctx.table("boxes3d")
    if boxes is None or boxes.num_rows == 0:
        return
    boxes = boxes.sort_by("t_ns")
    t, p, q = _pose_rows(boxes)
    size = np.stack([boxes.column(c).to_numpy() for c in ("size_x", "size_y", "size_z")], -1)
    stamps, counts = np.unique(t, return_counts=True)
    cols = rr.Boxes3D.columns(
        centers=p,
        half_sizes=0.5 * size,
        quaternions=q[:, [1, 2, 3, 0]],
        labels=boxes.column("object").to_pylist(),
    ).partition(counts)
    ctx.send("world/boxes3d", stamps, cols)


def _layer_ee_poses(ctx: RerunContext) -> None:
    table = ctx.table("ee_poses")
    if table is None or table.num_rows == 0:
        return
    for link, idx in _groups(
        np.asarray(table.column("link").to_pylist(), dtype=object).astype(str)
    ).items():
        t, p, q = _pose_rows(table.take(pa.array(idx)))
        keep = downsample_indices(t, ctx.max_hz)
        path = "world/ee/" + entity(link)
        ctx.rec.log(path, rr.TransformAxes3D(0.05), static=True)
        ctx.send(
            path,
            t[keep],
            rr.Transform3D.columns(translation=p[keep], quaternion=q[keep][:, [1, 2, 3, 0]]),
        )


def log_scalar_series(
    ctx: RerunContext, path: str, t_ns: np.ndarray, values: np.ndarray, *, name: str = ""
) -> None:
    """Plot one scalar series (e.g. a residual) on the ``time`` timeline.

    Args:
        ctx: the context.
        path: entity path (e.g. ``"plots/residuals/box/position_mm"``).
        t_ns: [N] int64 stamps.
        values: [N] float values (units in the path or ``name``).
        name: legend name.
    """
    if name:
        ctx.rec.log(path, rr.SeriesLines(names=name), static=True)
    ctx.send(
        path,
        np.asarray(t_ns, dtype=np.int64),
        rr.Scalars.columns(scalars=np.asarray(values, np.float64)),
    )


def _layer_plots(ctx: RerunContext) -> None:
    js = ctx.table("joint_states")
    if js is not None and js.num_rows:
        t = js.column("t_ns").to_numpy().astype(np.int64)
        for col in js.column_names:
            kind, _, joint = col.partition(".")
            if kind in ("position", "velocity", "effort") and joint:
                log_scalar_series(
                    ctx,
                    f"plots/joints/{kind}/" + entity(joint),
                    t,
                    js.column(col).to_numpy(),
                    name=joint,
                )
    wr = ctx.table("wrenches")
    if wr is not None and wr.num_rows:
        for frame, idx in _groups(
            np.asarray(wr.column("frame").to_pylist(), dtype=object).astype(str)
        ).items():
            sub = wr.take(pa.array(idx))
            t = sub.column("t_ns").to_numpy().astype(np.int64)
            for c in ("fx", "fy", "fz", "tx", "ty", "tz"):
                log_scalar_series(
                    ctx, f"plots/wrench/{entity(frame)}/{c}", t, sub.column(c).to_numpy(), name=c
                )


_LEVELS = {
    "error": rr.TextLogLevel.ERROR,
    "warning": rr.TextLogLevel.WARN,
    "warn": rr.TextLogLevel.WARN,
    "info": rr.TextLogLevel.INFO,
    "debug": rr.TextLogLevel.DEBUG,
}


def _finding_record(f: Any) -> tuple[str, str, int | None]:
    """(level, text, t_ns) of a finding object or dict, read defensively."""

    def get(obj: Any, key: str) -> Any:
        return obj.get(key) if isinstance(obj, dict) else getattr(obj, key, None)

    sev = str(get(f, "severity") or "info").lower()
    parts = [str(x) for x in (get(f, "code"), get(f, "message")) if x]
    loc = get(f, "location")
    t = get(f, "t_ns")
    if t is None and loc is not None:
        t = get(loc, "t_ns")
    hint = get(f, "hint")
    text = ": ".join(parts) + (f" (hint: {hint})" if hint else "")
    return sev, text, None if t is None else int(t)


def _layer_findings(ctx: RerunContext) -> None:
    from .. import validate as _validate

    ctx.notes.append(
        "findings of the re-render (binding) checks are not logged; run robogs-validate for them"
    )
    try:
        result = _validate.validate(ctx.ds.root, ignore=["binding"])
    except RobogsError as exc:
        ctx.notes.append(f"validation failed, findings skipped: {exc.one_line()}")
        return
    findings = getattr(result, "findings", result) or []
    start = ctx.episode.start_ns if ctx.episode is not None else 0
    n = 0
    for f in findings:
        sev, text, t = _finding_record(f)
        ctx.time.set(ctx.rec, start if t is None else t)
        ctx.rec.log("logs/findings", rr.TextLog(text, level=_LEVELS.get(sev, rr.TextLogLevel.INFO)))
        n += 1
    ctx.rec.reset_time()
    ctx.notes.append(f"{n} validator findings logged")


Layer = Callable[[RerunContext], None]
LayerViews = Callable[[Dataset], list[Any]]
_LAYER_VIEWS: dict[str, LayerViews] = {}
_BUILTIN_LAYERS: dict[str, Layer] = {
    "robot": _layer_robot,
    "objects": _layer_objects,
    "splats": _layer_splats,
    "cameras": _layer_cameras,
    "boxes3d": _layer_boxes3d,
    "ee_poses": _layer_ee_poses,
    "plots": _layer_plots,
    "findings": _layer_findings,
}
DEFAULT_LAYERS: tuple[str, ...] = tuple(_BUILTIN_LAYERS)


def _adopt(reg: Registry[Layer], name: str, obj: object) -> None:
    """A ``robogs.layers`` entry point: a layer function (registered under the entry's name)
    or a module that calls :func:`register_layer` on import."""
    if isinstance(obj, ModuleType):
        return
    if not callable(obj):
        raise TypeError(f"{type(obj).__name__} is not callable")
    register_layer(name, obj)  # type: ignore[arg-type]


#: the layer registry (the built-in layers, in logging order, then ``rerender`` and plug-ins)
REGISTRY: Registry[Layer] = Registry(
    "layers",
    ENTRY_POINT_GROUPS["layers"],
    noun="Rerun layer",
    adopt=_adopt,
    order=lambda e: (list(_BUILTIN_LAYERS).index(e.name) if e.name in _BUILTIN_LAYERS else 99,),
    unknown_where="layers",
)
for _name, _fn in _BUILTIN_LAYERS.items():
    REGISTRY.register(_name, _fn)


def register_layer(
    name: str,
    fn: Layer,
    *,
    default: bool = False,
    views: LayerViews | None = None,
    replace: bool = False,
) -> Layer:
    """Add a layer (``fn(ctx)``) that :func:`log_dataset` can run by name; returns ``fn``.

    Args:
        name: layer name.
        fn: logs its content through ``ctx.rec`` on ``ctx.time``.
        default: also run it when no layer list is given.
        views: ``views(dataset) -> [rerun.blueprint views]`` added to the default blueprint's
            right column when the layer runs.
        replace: allow replacing another layer of that name.

    Raises:
        RegistrationError: the name is taken and ``replace`` is False.
    """
    global DEFAULT_LAYERS
    REGISTRY.register(name, fn, replace=replace)
    if views is not None:
        _LAYER_VIEWS[name] = views
    if default and name not in DEFAULT_LAYERS:
        DEFAULT_LAYERS = (*DEFAULT_LAYERS, name)
    return fn


def available_layers() -> dict[str, Layer]:
    """``name -> layer function`` of every usable layer (built-in, ``rerender``, plug-ins), in
    logging order; :func:`layer_entries` also lists the unavailable ones with the reason."""
    return REGISTRY.available()


def layer_entries() -> list[Entry[Layer]]:
    """Every entry of the layer registry, usable or not, with status, reason and source."""
    return REGISTRY.entries()


# ----------------------------------------------------------------------------- recording


def default_blueprint(ds: Dataset, layers: Iterable[str] | None = None) -> rrb.Blueprint:
    """3D scene on the left; camera views, joint plots and the findings log on the right.

    Layers registered with ``views`` add theirs after the camera views when they are in
    ``layers``.
    """
    right: list[Any] = [
        rrb.Spatial2DView(origin="world/cameras/" + entity(c) + "/image", name=c)
        for c in ds.camera_names
    ]
    for name in layers or ():
        if name in _LAYER_VIEWS:
            right.extend(_LAYER_VIEWS[name](ds))
    right.append(
        rrb.Tabs(
            rrb.TimeSeriesView(origin="plots/joints/position", name="joint positions"),
            rrb.TimeSeriesView(origin="plots/joints/velocity", name="joint velocities"),
            rrb.TimeSeriesView(origin="plots/joints/effort", name="joint efforts"),
            rrb.TimeSeriesView(origin="plots/wrench", name="wrenches"),
        )
    )
    right.append(rrb.TextLogView(origin="logs", name="findings"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="scene"),
            rrb.Vertical(*right),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def log_dataset(
    rec: rr.RecordingStream,
    ds: Dataset,
    *,
    episode: str | None = None,
    max_hz: float = 60.0,
    layers: Iterable[str] | None = None,
    layer_options: dict[str, dict[str, Any]] | None = None,
) -> RerunContext:
    """Log a dataset into an open recording.

    Args:
        rec: the recording (its sinks already set).
        ds: the dataset.
        episode: episode id (default: the only/first one).
        max_hz: downsampling rate of transforms and images.
        layers: layer names (default :data:`DEFAULT_LAYERS`).
        layer_options: ``layer name -> {option: value}`` (``ctx.options``).

    Returns:
        The context (``notes`` lists what was skipped).
    """
    eps = ds.episodes
    ep = ds.episode(episode) if episode is not None else (eps[0] if eps else None)
    ctx = RerunContext(rec, ds, ep, time_axis(ds), max_hz, options=dict(layer_options or {}))
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    fns = [REGISTRY.get(n) for n in (DEFAULT_LAYERS if layers is None else layers)]
    for fn in fns:
        fn(ctx)
    return ctx


def write_rrd(
    ds: Dataset,
    path: str | Path,
    *,
    episode: str | None = None,
    max_hz: float = 60.0,
    layers: Iterable[str] | None = None,
    application_id: str = "robogs",
    layer_options: dict[str, dict[str, Any]] | None = None,
) -> list[str]:
    """Write a dataset to a Rerun ``.rrd`` file with the default blueprint.

    Args:
        ds: the dataset.
        path: output ``.rrd`` (written directly; callers wanting atomicity pass a temp path).
        episode: episode id (default: the first).
        max_hz: downsampling rate of transforms and images (``<= 0``: all samples).
        layers: layer names (default all).
        application_id: Rerun application id.
        layer_options: ``layer name -> {option: value}`` for the layers that take options.

    Returns:
        Notes on skipped content.
    """
    if not math.isfinite(max_hz):
        raise RobogsError(f"max_hz must be finite, got {max_hz}")
    rec = rr.RecordingStream(
        application_id, recording_id=f"robogs-{ds.name}", send_properties=False
    )
    rec.set_log_time_enabled(False)  # only the dataset clock, so recordings are reproducible
    rec.set_log_tick_enabled(False)
    names = list(DEFAULT_LAYERS if layers is None else layers)
    rec.save(str(path), default_blueprint=default_blueprint(ds, names))
    try:
        ctx = log_dataset(
            rec, ds, episode=episode, max_hz=max_hz, layers=names, layer_options=layer_options
        )
    finally:
        rec.flush()
        rec.disconnect()
    return ctx.notes


from . import rerun_rerender as _rerun_rerender  # noqa: E402,F401 - registers the "rerender" layer

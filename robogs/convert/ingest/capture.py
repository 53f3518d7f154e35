"""Write a static multi-view capture (nerfstudio, COLMAP) as cameras plus one static episode.

Views that share intrinsics and image size form one camera. Each camera gets
``cameras/<cam>.json`` (intrinsics, ``extrinsics: time_varying``), and in the episode a camera
stream with ``frames.parquet``, ``rgb.mp4`` (view i = frame i) and ``extrinsics.parquet``
(``T_world_cam`` per frame). A static capture has no clock: ``t_ns`` is the view's ordinal
(0, 1, 2, ... over all views sorted by image name), declared as ``stamp_source: none``, and the
frame table and extrinsics table of a camera share those stamps.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError

from .context import IngestContext
from .sinks import CameraSink
from .tf_tree import matrix_to_quat_np

__all__ = ["View", "orient_world", "write_static_capture", "world_up_rotation", "UP_AXES"]

UP_AXES = {
    "+x": (1, 0, 0),
    "-x": (-1, 0, 0),
    "+y": (0, 1, 0),
    "-y": (0, -1, 0),
    "+z": (0, 0, 1),
    "-z": (0, 0, -1),
}


@dataclass
class View:
    """One image of a static capture.

    Attributes:
        name: image name as the source lists it (sort key).
        image_path: the image file.
        camera: intrinsics (its ``name`` groups views into cameras).
        T_world_cam: [4, 4] camera-to-world, OpenCV camera axes, metres.
    """

    name: str
    image_path: Path
    camera: CameraModel
    T_world_cam: np.ndarray


def world_up_rotation(up: str) -> np.ndarray:
    """[4, 4] rotation taking the source world's ``up`` axis to +z (a right-handed rotation).

    ``+y`` gives ``(x, y, z) -> (x, -z, y)``, the y-up to z-up map of
    :data:`robogs.format.frames.T_ZUP_YUP`.
    """
    if up not in UP_AXES:
        raise InputError(
            f"unknown up axis {up!r}", where="--world-up", hint=f"one of {', '.join(UP_AXES)}"
        )
    u = np.asarray(UP_AXES[up], dtype=np.float64)
    z = np.array([0.0, 0.0, 1.0])
    R = np.eye(3)
    if np.allclose(u, -z):
        R = np.diag([1.0, -1.0, -1.0])  # half turn about x
    elif not np.allclose(u, z):
        axis = np.cross(u, z)
        axis /= np.linalg.norm(axis)
        angle = np.arccos(np.clip(u @ z, -1.0, 1.0))
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
        R = np.round(R, 15)
    T = np.eye(4)
    T[:3, :3] = R
    return T


def orient_world(ctx: IngestContext, views: list[View], kept: str) -> None:
    """Apply ``--world-up``: turn every view's ``T_world_cam`` so that the capture's up axis is
    +z (:func:`world_up_rotation`), or, without it, note ``kept`` (how the source's world frame
    is kept) in the provenance."""
    up = ctx.options.world_up
    if not up:
        ctx.provenance.note(f"{kept}; pass --world-up to re-orient")
        return
    T = world_up_rotation(up)
    for v in views:
        v.T_world_cam = T @ v.T_world_cam
    ctx.provenance.note(f"world rotated so that the capture's {up} axis is +z")


def _intrinsics_key(c: CameraModel) -> tuple:
    return (c.width, c.height, c.fx, c.fy, c.cx, c.cy, c.distortion_model, tuple(c.distortion))


def _read_rgb(path: Path, view: str) -> np.ndarray:
    if not path.is_file():
        raise InputError(
            "image file not found",
            path=path,
            where=f"view {view}",
            hint="pass --images with the folder that holds the capture's images",
        )
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise InputError("image file cannot be decoded", path=path, where=f"view {view}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def write_static_capture(ctx: IngestContext, views: list[View], *, source: str) -> None:
    """Write the cameras, frames, videos and extrinsics of ``views``.

    Raises:
        InputError: no views, images of a camera differing in size from its intrinsics, missing
            or undecodable image files.
    """
    if not views:
        raise InputError("the capture has no views", path=source)
    views = sorted(views, key=lambda v: v.name)
    groups: dict[str, list[tuple[int, View]]] = {}
    keys: dict[str, tuple] = {}
    for i, v in enumerate(views):
        name = v.camera.name
        k = _intrinsics_key(v.camera)
        if name in keys and keys[name] != k:
            raise InputError(
                f"views named camera {name!r} have different intrinsics",
                path=source,
                where=f"view {v.name}",
            )
        keys[name] = k
        groups.setdefault(name, []).append((i, v))
    ep = ctx.episode_dir()
    w = ctx.writer
    ctx.clock = "none (static capture: t_ns is the view ordinal)"
    n_total = len(views)
    ctx.progress.start("writing views", n_total, unit="views")
    for cam_name, items in sorted(groups.items()):
        cam = items[0][1].camera
        w.set_camera(replace(cam, T_world_cam=None, extrinsics="time_varying"))
        base = f"{ep}/cameras/{cam_name}"
        sink = CameraSink(
            w.path(f"{base}/frames.parquet"),
            w.path(f"{base}/rgb.mp4"),
            topic=source,
            provenance=ctx.provenance,
            video=ctx.options.video,
            fps_hint=1.0,
        )
        rows: list[list[float]] = []
        stamps: list[int] = []
        for i, v in items:
            rgb = None
            if ctx.options.video:
                rgb = _read_rgb(v.image_path, v.name)
                if (rgb.shape[1], rgb.shape[0]) != (cam.width, cam.height):
                    raise InputError(
                        f"image is {rgb.shape[1]}x{rgb.shape[0]} but its camera says "
                        f"{cam.width}x{cam.height}",
                        path=v.image_path,
                        where=f"view {v.name}",
                    )
            sink.add(i, rgb)
            T = np.asarray(v.T_world_cam, dtype=np.float64)
            rows.append([*T[:3, 3].tolist(), *matrix_to_quat_np(T[:3, :3]).tolist()])
            stamps.append(i)
            ctx.progress.advance()
            rec = ctx.provenance.topic(source)
            rec.messages += 1
            rec.written += 1
        st = sink.close()
        vals = np.asarray(rows, dtype=np.float64)
        cols = [pa.array(stamps, pa.int64())] + [pa.array(vals[:, j]) for j in range(7)]
        table = pa.Table.from_arrays(cols, names=["t_ns", "x", "y", "z", "qw", "qx", "qy", "qz"])
        w.write_table(f"{base}/extrinsics.parquet", table, kind="camera_extrinsics")
        entry = {
            "kind": "camera",
            "camera": cam_name,
            "frames": f"{base}/frames.parquet",
            "extrinsics": f"{base}/extrinsics.parquet",
            "stamp_source": "none",
            "offset_ns": 0,
            "nominal_rate_hz": None,
            "source": source,
        }
        if ctx.options.video:
            entry["video"] = f"{base}/rgb.mp4"
        ctx.add_stream(f"camera/{cam_name}", entry, start_ns=st.start_ns, end_ns=st.end_ns)
    ctx.progress.stop()
    ctx.provenance.topic(source).stamp_source = "none"
    ctx.provenance.extra["views"] = n_total

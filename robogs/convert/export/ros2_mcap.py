"""Export one episode as an MCAP file of ROS 2 messages (CDR, ``ros2msg`` schemas).

Topics (names outside ``[A-Za-z0-9_]`` are replaced by ``_``):

================================== ============================== =================================
topic                              type                           from
================================== ============================== =================================
/joint_states                      sensor_msgs/JointState         joint_states (name order = table)
/camera/<cam>/image_raw/compressed sensor_msgs/CompressedImage    video frames, PNG (lossless re-
                                                                  encoding of the decoded frame) or
                                                                  JPEG
/camera/<cam>/camera_info          sensor_msgs/CameraInfo         cameras/<cam>.json, one per frame
/camera/<cam>/labels/compressed    sensor_msgs/CompressedImage    label PNGs (16-bit), as stored
/tf_static                         tf2_msgs/TFMessage             world -> <cam>_optical_frame
/tf                                tf2_msgs/TFMessage             time-varying camera extrinsics
/objects/<name>/pose               geometry_msgs/PoseStamped      object_poses (frame_id world)
/ee/<link>/pose                    geometry_msgs/PoseStamped      ee_poses (frame_id world)
/wrench/<frame>                    geometry_msgs/WrenchStamped    wrenches (frame_id = frame)
/robot_description                 std_msgs/String                the URDF text, once at start
================================== ============================== =================================

Every message's ``header.stamp`` is the sample's ``t_ns`` exactly (``sec = t_ns // 10**9``,
``nanosec = t_ns % 10**9``), and its MCAP ``log_time`` and ``publish_time`` equal ``t_ns``.
Static messages (``/tf_static``, ``/robot_description``) are stamped with the episode start.
Quaternions are reordered to ROS's (x, y, z, w). ``CameraInfo`` follows ROS's pixel convention
(pixel centres at integer coordinates), so its ``cx, cy`` are robogs' minus 0.5 px. A camera
with distortion model ``none`` is written as ``plumb_bob`` with five zero coefficients. Messages are written in time order
(ties: the order of the table above). Writing uses ``mcap_ros2.writer.Writer``
(https://github.com/foxglove/mcap, ``python/mcap-ros2-support``).
"""

from __future__ import annotations

import heapq
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from mcap_ros2.writer import Writer

from robogs.format import Dataset, Episode
from robogs.format.cameras import CameraModel
from robogs.format.errors import FormatError, InputError

from . import ExportReport, register_exporter
from .ros2_msgdefs import MSGDEFS

__all__ = ["CAMERA_FRAME_SUFFIX", "WORLD_FRAME", "export_mcap", "stamp", "topic_part"]

WORLD_FRAME = "world"
CAMERA_FRAME_SUFFIX = "_optical_frame"
_BAD = re.compile(r"[^A-Za-z0-9_]")
_NS = 1_000_000_000

Item = tuple[int, int, str, str, dict[str, Any]]  # (t_ns, priority, topic, type, message)


def topic_part(name: str) -> str:
    """A name made safe for a ROS topic component."""
    out = _BAD.sub("_", name)
    return out if out and not out[0].isdigit() else f"_{out}"


def stamp(t_ns: int) -> dict[str, int]:
    """``builtin_interfaces/Time`` of an int64 ns stamp, exactly (``nanosec`` in [0, 1e9))."""
    sec, nsec = divmod(int(t_ns), _NS)
    if not -(2**31) <= sec < 2**31:
        raise InputError(f"stamp {t_ns} ns does not fit builtin_interfaces/Time (int32 seconds)")
    return {"sec": sec, "nanosec": nsec}


def _header(t_ns: int, frame: str) -> dict[str, Any]:
    return {"stamp": stamp(t_ns), "frame_id": frame}


def _columns(table: pa.Table, names: list[str]) -> list[list[Any]]:
    return [table.column(n).to_pylist() for n in names]


def _joint_states(ep: Episode) -> Iterator[Item]:
    if not ep.has("joint_states"):
        return
    tab = ep.table("joint_states").sort_by("t_ns")
    cols = tab.column_names
    joints = [c[len("position.") :] for c in cols if c.startswith("position.")]
    t = tab.column("t_ns").to_pylist()
    data = {
        kind: _columns(tab, [f"{kind}.{j}" for j in joints])
        if all(f"{kind}.{j}" in cols for j in joints)
        else None
        for kind in ("position", "velocity", "effort")
    }
    for i, ti in enumerate(t):
        msg = {"header": _header(ti, ""), "name": joints}
        for kind, values in data.items():
            msg[kind] = [] if values is None else [v[i] for v in values]
        yield ti, 0, "/joint_states", "sensor_msgs/JointState", msg


def _camera_info(cam: CameraModel, t_ns: int) -> dict[str, Any]:
    model, d = cam.distortion_model, list(cam.distortion)
    if model == "none":
        model, d = "plumb_bob", [0.0] * 5
    # ROS (like OpenCV) puts pixel centres at integers; robogs at +0.5
    fx, fy, cx, cy = cam.fx, cam.fy, cam.cx - 0.5, cam.cy - 0.5
    return {
        "header": _header(t_ns, topic_part(cam.name) + CAMERA_FRAME_SUFFIX),
        "height": cam.height,
        "width": cam.width,
        "distortion_model": model,
        "d": d,
        "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def _transform(t_ns: int, parent: str, child: str, T: np.ndarray) -> dict[str, Any]:
    from robogs.format.frames import matrix_to_quat

    q = np.asarray(matrix_to_quat(np.asarray(T[:3, :3], dtype=np.float64)))
    return {
        "header": _header(t_ns, parent),
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", map(float, T[:3, 3]), strict=True)),
            "rotation": {"x": float(q[1]), "y": float(q[2]), "z": float(q[3]), "w": float(q[0])},
        },
    }


def _camera_sources(ds: Dataset, ep: Episode, image_format: str) -> list[Iterator[Item]]:
    """One time-ordered source per camera and message kind."""
    out: list[Iterator[Item]] = []
    for name, stream in sorted(ep.camera_streams.items()):
        if "frames" not in stream:
            continue
        frames = ep.frames(name)
        stamps = dict(zip(*_columns(frames, ["frame_index", "t_ns"]), strict=True))
        if "video" in stream:
            out.append(_images(ds, ep, name, stamps, image_format))
        if "labels" in stream:
            out.append(_labels(ep, name, stamps))
        if "extrinsics" in stream:
            out.append(_extrinsics(ds, name, stream["extrinsics"]))
    return out


def _images(
    ds: Dataset, ep: Episode, name: str, stamps: dict[int, int], image_format: str
) -> Iterator[Item]:
    ext, params = (
        (".png", [cv2.IMWRITE_PNG_COMPRESSION, 3])
        if image_format == "png"
        else (".jpg", [cv2.IMWRITE_JPEG_QUALITY, 95])
    )
    cam = ds.camera(name)
    base, frame = f"/camera/{topic_part(name)}", topic_part(name) + CAMERA_FRAME_SUFFIX
    for i, rgb in enumerate(ep.iter_video(name)):
        if i not in stamps:
            raise FormatError(
                f"video frame {i} has no row in frames.parquet", path=ep.video_path(name)
            )
        ok, buf = cv2.imencode(ext, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), params)
        if not ok:
            raise FormatError(f"{image_format} encoding failed", where=f"{name} frame {i}")
        t = stamps[i]
        msg = {"header": _header(t, frame), "format": image_format, "data": buf.tobytes()}
        yield t, 1, f"{base}/image_raw/compressed", "sensor_msgs/CompressedImage", msg
        yield t, 2, f"{base}/camera_info", "sensor_msgs/CameraInfo", _camera_info(cam, t)


def _labels(ep: Episode, name: str, stamps: dict[int, int]) -> Iterator[Item]:
    topic, frame = (
        f"/camera/{topic_part(name)}/labels/compressed",
        topic_part(name) + CAMERA_FRAME_SUFFIX,
    )
    labels = pq.read_table(ep.labels_path(name), columns=["frame_index", "png"]).sort_by(
        "frame_index"
    )
    for i, blob in zip(*_columns(labels, ["frame_index", "png"]), strict=True):
        if i in stamps:
            msg = {"header": _header(stamps[i], frame), "format": "png", "data": blob}
            yield stamps[i], 3, topic, "sensor_msgs/CompressedImage", msg


def _extrinsics(ds: Dataset, name: str, rel: str) -> Iterator[Item]:
    tab = pq.read_table(ds.resolve(rel)).sort_by("t_ns")
    t, x, y, z, qw, qx, qy, qz = _columns(tab, ["t_ns", "x", "y", "z", "qw", "qx", "qy", "qz"])
    for k, tk in enumerate(t):
        msg = {"transforms": [{
            "header": _header(tk, WORLD_FRAME),
            "child_frame_id": topic_part(name) + CAMERA_FRAME_SUFFIX,
            "transform": {"translation": {"x": x[k], "y": y[k], "z": z[k]},
                          "rotation": {"x": qx[k], "y": qy[k], "z": qz[k], "w": qw[k]}},
        }]}  # fmt: skip
        yield tk, 4, "/tf", "tf2_msgs/TFMessage", msg


def _poses(ep: Episode, stream: str, key: str, prefix: str, priority: int) -> Iterator[Item]:
    if not ep.has(stream):
        return
    tab = ep.table(stream).sort_by("t_ns")
    cols = _columns(tab, ["t_ns", key, "x", "y", "z", "qw", "qx", "qy", "qz"])
    for t, name, x, y, z, qw, qx, qy, qz in zip(*cols, strict=True):
        msg = {
            "header": _header(t, WORLD_FRAME),
            "pose": {
                "position": {"x": x, "y": y, "z": z},
                "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
            },
        }
        yield t, priority, f"/{prefix}/{topic_part(name)}/pose", "geometry_msgs/PoseStamped", msg


def _wrenches(ep: Episode) -> Iterator[Item]:
    if not ep.has("wrenches"):
        return
    tab = ep.table("wrenches").sort_by("t_ns")
    cols = _columns(tab, ["t_ns", "frame", "fx", "fy", "fz", "tx", "ty", "tz"])
    for t, frame, fx, fy, fz, tx, ty, tz in zip(*cols, strict=True):
        msg = {
            "header": _header(t, frame),
            "wrench": {"force": {"x": fx, "y": fy, "z": fz}, "torque": {"x": tx, "y": ty, "z": tz}},
        }
        yield t, 7, f"/wrench/{topic_part(frame)}", "geometry_msgs/WrenchStamped", msg


def _static(ds: Dataset, ep: Episode) -> Iterator[Item]:
    t0 = ep.start_ns
    transforms = []
    for name in sorted(ep.camera_streams):
        cam = ds.camera(name)
        if cam.T_world_cam is not None and "extrinsics" not in ep.camera_streams[name]:
            transforms.append(
                _transform(t0, WORLD_FRAME, topic_part(name) + CAMERA_FRAME_SUFFIX, cam.T_world_cam)
            )
    if transforms:
        yield t0, -2, "/tf_static", "tf2_msgs/TFMessage", {"transforms": transforms}
    if (ds.manifest.get("robot") or {}).get("urdf"):
        yield (
            t0,
            -1,
            "/robot_description",
            "std_msgs/String",
            {"data": ds.urdf_path.read_text(encoding="utf-8")},
        )


def export_mcap(
    ds: Dataset, out: Path, *, episode: str | None = None, image_format: str = "png"
) -> ExportReport:
    """Write one episode as ROS 2 messages in an MCAP file.

    Args:
        ds: the dataset.
        out: output ``.mcap`` file.
        episode: episode id (default: the only one).
        image_format: ``"png"`` (lossless w.r.t. the decoded video) or ``"jpeg"``.

    Returns:
        The report; ``facts["messages"]`` maps topic -> message count.
    """
    if image_format not in ("png", "jpeg"):
        raise InputError(f"image_format must be 'png' or 'jpeg', not {image_format!r}")
    if not ds.episodes:
        raise InputError(
            "dataset has no episode",
            path=ds.manifest_path,
            hint="the mcap export writes one episode",
        )
    ep = ds.episode(episode)
    if ep.start_ns < 0:
        raise InputError(
            f"episode starts at {ep.start_ns} ns: MCAP log times must be >= 0",
            hint="shift the dataset clock to non-negative stamps",
        )
    sources = [
        _static(ds, ep),
        _joint_states(ep),
        *_camera_sources(ds, ep, image_format),
        _poses(ep, "object_poses", "object", "objects", 5),
        _poses(ep, "ee_poses", "link", "ee", 6),
        _wrenches(ep),
    ]
    counts: dict[str, int] = {}
    with open(out, "wb") as fh:
        writer = Writer(fh)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        writer.add_metadata(
            "robogs",
            {
                "dataset": ds.name,
                "spec_version": ds.spec_version,
                "episode": ep.id,
                "clock": str(ds.manifest.get("conventions", {}).get("clock", "")),
            },
        )
        for t, _, topic, typ, msg in heapq.merge(*sources, key=lambda item: (item[0], item[1])):
            seq = counts.get(topic, 0)
            writer.write_message(
                topic, schemas[typ], msg, log_time=int(t), publish_time=int(t), sequence=seq
            )
            counts[topic] = seq + 1
        writer.finish()
    notes = [
        f"{s} not exported (no standard ROS message)"
        for s in ("boxes2d", "boxes3d", "segments", "actions")
        if ep.has(s)
    ]
    return ExportReport(
        out=out, files=[out.name], notes=notes, facts={"messages": counts, "episode": ep.id}
    )


register_exporter(
    "mcap",
    export_mcap,
    output="file",
    suffix=".mcap",
    help="one episode as ROS 2 messages (joint states, images, camera info, TF, poses, wrenches)",
)

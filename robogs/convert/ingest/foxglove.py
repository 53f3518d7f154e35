"""Foxglove well-known schemas mapped onto the ROS message shapes the ingest understands.

Foxglove schemas (https://docs.foxglove.dev/docs/visualization/message-schemas) carry the same
content as the ROS messages under other field names. Each adapter takes a decoded message
(JSON objects become ``SimpleNamespace``; protobuf messages are read by attribute) and returns
an object with the ROS field names, so the handlers in :mod:`robogs.convert.ingest.messages` need
no Foxglove-specific code.
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

__all__ = ["FOXGLOVE_TYPES", "adapt", "ros_type_of", "to_namespace"]


def to_namespace(obj: Any) -> Any:
    """JSON value -> nested ``SimpleNamespace`` (lists kept as lists)."""
    if isinstance(obj, dict):
        return SimpleNamespace(**{k: to_namespace(v) for k, v in obj.items()})
    if isinstance(obj, list):
        return [to_namespace(v) for v in obj]
    return obj


def _get(obj: Any, *names: str, default: Any = None) -> Any:
    for n in names:
        if hasattr(obj, n):
            return getattr(obj, n)
    return default


def _stamp(ts: Any) -> SimpleNamespace:
    if ts is None:
        return SimpleNamespace(sec=0, nanosec=0)
    return SimpleNamespace(
        sec=int(_get(ts, "sec", "seconds", default=0)),
        nanosec=int(_get(ts, "nsec", "nanos", "nanosec", default=0)),
    )


def _header(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        stamp=_stamp(_get(m, "timestamp")), frame_id=str(_get(m, "frame_id", default=""))
    )


def _bytes(data: Any) -> bytes:
    if isinstance(data, str):  # JSON encodes bytes as base64
        return base64.b64decode(data)
    return bytes(data or b"")


def _xyz(v: Any) -> SimpleNamespace:
    return SimpleNamespace(
        x=float(_get(v, "x", default=0.0)),
        y=float(_get(v, "y", default=0.0)),
        z=float(_get(v, "z", default=0.0)),
    )


def _quat(q: Any) -> SimpleNamespace:
    return SimpleNamespace(
        x=float(_get(q, "x", default=0.0)),
        y=float(_get(q, "y", default=0.0)),
        z=float(_get(q, "z", default=0.0)),
        w=float(_get(q, "w", default=1.0)),
    )


def _compressed_image(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        header=_header(m), format=str(_get(m, "format", default="")), data=_bytes(m.data)
    )


def _raw_image(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        header=_header(m),
        width=int(m.width),
        height=int(m.height),
        encoding=str(m.encoding),
        step=int(m.step),
        is_bigendian=0,
        data=_bytes(m.data),
    )


def _calibration(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        header=_header(m),
        width=int(m.width),
        height=int(m.height),
        distortion_model=str(_get(m, "distortion_model", default="")),
        d=list(_get(m, "D", "d", default=[])),
        k=list(_get(m, "K", "k", default=[])),
        r=list(_get(m, "R", "r", default=[])),
        p=list(_get(m, "P", "p", default=[])),
        binning_x=0,
        binning_y=0,
        roi=None,
    )


def _transform(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        header=SimpleNamespace(stamp=_stamp(_get(m, "timestamp")), frame_id=str(m.parent_frame_id)),
        child_frame_id=str(m.child_frame_id),
        transform=SimpleNamespace(translation=_xyz(m.translation), rotation=_quat(m.rotation)),
    )


def _frame_transform(m: Any) -> SimpleNamespace:
    return SimpleNamespace(transforms=[_transform(m)])


def _frame_transforms(m: Any) -> SimpleNamespace:
    return SimpleNamespace(transforms=[_transform(t) for t in _get(m, "transforms", default=[])])


def _pose_in_frame(m: Any) -> SimpleNamespace:
    return SimpleNamespace(
        header=_header(m),
        pose=SimpleNamespace(position=_xyz(m.pose.position), orientation=_quat(m.pose.orientation)),
    )


#: Foxglove schema name -> (ROS type it stands for, adapter)
FOXGLOVE_TYPES: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "foxglove.CompressedImage": ("sensor_msgs/msg/CompressedImage", _compressed_image),
    "foxglove.RawImage": ("sensor_msgs/msg/Image", _raw_image),
    "foxglove.CameraCalibration": ("sensor_msgs/msg/CameraInfo", _calibration),
    "foxglove.FrameTransform": ("tf2_msgs/msg/TFMessage", _frame_transform),
    "foxglove.FrameTransforms": ("tf2_msgs/msg/TFMessage", _frame_transforms),
    "foxglove.PoseInFrame": ("geometry_msgs/msg/PoseStamped", _pose_in_frame),
}


def ros_type_of(schema_name: str) -> str | None:
    """The ROS type a Foxglove schema stands for (``foxglove_msgs/msg/X`` or ``foxglove.X``)."""
    key = schema_name.replace("foxglove_msgs/msg/", "foxglove.").replace(
        "foxglove_msgs/", "foxglove."
    )
    entry = FOXGLOVE_TYPES.get(key)
    return entry[0] if entry else None


def adapt(schema_name: str, msg: Any) -> Any:
    """Convert a decoded Foxglove message to its ROS shape."""
    key = schema_name.replace("foxglove_msgs/msg/", "foxglove.").replace(
        "foxglove_msgs/", "foxglove."
    )
    return FOXGLOVE_TYPES[key][1](msg)

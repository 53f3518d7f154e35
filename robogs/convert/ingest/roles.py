"""Topic roles: what each bag/MCAP topic becomes in the dataset.

A role is detected from the message type and the topic name, and the user can override it
with a YAML mapping (``--map roles.yaml``: ``topic: role``) or ``--topic ROLE=TOPIC``.

Roles: ``joint_states``, ``camera_image``, ``camera_info``, ``camera_labels``,
``object_pose:<name>``, ``ee_pose:<link>``, ``wrench:<frame>``, ``tf_static``, ``tf``,
``robot_description``, ``generic`` (every field decoded into ``streams/<topic>.parquet``; the
default for types without a role of their own), ``ignore``. ``camera_image`` / ``camera_info`` may name the camera
(``camera_image:cam0``); by default the camera name comes from the topic namespace
(``/camera/cam0/image_raw/compressed`` -> ``cam0``; ``/kinect_head/rgb/camera_info`` ->
``kinect_head_rgb``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from robogs.format.errors import InputError

from .yamlio import read_yaml

__all__ = [
    "Role",
    "ROLE_KINDS",
    "parse_role",
    "load_role_map",
    "load_frame_map",
    "parse_topic_flags",
    "parse_frame_flags",
    "default_role",
    "normalize_type",
    "camera_name_from_topic",
    "safe_name",
]

ROLE_KINDS = (
    "joint_states",
    "camera_image",
    "camera_info",
    "camera_labels",
    "object_pose",
    "ee_pose",
    "wrench",
    "tf_static",
    "tf",
    "robot_description",
    "generic",
    "ignore",
)
_NAMED = {"object_pose", "ee_pose", "wrench", "camera_image", "camera_info", "camera_labels"}
_MAX_MAP_BYTES = 1 << 20

_IMAGE_SUFFIXES = (
    "image_raw",
    "image_rect_color",
    "image_rect",
    "image_color",
    "image_mono",
    "image",
)
_POSE_TYPES = {
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped",
}
_TF_TYPES = {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"}


@dataclass(frozen=True)
class Role:
    """A topic's role: ``kind`` from :data:`ROLE_KINDS`, ``name`` for object/link/frame/camera."""

    kind: str
    name: str | None = None

    def __str__(self) -> str:
        return self.kind if self.name is None else f"{self.kind}:{self.name}"


def safe_name(text: str) -> str:
    """``text`` reduced to ``[A-Za-z0-9_.-]`` (other characters become ``_``), never empty."""
    out = re.sub(r"[^A-Za-z0-9_.-]+", "_", text.strip("/")).strip("_")
    return out[:64] or "unnamed"


def normalize_type(msgtype: str) -> str:
    """``pkg/Name`` (ROS 1) or ``pkg/msg/Name`` -> ``pkg/msg/Name``; other names unchanged."""
    parts = msgtype.split("/")
    if len(parts) == 2 and parts[0] and parts[1]:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


def parse_role(text: str, *, where: str | None = None) -> Role:
    """Parse ``kind`` or ``kind:name``.

    Raises:
        InputError: unknown kind, or a name where none is allowed.
    """
    kind, sep, name = str(text).strip().partition(":")
    if kind not in ROLE_KINDS:
        raise InputError(
            f"unknown role {text!r}", where=where, hint=f"roles: {', '.join(ROLE_KINDS)}"
        )
    if sep and kind not in _NAMED:
        raise InputError(f"role {kind!r} takes no name", where=where)
    if sep and not name:
        raise InputError(f"role {text!r} has an empty name", where=where)
    return Role(kind, safe_name(name) if sep else None)


_FRAME_KEYS = ("tf_objects", "tf_cameras")


def _read_map(p: Path) -> object:
    return read_yaml(p, what="role map", max_bytes=_MAX_MAP_BYTES)


def load_role_map(path: str | Path) -> dict[str, Role]:
    """Read a ``topic: role`` YAML mapping (optionally under a ``topics:`` key).

    The keys ``tf_objects`` and ``tf_cameras`` are frame mappings (:func:`load_frame_map`).

    Raises:
        InputError: unreadable file, not a mapping, unknown role.
    """
    p = Path(path)
    doc = _read_map(p)
    if isinstance(doc, dict):
        doc = {k: v for k, v in doc.items() if k not in _FRAME_KEYS}
    if isinstance(doc, dict) and isinstance(doc.get("topics"), dict):
        doc = doc["topics"]
    if not isinstance(doc, dict):
        raise InputError(
            "role map must be a mapping 'topic: role'",
            path=p,
            hint="e.g. '/mocap/box/pose: object_pose:box'",
        )
    out: dict[str, Role] = {}
    for topic, role in doc.items():
        out[str(topic)] = parse_role(str(role), where=f"{p}: {topic}")
    return out


def load_frame_map(path: str | Path) -> tuple[dict[str, str], dict[str, str]]:
    """The ``tf_objects: {object: frame}`` and ``tf_cameras: {camera: frame}`` sections of a
    ``--map`` YAML (empty when absent).

    Raises:
        InputError: unreadable file, a section that is not a name -> frame mapping.
    """
    p = Path(path)
    doc = _read_map(p)
    out: list[dict[str, str]] = []
    for key in _FRAME_KEYS:
        sec = doc.get(key) if isinstance(doc, dict) else None
        if sec is None:
            out.append({})
            continue
        if not isinstance(sec, dict) or not all(
            isinstance(v, str) and v.strip("/") for v in sec.values()
        ):
            raise InputError(
                f"{key} must map names to TF frames",
                path=p,
                where=key,
                hint=f"e.g. '{key}: {{box: box_link}}'",
            )
        out.append({str(k): str(v) for k, v in sec.items()})
    return out[0], out[1]


def parse_frame_flags(flags: list[str], flag: str) -> dict[str, str]:
    """Parse ``NAME=FRAME`` (or ``FRAME``: the name is the frame's) flags.

    Raises:
        InputError: an empty name or frame.
    """
    out: dict[str, str] = {}
    for item in flags:
        name, sep, frame = item.partition("=")
        if not sep:
            name, frame = safe_name(item), item
        if not name or not frame.strip("/"):
            raise InputError(
                f"{flag} expects NAME=FRAME or FRAME, got {item!r}",
                where=flag,
                hint=f"e.g. {flag} box=box_link",
            )
        out[name] = frame.lstrip("/")
    return out


def parse_topic_flags(flags: list[str]) -> dict[str, Role]:
    """Parse ``--topic ROLE=TOPIC`` flags.

    Raises:
        InputError: a flag without ``=``.
    """
    out: dict[str, Role] = {}
    for flag in flags:
        role, sep, topic = flag.partition("=")
        if not sep or not topic:
            raise InputError(
                f"--topic expects ROLE=TOPIC, got {flag!r}",
                where="--topic",
                hint="e.g. --topic object_pose:box=/mocap/box/pose",
            )
        out[topic] = parse_role(role, where="--topic")
    return out


def camera_name_from_topic(topic: str) -> str:
    """Camera name from an image or camera_info topic (the topic's camera namespace)."""
    parts = [p for p in topic.split("/") if p]
    if parts and parts[-1] in ("compressed", "compressedDepth", "theora", "h264", "ffmpeg"):
        parts = parts[:-1]
    if parts and (parts[-1] in _IMAGE_SUFFIXES or parts[-1] == "camera_info"):
        parts = parts[:-1]
    if len(parts) > 1 and parts[0] in ("camera", "cameras"):
        parts = parts[1:]
    return safe_name("_".join(parts)) if parts else "camera"


def _pose_name(topic: str, prefix: str) -> str | None:
    parts = [p for p in topic.split("/") if p]
    if len(parts) >= 2 and parts[0] == prefix:
        rest = parts[1:-1] if parts[-1] in ("pose", "transform") and len(parts) > 2 else parts[1:]
        return safe_name("_".join(rest))
    return None


def _object_name(topic: str) -> str:
    parts = [p for p in topic.split("/") if p]
    while len(parts) > 1 and parts[-1] in (
        "pose",
        "pose_stamped",
        "transform",
        "transform_stamped",
        "odom",
    ):
        parts = parts[:-1]
    return safe_name(parts[-1]) if parts else "object"


def default_role(topic: str, msgtype: str) -> tuple[Role, str]:
    """The role detected for ``topic`` of type ``msgtype``, and why.

    A type with no role of its own is decoded into a generic table (role ``generic``).

    Returns:
        ``(role, reason)``: ``reason`` is a short phrase saying why this role was guessed.
    """
    t = normalize_type(msgtype)
    short = t.rsplit("/", 1)[-1]
    low = topic.lower()
    if t == "sensor_msgs/msg/JointState":
        return Role("joint_states"), "JointState"
    if t in ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"):
        if "depth" in low:
            return Role("generic"), "depth images are not part of the format (decoded, data kept "
            "as its length)"
        if any(k in low for k in ("label", "panoptic", "segment")):
            return Role("camera_labels"), f"{short} on a label/panoptic/segment topic"
        return Role("camera_image"), short
    if t == "sensor_msgs/msg/CameraInfo":
        return Role("camera_info"), "CameraInfo"
    if t in _TF_TYPES:
        if low.rstrip("/").endswith("tf_static"):
            return Role("tf_static"), "TFMessage on a tf_static topic"
        return Role("tf"), "TFMessage"
    if t in _POSE_TYPES:
        ee = _pose_name(topic, "ee")
        if ee:
            return Role("ee_pose", ee), f"{short} under /ee/"
        obj = _pose_name(topic, "objects")
        if obj:
            return Role("object_pose", obj), f"{short} under /objects/"
        return Role("object_pose", _object_name(topic)), (
            f"{short}, named after its topic (an end-effector if its path tracks a robot link)"
        )
    if t == "geometry_msgs/msg/WrenchStamped":
        frame = _pose_name(topic, "wrench")
        return Role("wrench", frame), "WrenchStamped, one stream per topic"
    if t == "std_msgs/msg/String" and low.rstrip("/").endswith("robot_description"):
        return Role("robot_description"), "String on a robot_description topic"
    return Role("generic"), f"no role for message type {t}; decoded into a generic table"

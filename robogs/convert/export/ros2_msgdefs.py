"""ROS 2 message definitions (``ros2msg`` text) for the MCAP export.

Each schema is the type's ``.msg`` text followed by every type it uses, each after a line of
80 ``=`` and a ``MSG: pkg/Type`` header — the concatenated form rosbag2 and
``mcap_ros2.writer.Writer.register_msgdef`` expect. The field lists are those of ROS 2
(Humble and later): ``common_interfaces`` (std_msgs, geometry_msgs, sensor_msgs),
``geometry2`` (tf2_msgs) and ``rcl_interfaces`` (builtin_interfaces).
"""

from __future__ import annotations

__all__ = ["MSGDEFS", "msgdef"]

_SEP = "=" * 80

_PLAIN: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
    "geometry_msgs/Wrench": "Vector3 force\nVector3 torque\n",
    "geometry_msgs/WrenchStamped": "std_msgs/Header header\nWrench wrench\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n"
    ),
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data\n",
    "sensor_msgs/RegionOfInterest": (
        "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"
    ),
    "sensor_msgs/CameraInfo": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
        "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
        "sensor_msgs/RegionOfInterest roi\n"
    ),
}

_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}  # fmt: skip


def _deps(name: str) -> list[str]:
    """Types ``name`` uses, depth first, each once."""
    pkg = name.split("/")[0]
    out: list[str] = []
    for line in _PLAIN[name].splitlines():
        typ = line.split()[0].split("[")[0]
        if typ in _PRIMITIVES:
            continue
        full = typ if "/" in typ else f"{pkg}/{typ}"
        for t in (full, *_deps(full)):
            if t not in out:
                out.append(t)
    return out


def msgdef(name: str) -> str:
    """The concatenated ``ros2msg`` schema text of ``name`` (e.g. ``sensor_msgs/JointState``)."""
    parts = [_PLAIN[name]]
    for dep in _deps(name):
        parts.append(f"{_SEP}\nMSG: {dep}\n{_PLAIN[dep]}")
    return "\n".join(p.rstrip("\n") for p in parts) + "\n"


#: full schema text of every message type the exporter writes
MSGDEFS: dict[str, str] = {
    n: msgdef(n)
    for n in (
        "sensor_msgs/JointState",
        "sensor_msgs/CompressedImage",
        "sensor_msgs/CameraInfo",
        "tf2_msgs/TFMessage",
        "geometry_msgs/PoseStamped",
        "geometry_msgs/WrenchStamped",
        "std_msgs/String",
    )
}

"""UR RTDE logs (Universal Robots, "Real-Time Data Exchange" guide; ``record_data``-style CSV).

Joints: ``actual_q_i`` (rad), ``actual_qd_i`` (rad/s), ``target_moment_i`` (N m). Time:
``timestamp``, seconds since the controller started. End-effector: ``actual_TCP_pose_0..5``,
``x y z`` (m) and the rotation vector ``rx ry rz`` (rad) of the TCP in the controller's base
frame. ur_description names that frame ``base`` (a fixed child of ``base_link``, turned by pi
about z) and the flange ``tool0``; the poses are read as ``tool0`` in ``base`` (in the root
link when the URDF has no ``base``). A TCP offset set on the controller moves the recorded
point off ``tool0``: a map's ``ee_pose`` then names the right link.
"""

from __future__ import annotations

from ..pose import EePoseColumns

__all__ = ["JOINT_FAMILIES", "TCP_POSE", "TIME_COLUMN", "infer_tcp_pose"]

#: per-joint column families: (layout, kind, base name)
JOINT_FAMILIES = (
    ("rtde", "position", "actual_q"),
    ("rtde", "velocity", "actual_qd"),
    ("rtde", "effort", "target_moment"),
)
#: RTDE's time column, in seconds since the controller started
TIME_COLUMN = "timestamp"
#: ``actual_TCP_pose``: the TCP in the controller's base frame, ``x y z`` m and the rotation
#: vector ``rx ry rz`` rad (axis times angle)
TCP_POSE = "actual_TCP_pose"
#: ur_description's link for the controller's base frame (``base_link`` turned by pi about z)
_UR_BASE = "base"
#: ur_description's flange link, the TCP when the controller has no TCP offset configured
_UR_TOOL = "tool0"


def infer_tcp_pose(cols: dict[int, str], link_names: list[str]) -> tuple[EePoseColumns | None, str]:
    """``actual_TCP_pose_0..5`` (``cols``: index -> column) as an ``ee_pose`` spec, with a
    sentence saying how it is read (or, when the spec is None, why it is not)."""
    if sorted(cols) != list(range(6)):
        return None, f"{TCP_POSE}* ignored ({TCP_POSE} needs 6 columns {TCP_POSE}_0..5"
    if _UR_TOOL not in link_names:
        return None, (
            f"{TCP_POSE}* ignored (the URDF has no UR flange link {_UR_TOOL!r}, the TCP "
            "without a controller TCP offset"
        )
    frame = _UR_BASE if _UR_BASE in link_names else None
    spec = EePoseColumns(_UR_TOOL, "axis_angle", [cols[i] for i in range(6)], frame=frame)
    where = (
        f"UR's controller base frame, link {_UR_BASE!r}"
        if frame
        else f"the root link {link_names[0]!r} (the URDF has no UR {_UR_BASE!r} link)"
    )
    return spec, (
        f"{spec.columns[0]}..{spec.columns[-1]} read as the UR RTDE TCP pose (x y z m, rotation "
        f"vector rad) of link {_UR_TOOL!r} in {where}; a TCP offset set on the controller "
        "moves it off tool0"
    )

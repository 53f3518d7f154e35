"""Published kinematic tables of common arms, as :class:`MDHTable` objects."""

from __future__ import annotations

import math

import numpy as np

from robogs.format.kinematics.mdh import MDHTable

__all__ = ["UR5_JOINT_NAMES", "ur5_mdh"]

UR5_JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
"""UR5 joint names as in the ROS ``ur_description`` URDF."""


def ur5_mdh() -> MDHTable:
    """UR5 from Universal Robots' published standard DH parameters, converted to modified DH.

    Standard DH (Universal Robots, "DH parameters for calculations of kinematics and dynamics"):
    d1 = 0.089159, a2 = -0.425, a3 = -0.39225, d4 = 0.10915, d5 = 0.09465, d6 = 0.0823 m;
    alpha = (pi/2, 0, 0, pi/2, -pi/2, 0); zero offsets. Converted with
    :meth:`MDHTable.from_standard_dh`.

    The fixed transforms match the ROS ``ur_description`` URDF frames: ``T_base`` is a rotation
    of pi about z (``base_link`` to the DH base frame, the URDF's ``base`` link) and the tool
    frame equals the URDF's ``tool0`` (flange, z out of the tool plate), so
    ``tool_pose(q) == T_base_link_tool0(q)`` for the same joint vector ``q``.

    Returns:
        The 6-joint table (``joint_names`` = :data:`UR5_JOINT_NAMES`).
    """
    half_pi = math.pi / 2
    T_base = np.diag([-1.0, -1.0, 1.0, 1.0])  # RotZ(pi): base_link -> DH frame 0
    return MDHTable.from_standard_dh(
        a_m=[0.0, -0.425, -0.39225, 0.0, 0.0, 0.0],
        alpha_rad=[half_pi, 0.0, 0.0, half_pi, -half_pi, 0.0],
        d_m=[0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823],
        theta_offset_rad=[0.0] * 6,
        joint_names=UR5_JOINT_NAMES,
        T_base=T_base,
    )

"""Synthetic arm joint logs (RTDE-style CSV) with one hidden torque-model effect, and arm
datasets with recorded end-effector poses and one hidden kinematic effect."""

from robogs.synth.armlogs.generate import DEFAULT_PARAMS, ArmLogSpec, generate_armlog
from robogs.synth.armlogs.kinematic import (
    KIN_PARAMS,
    KinLogSpec,
    generate_kinematic_dataset,
    kin_truth_path,
)
from robogs.synth.armlogs.ur5 import UR5_JOINTS, ur5_urdf

__all__ = [
    "ArmLogSpec",
    "generate_armlog",
    "DEFAULT_PARAMS",
    "ur5_urdf",
    "UR5_JOINTS",
    "KIN_PARAMS",
    "KinLogSpec",
    "generate_kinematic_dataset",
    "kin_truth_path",
]

"""Forward kinematics: URDF trees (:class:`Chain`), modified-DH tables (:class:`MDHTable`) and
the fitted joint offsets of ``physics.json`` (:func:`chain_with_offsets`).

Conventions are in ``design.md`` next to this file.
"""

from robogs.format.kinematics.chain import JOINT_TYPES, Chain
from robogs.format.kinematics.mdh import (
    MDH_CONVENTION,
    MDHTable,
    load_mdh_json,
    mdh_transform,
    save_mdh_json,
)
from robogs.format.kinematics.offsets import (
    OFFSET_KEYS,
    JointOffsets,
    chain_with_offsets,
    dataset_fitted_chain,
    fitted_chain,
    offset_origin,
    perpendicular,
    read_joint_offsets,
)
from robogs.format.kinematics.presets import UR5_JOINT_NAMES, ur5_mdh

__all__ = [
    "Chain",
    "JOINT_TYPES",
    "MDHTable",
    "MDH_CONVENTION",
    "mdh_transform",
    "load_mdh_json",
    "save_mdh_json",
    "ur5_mdh",
    "UR5_JOINT_NAMES",
    "OFFSET_KEYS",
    "JointOffsets",
    "chain_with_offsets",
    "fitted_chain",
    "dataset_fitted_chain",
    "offset_origin",
    "perpendicular",
    "read_joint_offsets",
]

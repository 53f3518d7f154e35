"""Robot-arm model: inverse dynamics and forward kinematics from the URDF, joint effects,
identification.

Public entry points (imported lazily):

* :class:`ArmModel`, :func:`inverse_dynamics`, :func:`regressor` - rigid-body dynamics;
* :func:`savgol_derivative` - the documented differentiator of joint signals;
* :func:`compare_arm`, :func:`diagnose_arm`, :func:`fit_arm`, :func:`open_arm` - the physics
  loop on a dataset's joint logs with efforts (torque residual) and recorded end-effector
  poses (kinematic residual, :mod:`reference_impl.physics.arm.kinematic_model`);
* the effects (torque: ``joint_friction``, ``armature``, ``payload``, ``mass_scale``,
  ``effort_time_offset``; kinematic: ``joint_elasticity``, ``backlash``,
  ``kinematic_offsets``) register in :mod:`reference_impl.physics.effects` on import of
  :mod:`reference_impl.physics.arm.effects`.
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "ArmModel",
    "Inertials",
    "inverse_dynamics",
    "regressor",
    "savgol_derivative",
    "open_arm",
    "compare_arm",
    "diagnose_arm",
    "fit_arm",
    "fit_effects",
]

_LAZY = {
    "ArmModel": "reference_impl.physics.arm.rnea",
    "Inertials": "reference_impl.physics.arm.rnea",
    "inverse_dynamics": "reference_impl.physics.arm.rnea",
    "regressor": "reference_impl.physics.arm.rnea",
    "savgol_derivative": "robogs_format.differentiate",
    "open_arm": "reference_impl.physics.arm.api",
    "compare_arm": "reference_impl.physics.arm.api",
    "diagnose_arm": "reference_impl.physics.arm.api",
    "fit_arm": "reference_impl.physics.arm.api",
    "fit_effects": "reference_impl.physics.arm.identify",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(name)

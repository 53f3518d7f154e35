"""Robot-arm model: inverse dynamics and forward kinematics from the URDF, joint effects,
identification.

Public entry points (imported lazily):

* :class:`ArmModel`, :func:`inverse_dynamics`, :func:`regressor` - rigid-body dynamics;
* :func:`savgol_derivative` - the documented differentiator of joint signals;
* :func:`compare_arm`, :func:`diagnose_arm`, :func:`fit_arm`, :func:`open_arm` - the physics
  loop on a dataset's joint logs with efforts (torque residual) and recorded end-effector
  poses (kinematic residual, :mod:`robogs.physics.arm.kinematic_model`);
* the effects (torque: ``joint_friction``, ``armature``, ``payload``, ``mass_scale``,
  ``effort_time_offset``; kinematic: ``joint_elasticity``, ``backlash``,
  ``kinematic_offsets``) register in :mod:`robogs.physics.effects` on import of
  :mod:`robogs.physics.arm.effects`.
"""

from __future__ import annotations

from robogs._lazy import lazy_getattr

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
    "ArmModel": "robogs.physics.arm.rnea",
    "Inertials": "robogs.physics.arm.rnea",
    "inverse_dynamics": "robogs.physics.arm.rnea",
    "regressor": "robogs.physics.arm.rnea",
    "savgol_derivative": "robogs.format.differentiate",
    "open_arm": "robogs.physics.arm.api",
    "compare_arm": "robogs.physics.arm.api",
    "diagnose_arm": "robogs.physics.arm.api",
    "fit_arm": "robogs.physics.arm.api",
    "fit_effects": "robogs.physics.arm.identify",
}


__getattr__ = lazy_getattr(__name__, _LAZY)

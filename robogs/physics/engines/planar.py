"""The ``planar`` engine: a thin adapter over the batched torch model (:mod:`robogs.physics.model`).

It represents one box on a horizontal plane pushed by a frictionless sphere or capsule
(grasps included); parameter sets change ``objects.<box>.friction_dynamic`` (the base model's
refitted parameter). Effects are not passed through this interface yet: the fitter still
calls :func:`robogs.physics.model.simulate` directly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.physics.engines.base import ObjectState, Predicted, yaw_quat
from robogs.physics.model import Drive, simulate
from robogs.physics.scene import base_params, scene_from_physics
from robogs.physics.space import BASE, ParamSpace

__all__ = ["PlanarEngine", "MAX_TILT_DEG"]

MAX_TILT_DEG = 3.0
"""A support plane tilted more than this is not horizontal for the planar model [deg].

Below it the planar model keeps the plane horizontal at ``plane_z_m`` (``robogs physics init``
notes any tilt above 1 deg) and the catalogue's ``tilt`` effect carries the in-plane pull of
gravity; at 3 deg the plane rises 5 mm over a 100 mm slide, about the size of the pose noise
of the recordings this model is fitted to, beyond which the lost height dominates and a 3-D
engine is needed."""


class PlanarEngine:
    """The torch rigid-box model behind the :class:`~robogs.physics.engines.base.Engine` interface."""

    name: ClassVar[str] = "planar"

    def __init__(
        self,
        physics: Mapping[str, Any],
        *,
        object_name: str | None = None,
        meshes: Mapping[str, Any] | None = None,
        poses: Mapping[str, Sequence[float]] | None = None,
        dt: float = 1e-3,
        threads: int = 1,
    ) -> None:
        ok, why = self.can_represent(physics, meshes)
        if not ok:
            raise InputError(f"the planar engine cannot represent this scene: {why}")
        rigid = [k for k, v in physics["objects"].items() if v.get("equation") == "rigid"]
        self.object_name = object_name or rigid[0]
        self.scene = scene_from_physics(dict(physics), self.object_name, dt=dt)
        self.space = ParamSpace(base_params(self.scene), [])
        self.dt = dt

    @classmethod
    def can_represent(
        cls, physics: Mapping[str, Any], meshes: Mapping[str, Any] | None = None
    ) -> tuple[bool, str]:
        """Exactly one rigid box, a horizontal plane, a frictionless sphere or capsule."""
        objects = physics.get("objects") or {}
        rigid = [
            k for k, v in objects.items() if isinstance(v, Mapping) and v.get("equation") == "rigid"
        ]
        if len(rigid) != 1:
            return False, f"{len(rigid)} rigid objects (the planar model has exactly one)"
        name = rigid[0]
        if name in (meshes or {}):
            return False, f"object {name!r} has a mesh shape (the planar model knows boxes)"
        if "size_m" not in objects[name] or "mass_kg" not in objects[name]:
            return False, f"object {name!r} lacks size_m or mass_kg"
        n = np.asarray((objects.get("table") or {}).get("normal", [0, 0, 1]), dtype=float)
        tilt = float(np.degrees(np.arccos(np.clip(n[2] / np.linalg.norm(n), -1, 1))))
        if tilt > MAX_TILT_DEG:
            return False, f"support plane tilted {tilt:.1f} deg (> {MAX_TILT_DEG} deg)"
        pusher = objects.get("pusher") or {}
        moving = getattr((meshes or {}).get("pusher"), "dofs", None)
        if pusher.get("geometry", "primitive") == "robot" and moving:
            return False, (
                f"the robot pusher moves {', '.join(moving)} (moving fingers touch the objects: "
                "grasp by contact; the planar model pushes with one rigid sphere or capsule, "
                "the mujoco engine drives each moving link with its own servo)"
            )
        if pusher.get("geometry", "primitive") != "primitive":
            return False, (
                f"objects.pusher.geometry is {pusher.get('geometry')!r} (the planar model "
                "pushes with a sphere or capsule; the robot's links need the mujoco engine)"
            )
        if pusher.get("shape") not in (None, "sphere", "capsule"):
            return False, f"pusher shape {pusher.get('shape')!r} (sphere or capsule only)"
        if float(pusher.get("friction_dynamic") or 0.0) > 0.0:
            return False, "the pusher has friction (the planar pusher is frictionless)"
        return True, "one box, horizontal plane, frictionless sphere/capsule pusher"

    def rollout(
        self,
        drive: Drive,
        initial: Mapping[str, ObjectState] | None = None,
        params: Mapping[str, Sequence[float]] | None = None,
    ) -> Predicted:
        """Poses of the box at ``drive.obs_t`` (its initial pose, velocity and yaw rate from
        ``initial`` when given: the quaternion's yaw and omega's z are used, roll and pitch are
        not modelled)."""
        key = f"objects.{self.object_name}.friction_dynamic"
        unknown = set(params or {}) - {key}
        if unknown:
            raise InputError(
                f"parameter(s) {', '.join(sorted(unknown))} cannot be set on the planar engine",
                where="params",
                hint=f"settable: {key}",
            )
        mu = np.atleast_1d(np.asarray((params or {}).get(key, [self.scene.friction_dynamic])))
        theta = torch.as_tensor(np.repeat(self.space.zero[None], len(mu), 0), dtype=torch.float64)
        theta[:, self.space.index(BASE, "friction_dynamic")] = torch.as_tensor(mu)
        st = (initial or {}).get(self.object_name)
        if st is not None:
            from robogs.physics.engines.base import quat_yaw

            drive = Drive(**{**drive.__dict__})
            drive.init_pos = torch.as_tensor(np.asarray(st.pos, float))
            drive.init_yaw = torch.as_tensor(quat_yaw(np.asarray(st.quat, float)))
            if st.vel is not None:
                drive.init_vel = torch.as_tensor(np.asarray(st.vel, float))
            if st.omega is not None:  # the yaw rate; roll and pitch rates are not modelled
                drive.init_rate = torch.as_tensor(np.asarray(st.omega, float)[:, 2])
        with torch.no_grad():
            res = simulate(theta, self.space, drive, self.scene)
        pos = res.pos.numpy()
        return Predicted({self.object_name: pos}, {self.object_name: yaw_quat(res.yaw.numpy())}, [])


def _register() -> None:
    from robogs.physics.engines import register_engine

    register_engine(PlanarEngine)


_register()

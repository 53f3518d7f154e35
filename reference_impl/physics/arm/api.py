"""Dataset-level entry points of the arm torque model: compare, diagnose, fit --add.

Example:
    >>> from reference_impl.physics.arm import diagnose_arm, fit_arm   # doctest: +SKIP
    >>> report = diagnose_arm("scene/")                                # doctest: +SKIP
    >>> fit_arm("scene/", ["joint_friction"])                          # doctest: +SKIP
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from reference_impl.physics.arm import effects as _effects  # noqa: F401  (registers the arm effects)
from reference_impl.physics.arm.compare import base_prediction, compare_torques
from reference_impl.physics.arm.diagnose import diagnose_torques
from reference_impl.physics.arm.effects import ArmEffect
from reference_impl.physics.arm.held import freeze_joints, held_joints
from reference_impl.physics.arm.identify import expand_effects, fit_effects
from reference_impl.physics.arm.rnea import ArmModel
from reference_impl.physics.arm.torque_model import (
    ArmProblem,
    fixed_effects,
    load_arm_data,
    prepare_arm,
)
from robogs_format.dataset import Dataset
from robogs_format.errors import FormatError

__all__ = ["ArmSession", "open_arm", "compare_arm", "diagnose_arm", "fit_arm"]


@dataclass
class ArmSession:
    """A dataset opened for the arm torque model.

    Attributes:
        dataset, model, physics (current physics.json or None), fixed (arm effects already in
        it), problem (prepared data).
    """

    dataset: Dataset
    model: ArmModel
    physics: dict[str, Any] | None
    fixed: dict[str, dict[str, float]]
    problem: ArmProblem


def open_arm(
    path: str | Path | Dataset,
    *,
    payload_link: str | None = None,
    device: torch.device | str | None = None,
) -> ArmSession:
    """Read the robot, the physics and the joint logs with efforts of a dataset.

    Joints logged without efforts at a constant position (``hold`` in the tabular import) are
    fixed at that position in the model (:mod:`.held`).

    Args:
        path: dataset folder (or an open Dataset).
        payload_link: link carrying a payload (default: physics.json ``payload.link``, then the
            manifest's ``ee_link``, then the last moving link).
        device: torch device for the model tensors.
    """
    ds = path if isinstance(path, Dataset) else Dataset.open(path)
    urdf = ds.urdf(load_meshes=False)
    held = held_joints(ds, ArmModel.from_urdf(urdf).joint_names)
    model = ArmModel.from_urdf(freeze_joints(urdf, held))
    try:
        physics = ds.physics()
    except FormatError:
        physics = None
    link = (
        payload_link
        or ((physics or {}).get("payload") or {}).get("link")
        or (ds.manifest.get("robot") or {}).get("ee_link")
    )
    if link is not None and link not in model.link_body:
        link = None
    data = load_arm_data(ds, model.joint_names)
    pb = prepare_arm(model, data, payload_link=link, device=device)
    return ArmSession(ds, model, physics, fixed_effects(physics, model.joint_names), pb)


def compare_arm(path: str | Path | Dataset, **kwargs: Any) -> dict[str, Any]:
    """Joint-torque residuals of the current model (see :func:`.compare.compare_torques`)."""
    s = open_arm(path)
    out = compare_torques(s.problem, s.fixed, **kwargs)
    out["physics_revision"] = (s.physics or {}).get("revision")
    return out


def diagnose_arm(
    path: str | Path | Dataset, *, candidates: Sequence[str] | None = None, **kwargs: Any
) -> dict[str, Any]:
    """Missing effects by forward selection, ranked (see :func:`.diagnose.diagnose_torques`)."""
    s = open_arm(path)
    out = diagnose_torques(s.problem, s.fixed, candidates=candidates, **kwargs)
    out["physics_revision"] = (s.physics or {}).get("revision")
    return out


def fit_arm(
    path: str | Path | Dataset,
    effects: Sequence[str],
    *,
    write: bool = True,
    note: str | None = None,
) -> dict[str, Any]:
    """Fit ``effects`` together and write them into physics.json as a new revision.

    Friction goes to ``joints.<j>.friction`` (Coulomb, N m) and ``joints.<j>.damping``
    (viscous, N m s/rad), armature to ``joints.<j>.armature`` (kg m^2), the payload to
    ``payload`` (``link``, ``mass_kg``, ``com_m``), other effects to ``effects``; values that
    would be negative are written as 0 (and listed under ``clamped``).

    Returns:
        ``{"revision", "params", "rms_before_nm", "rms_after_nm", "clamped"}``.
    """
    s = open_arm(path)
    pb = s.problem
    fit = fit_effects(pb, effects, fixed=s.fixed)
    sig = pb.sigma.cpu().numpy()
    before = (pb.tau - base_prediction(pb, s.fixed)).cpu().numpy()
    after = fit.resid * sig
    names = pb.data.joint_names
    doc = (
        copy.deepcopy(s.physics)
        if s.physics
        else {"revision": 0, "objects": {}, "gravity_mps2": [0.0, 0.0, -9.81]}
    )
    doc.pop("parent_revision", None)
    doc.pop("note", None)
    clamped: list[str] = []
    params: dict[str, Any] = {}
    for eff in expand_effects(effects, names):
        vals = fit.values(eff.name)
        params[eff.name] = fit.intervals(eff.name)
        clamped += [
            f"{eff.name}.{k}"
            for k, v in vals.items()
            if v < 0 and eff.name in ("joint_friction", "armature")
        ]
        if eff.name == "payload":
            doc["payload"] = {**(doc.get("payload") or {}), "link": pb.ctx.payload_link}
        assert isinstance(eff, ArmEffect)
        eff.write_physics(vals, doc)
    out: dict[str, Any] = {
        "params": params,
        "rms_before_nm": {
            j: float(np.sqrt(np.mean(before[:, k] ** 2))) for k, j in enumerate(names)
        },
        "rms_after_nm": {j: float(np.sqrt(np.mean(after[:, k] ** 2))) for k, j in enumerate(names)},
        "noise_floor_nm": {j: float(sig[k]) for k, j in enumerate(names)},
        "clamped": clamped,
        "revision": None,
    }
    if write:
        with s.dataset.edit() as w:
            out["revision"] = w.set_physics(doc, note=note or f"fit --add {' '.join(effects)}")
            w.commit()
    return out

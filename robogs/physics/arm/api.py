"""Dataset-level entry points of the arm model: compare, diagnose, fit --add.

Two residuals, each used where the data have its stream: joint torques (``joint_states``
with efforts; :mod:`.torque_model`) and end-effector poses (``ee_poses``;
:mod:`.kinematic_model`). Each effect is judged and fitted on its own residual
(``ArmEffect.residual``).

Example:
    >>> from robogs.physics.arm import diagnose_arm, fit_arm   # doctest: +SKIP
    >>> report = diagnose_arm("scene/")                                # doctest: +SKIP
    >>> fit_arm("scene/", ["joint_friction"])                          # doctest: +SKIP
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from robogs.format.dataset import Dataset
from robogs.format.errors import FormatError, InputError
from robogs.physics.arm import effects as _effects  # noqa: F401  (registers the arm effects)
from robogs.physics.arm.compare import base_prediction, compare_torques
from robogs.physics.arm.diagnose import (
    diagnose_kinematic,
    diagnose_torques,
    holdout_folds,
    split_candidates,
    unit_folds,
)
from robogs.physics.arm.effects import ArmEffect, Payload
from robogs.physics.arm.held import freeze_joints, held_joints
from robogs.physics.arm.identify import expand_effects, fit_effects, fit_many, unit_layout
from robogs.physics.arm.kinematic_compare import (
    compare_kinematic,
    orientation_rms_deg,
    position_rms_mm,
)
from robogs.physics.arm.kinematic_model import (
    KinProblem,
    base_residual,
    describe,
    load_kinematic_data,
    prepare_kinematic,
)
from robogs.physics.arm.rnea import ArmModel
from robogs.physics.arm.torque_model import (
    ArmProblem,
    fixed_effects,
    load_arm_data,
    prepare_arm,
)

__all__ = ["ArmSession", "open_arm", "compare_arm", "diagnose_arm", "fit_arm"]

_CLAMPED_AT_ZERO = ("joint_friction", "armature", "joint_elasticity", "backlash")


@dataclass
class ArmSession:
    """A dataset opened for the arm model.

    Attributes:
        dataset, model, physics (current physics.json or None), fixed (arm effects already in
        it), problem (torque data, None without efforts), kin (pose data, None without
        ee_poses), notes (why a residual is unavailable).
    """

    dataset: Dataset
    model: ArmModel
    physics: dict[str, Any] | None
    fixed: dict[str, dict[str, float]]
    problem: ArmProblem | None
    kin: KinProblem | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def has(self) -> set[str]:
        """Streams with a usable residual (``efforts``, ``ee_poses``)."""
        return {n for n, p in (("efforts", self.problem), ("ee_poses", self.kin)) if p is not None}


def open_arm(
    path: str | Path | Dataset,
    *,
    payload_link: str | None = None,
    device: torch.device | str | None = None,
    ee_orientation: bool | None = None,
) -> ArmSession:
    """Read the robot, the physics, the joint logs with efforts and the end-effector poses.

    Joints logged without efforts at a constant position (``hold`` in the tabular import) are
    fixed at that position in the model (:mod:`.held`).

    Args:
        path: dataset folder (or an open Dataset).
        payload_link: link carrying a payload (default: physics.json ``payload.link``, then the
            manifest's ``ee_link``, then the last moving link).
        device: torch device for the model tensors.
        ee_orientation: use the recorded orientation in the pose residual (default: when every
            pose has a unit quaternion); False: positions only.

    Raises:
        InputError: neither joint efforts nor end-effector poses to compare with.
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
    fixed = fixed_effects(physics, model.joint_names)
    has_ee = any(ep.has("ee_poses") for ep in ds.episodes)
    notes: list[str] = []
    pb = kp = None
    try:
        pb = prepare_arm(
            model, load_arm_data(ds, model.joint_names), payload_link=link, device=device
        )
    except InputError as exc:
        if not has_ee:
            raise
        notes.append(f"no torque residual: {exc.message}")
    if has_ee:
        try:
            kd = load_kinematic_data(ds, model, orientation=ee_orientation)
            kp = prepare_kinematic(model, kd, fixed, payload_link=link, device=device)
        except InputError as exc:
            if pb is None:
                raise
            notes.append(f"no pose residual: {exc.message}")
    return ArmSession(ds, model, physics, fixed, pb, kp, notes)


def compare_arm(
    path: str | Path | Dataset, *, ee_orientation: bool | None = None, **kwargs: Any
) -> dict[str, Any]:
    """Residuals of the current model: joint torques (:func:`.compare.compare_torques`, at
    the top level) and end-effector poses (:func:`.kinematic_compare.compare_kinematic`,
    under ``kinematic``), where the data have them."""
    s = open_arm(path, ee_orientation=ee_orientation)
    out: dict[str, Any] = {"model": "arm"}
    if s.problem is not None:
        out.update(compare_torques(s.problem, s.fixed, **kwargs))
    if s.kin is not None:
        out["kinematic"] = compare_kinematic(s.kin, s.fixed, **kwargs)
    out["residuals"] = [r for r, p in (("torque", s.problem), ("kinematic", s.kin)) if p]
    out["notes"] = s.notes
    out["physics_revision"] = (s.physics or {}).get("revision")
    return out


_SHARED = ("n_samples", "n_trajectories", "split", "gate", "selection")


def diagnose_arm(
    path: str | Path | Dataset,
    *,
    candidates: Sequence[str] | None = None,
    ee_orientation: bool | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """Missing effects by forward selection, ranked (see :mod:`.diagnose`).

    Candidates judged on the joint torques and those judged on the end-effector poses are
    selected independently, each on its own residual; a residual whose stream is missing
    skips its candidates with the reason.

    Returns:
        ``effects`` (rows of both, accepted first: the residual whose first accepted effect
        has the lower dBIC first, then by step; the rest by dBIC), ``selected``, ``steps``,
        ``skipped``, ``residuals`` (per residual: its report without the rows) and, at the top
        level, the torque report's figures (``noise_floor_nm``...) or, without efforts, the
        pose report's.
    """
    s = open_arm(path, ee_orientation=ee_orientation)
    groups, skipped = split_candidates(candidates, s.has)
    reports: dict[str, dict[str, Any]] = {}
    if s.problem is not None and (groups["torque"] or candidates is None):
        names = [e.name for e in groups["torque"]]
        reports["torque"] = diagnose_torques(s.problem, s.fixed, candidates=names, **kwargs)
    if s.kin is not None and (groups["kinematic"] or candidates is None):
        names = [e.name for e in groups["kinematic"]]
        reports["kinematic"] = diagnose_kinematic(s.kin, s.fixed, candidates=names, **kwargs)
    accepted: list[list[dict[str, Any]]] = []
    others: list[dict[str, Any]] = []
    for rep in reports.values():
        acc = [r for r in rep["effects"] if r["reported"]]
        if acc:
            accepted.append(acc)
        others += [r for r in rep["effects"] if not r["reported"]]
    accepted.sort(key=lambda rows: rows[0]["delta_bic"])
    others.sort(key=lambda r: r["delta_bic"])
    rows = [r for group in accepted for r in group] + others
    out: dict[str, Any] = {"model": "arm"}
    main = reports.get("torque") or reports.get("kinematic") or {}
    out.update({k: v for k, v in main.items() if k not in ("effects", "skipped", "steps")})
    out.update(
        {
            "selected": [r["name"] for r in rows if r["reported"]],
            "steps": [st for rep in reports.values() for st in rep["steps"]],
            "stop": {k: rep.get("stop") for k, rep in reports.items()},
            "effects": rows,
            "skipped": skipped,
            "residuals": {
                k: {kk: vv for kk, vv in rep.items() if kk not in ("effects", "skipped")}
                for k, rep in reports.items()
            },
            "notes": s.notes,
            "physics_revision": (s.physics or {}).get("revision"),
        }
    )
    return out


def fit_arm(
    path: str | Path | Dataset,
    effects: Sequence[str],
    *,
    write: bool = True,
    note: str | None = None,
    ee_orientation: bool | None = None,
    holdout: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Fit ``effects`` together and write them into physics.json as a new revision.

    Torque effects are fitted on the joint torques, kinematic effects on the end-effector
    poses (after the torque effects, whose payload and mass scale change the gravity torque
    the elasticity sees). Friction goes to ``joints.<j>.friction`` (Coulomb, N m) and
    ``joints.<j>.damping`` (viscous, N m s/rad), armature to ``joints.<j>.armature``
    (kg m^2), the payload to ``payload`` (``link``, ``mass_kg``, ``com_m``), compliance to
    ``joints.<j>.compliance_rad_per_nm``, backlash to ``joints.<j>.backlash_rad``, kinematic
    offsets to ``joints.<j>.offsets`` (``dtheta_rad``, ``dd_m``, ``da_m``), other effects to
    ``effects``. Values that would be negative for friction, armature, compliance and
    backlash are written as 0 (listed under ``clamped``); parameters the data cannot identify
    are not written (listed under ``unidentifiable`` with the reason).

    Returns:
        ``{"revision", "params", "clamped", "unidentifiable"}``, plus ``rms_before_nm``,
        ``rms_after_nm``, ``noise_floor_nm`` (torque effects) and ``ee`` (kinematic effects:
        ``rms_before_mm``, ``rms_after_mm``, ``rms_before_deg``, ``rms_after_deg``,
        ``noise_floor``, ``units``).

    Raises:
        InputError: an effect whose residual the data do not have.
    """
    s = open_arm(path, ee_orientation=ee_orientation)
    names = s.model.joint_names
    effs = expand_effects(effects, names)
    # every active (stored) effect of a fitted residual is refitted jointly with the added ones,
    # as diagnose scores them; model corrections (``refit=False``) stay at their stored values
    kinds = {e.residual for e in effs}
    added = {e.name for e in effs}
    stored = [
        e
        for e in expand_effects(list(s.fixed), names)
        if e.residual in kinds and e.refit and e.name not in added
    ]
    effs = stored + effs
    by_kind = {k: [e for e in effs if e.residual == k] for k in ("torque", "kinematic")}
    for kind, stream, prob in (("torque", "efforts", s.problem), ("kinematic", "ee_poses", s.kin)):
        if by_kind[kind] and prob is None:
            raise InputError(
                f"{', '.join(e.name for e in by_kind[kind])} needs {stream}, not in the data",
                path=s.dataset.root,
                hint="; ".join(s.notes) or f"record {stream}",
            )
    doc = (
        copy.deepcopy(s.physics)
        if s.physics
        else {"revision": 0, "objects": {}, "gravity_mps2": [0.0, 0.0, -9.81]}
    )
    doc.pop("parent_revision", None)
    doc.pop("note", None)
    out: dict[str, Any] = {
        "params": {},
        "clamped": [],
        "unidentifiable": {},
        "revision": None,
        "refitted": [e.name for e in stored],
        "held": sorted(n for n in s.fixed if n not in {e.name for e in effs}),
    }
    fixed = dict(s.fixed)
    if by_kind["torque"]:
        assert s.problem is not None
        fixed.update(_fit_torques(s.problem, by_kind["torque"], s.fixed, doc, out, holdout))
    if by_kind["kinematic"]:
        assert s.kin is not None
        _fit_kinematic(s.kin, by_kind["kinematic"], fixed, doc, out)
    if write:
        with s.dataset.edit() as w:
            out["revision"] = w.set_physics(doc, note=note or f"fit --add {' '.join(effects)}")
            w.commit()
    return out


def _write(
    eff: ArmEffect, vals: dict[str, float], doc: dict[str, Any], out: dict[str, Any]
) -> None:
    out["clamped"] += [
        f"{eff.name}.{k}" for k, v in vals.items() if v < 0 and eff.name in _CLAMPED_AT_ZERO
    ]
    eff.write_physics(vals, doc)


def _fit_torques(
    pb: ArmProblem,
    effs: list[ArmEffect],
    fixed: dict[str, dict[str, float]],
    doc: dict[str, Any],
    out: dict[str, Any],
    holdout: Sequence[str] | None = None,
) -> dict[str, dict[str, float]]:
    """Fit torque effects, write them into ``doc``; return their fitted values (and the
    held-out RMS of the same joint fit per fold: default folds, or ``holdout`` trajectories)."""
    fit = fit_effects(pb, effs, fixed=fixed)
    sig = pb.sigma.cpu().numpy()
    before = (pb.tau - base_prediction(pb, fixed)).cpu().numpy()
    after = fit.resid * sig
    names = pb.data.joint_names
    values = {}
    for eff in effs:
        vals = values[eff.name] = fit.values(eff.name)
        out["params"][eff.name] = fit.intervals(eff.name)
        if isinstance(eff, Payload):  # the payload and the distal-mass correction
            doc[eff.slot] = {**(doc.get(eff.slot) or {}), "link": pb.ctx.payload_link}
        _write(eff, vals, doc, out)

    def rms(x: np.ndarray) -> dict[str, float]:
        return {j: float(np.sqrt(np.mean(x[:, k] ** 2))) for k, j in enumerate(names)}

    out["rms_before_nm"], out["rms_after_nm"] = rms(before), rms(after)
    # held-out: the same joint fit per fold of whole trajectories (as diagnose splits them),
    # each fold's residual on the units it did not see; "before" is the base (nothing fitted)
    layout = unit_layout(pb)
    folds = holdout_folds(pb, layout, holdout) if holdout else unit_folds(layout)
    masks = []
    for f in folds:
        m = np.ones(layout.n_units, bool)
        m[f] = False
        masks.append(m)
    fold_fits = fit_many(pb, [effs] * len(folds), fixed=fixed, masks=masks, layout=layout)
    test = np.concatenate([np.flatnonzero(np.isin(layout.unit, f)) for f in folds])
    held = np.zeros_like(after)
    for f, ff in zip(folds, fold_fits, strict=True):
        rows = np.isin(layout.unit, f)
        held[rows] = ff.resid[rows] * sig
    out["heldout_rms_before_nm"] = rms(before[test])
    out["heldout_rms_after_nm"] = rms(held[test])
    out["heldout_split"] = layout.how + (
        f", held out: {', '.join(holdout)}" if holdout else f", {len(folds)} held-out folds"
    )
    out["noise_floor_nm"] = {j: float(sig[k]) for k, j in enumerate(names)}
    return values


def _fit_kinematic(
    kp: KinProblem,
    effs: list[ArmEffect],
    fixed: dict[str, dict[str, float]],
    doc: dict[str, Any],
    out: dict[str, Any],
) -> None:
    """Fit kinematic effects; write the identifiable parameters into ``doc``."""
    fit = fit_effects(kp, effs, fixed=fixed)
    before = base_residual(kp, fixed)
    after = fit.resid * kp.sigma.cpu().numpy()
    for eff in effs:
        unid = fit.unidentifiable(eff.name)
        out["params"][eff.name] = fit.intervals(eff.name)
        if unid:
            out["unidentifiable"][eff.name] = unid
        vals = {k: v for k, v in fit.values(eff.name).items() if k not in unid}
        _write(eff, vals, doc, out)
    info = describe(kp)
    out["ee"] = {
        "link": info["link"],
        "rms_before_mm": position_rms_mm(before),
        "rms_after_mm": position_rms_mm(after),
        "rms_before_deg": orientation_rms_deg(before),
        "rms_after_deg": orientation_rms_deg(after),
        "noise_floor": info["noise_floor"],
        "units": info["units"],
    }

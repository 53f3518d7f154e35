"""Glue between a prepared recording, the parameter space and the fitter.

:class:`Engine` holds a :class:`~robogs.physics.prepare.Prepared` recording and the
effects already present in its physics.json (they belong to the base model and are refitted
with it). It builds parameter spaces, fits problems, and turns weighted residuals back into
millimetres and degrees.

Rollouts come from one of two backends (``backend``): ``planar``, the batched torch model of
:mod:`robogs.physics.model`, or ``mujoco``, the same scene compiled to MuJoCo
(:mod:`robogs.physics.engines.mujoco_fit`; every catalogue effect is mapped, see
:mod:`robogs.physics.engines.mujoco_effects`). ``auto`` picks with
:func:`robogs.physics.engines.choose_engine` (planar when it can represent the scene) and keeps
the reason in :attr:`Engine.backend_reason`. Object meshes of the dataset that are not their
``size_m`` box (:mod:`robogs.format.shapes`) are passed to ``can_represent`` and to MuJoCo.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.physics.effects import Effect, get_effect
from robogs.physics.fit import FitOutcome, Problem, ResidualFn, fit_problems
from robogs.physics.planarity import out_of_plane
from robogs.physics.prepare import Prepared, phase_labels, prepare
from robogs.physics.recording import as_recording
from robogs.physics.residuals import residual_fn, weighted_residuals
from robogs.physics.scene import base_params, scene_from_physics
from robogs.physics.space import ParamSpace

__all__ = ["BACKENDS", "Engine", "FitSummary", "recording_backend", "rms_mm", "resolve_backend"]

BACKENDS = ("auto", "planar", "mujoco")
"""Values of ``engine=`` / ``--engine``."""


def resolve_backend(
    physics: dict,
    name: str = "planar",
    *,
    out_of_plane: str | None = None,
    meshes: Mapping[str, Any] | None = None,
) -> tuple[str, str]:
    """``(backend, reason)`` for ``name`` in :data:`BACKENDS` (``auto``: choose_engine).

    ``out_of_plane``: why the recorded object leaves the plane (:mod:`robogs.physics.planarity`),
    None when it stays flat. Only MuJoCo's free joint can follow it: ``auto`` then picks
    ``mujoco`` and ``planar`` is refused. ``meshes``: the objects with a mesh shape (not their
    box, :meth:`robogs.physics.recording.Recording.shapes`), given to ``can_represent``.

    Raises:
        InputError: an unknown name, or a named engine that cannot represent the scene.
    """
    from robogs.physics.engines import choose_engine, get_engine

    if name not in BACKENDS:
        raise InputError(
            f"unknown engine {name!r}", where="--engine", hint=f"one of {', '.join(BACKENDS)}"
        )
    if out_of_plane is not None:
        if name == "planar":
            raise InputError(
                f"the planar engine cannot represent this recording: {out_of_plane}",
                where="--engine",
                hint="use --engine mujoco (or auto, which picks it): its free joint tips and rolls",
            )
        if name == "auto":
            return "mujoco", f"planar cannot represent it: {out_of_plane}; mujoco: free joint"
    if name == "auto":
        return choose_engine(physics, meshes)
    ok, why = get_engine(name).can_represent(physics, meshes)
    if not ok:
        try:
            fix = f"use --engine {choose_engine(physics, meshes)[0]} (or auto, which picks it)"
        except InputError:
            fix = "no registered engine can represent it (robogs plugins lists them)"
        raise InputError(
            f"the {name} engine cannot represent this scene: {why}", where="--engine", hint=fix
        )
    return name, "requested"


def recording_backend(recording: object, name: str = "auto") -> tuple[str, str]:
    """:func:`resolve_backend` for a recording: its scene and its recorded motion (an object
    that tips out of the plane, :func:`robogs.physics.planarity.out_of_plane`), as
    :class:`Engine` resolves it. Every caller that holds the recording uses this."""
    rec = as_recording(recording)
    labels, _ = phase_labels(rec, scene_from_physics(rec.physics, rec.object_name))
    tilt = out_of_plane(rec, labels).reason()
    return resolve_backend(rec.physics, name, out_of_plane=tilt, meshes=rec.shapes().meshes)


def rms_mm(raw: np.ndarray, mask: np.ndarray) -> float:
    """RMS of the 3-D position error [mm] over valid samples; ``raw`` [T, N, 4] m / rad."""
    sel = raw[mask][:, :3]
    if sel.size == 0:
        return 0.0
    return float(np.sqrt(np.mean(np.sum(sel**2, axis=-1))) * 1000.0)


@dataclass
class FitSummary:
    """A fitted model: its outcome, space columns and errors in measurement units."""

    outcome: FitOutcome
    free: list[int]
    rms_mm: float
    rms_deg: float


class Engine:
    """Fit models of one recording.

    Args:
        recording: a Recording or any recording-like object.
        dt: simulation step [s].
        backend: ``planar``, ``mujoco`` or ``auto`` (see the module docstring).
        threads: MuJoCo rollout threads; None (default): torch's intra-op thread count, which
            every verb sets deliberately (``--threads``), so one setting sizes both engines.

    Attributes:
        shapes: the recording's object meshes that are not their ``size_m`` box
            (:class:`robogs.format.shapes.Shapes`): they make the planar engine refuse the
            scene and reach MuJoCo as convex hulls; ``shapes.notes`` says so, one line each.
    """

    def __init__(
        self,
        recording: object,
        *,
        dt: float = 1e-3,
        backend: str = "planar",
        threads: int | None = None,
    ) -> None:
        if threads is None:
            threads = max(1, torch.get_num_threads())
        self.prep: Prepared = prepare(recording, dt=dt)
        self.tilt = out_of_plane(self.prep.rec, self.prep.labels)  # roll/pitch from the data
        tipped = self.tilt.reason()
        self.shapes = self.prep.rec.shapes()  # object meshes that are not their box
        self.backend, self.backend_reason = resolve_backend(
            self.prep.rec.physics, backend, out_of_plane=tipped, meshes=self.shapes.meshes
        )
        self._mujoco = None
        if self.backend == "mujoco":
            from robogs.physics.engines.mujoco_engine import drive_pusher_speed
            from robogs.physics.engines.mujoco_fit import MujocoFit

            self._mujoco = MujocoFit(
                self.prep.rec.physics,
                self.prep.rec.object_name,
                dt=dt,
                threads=threads,
                tracked=self.prep.tracked,
                meshes=self.shapes.meshes,
                pusher_speed=drive_pusher_speed(self.prep.drive),  # sizes the onset ramp
                joints="auto" if tipped is None else "free",
            )  # it predicts the pusher force: a measured wrench enters as on planar
        self.present: list[tuple[Effect, dict[str, float]]] = []
        for entry in self.prep.rec.physics.get("effects", []) or []:
            eff = get_effect(str(entry["name"]))
            self.present.append((eff, {k: float(v) for k, v in entry.get("params", {}).items()}))
        mask = self.prep.mask.numpy()
        self.mask = mask
        sig = torch.cat([self.prep.sig_pos, self.prep.sig_yaw.unsqueeze(-1)], dim=-1)
        self.sig = sig.numpy().reshape(self.prep.n_traj, -1)  # [T, N*4]

    def notes(self, effects: Sequence[str] = ()) -> list[str]:
        """What the engine simulates instead of what the dataset says, one line each: object
        meshes taken as convex hulls (``shapes.notes``) and, on MuJoCo, effects among
        ``effects`` and those already in physics.json that it plays another way
        (:meth:`~robogs.physics.engines.mujoco_fit.MujocoFit.notes`)."""
        out = list(self.shapes.notes)
        if self._mujoco is not None:
            out += self._mujoco.notes({e.name for e, _ in self.present} | set(effects))
        return out

    # ---- spaces ---------------------------------------------------------------------------
    def space(self, candidates: Sequence[Effect]) -> ParamSpace:
        """Base parameters (on MuJoCo with the other tracked objects' table frictions) +
        present effects + ``candidates`` (each once)."""
        effs = [e for e, _ in self.present]
        names = {e.name for e in effs}
        for c in candidates:
            if c.name not in names:
                effs.append(c)
                names.add(c.name)
        extra = [] if self._mujoco is None else self._mujoco.extra_params()
        return ParamSpace([*base_params(self.prep.scene), *extra], effs)

    def base_columns(self, space: ParamSpace) -> list[int]:
        """Columns always refitted: base parameters and the effects already in physics.json."""
        cols = space.owner_columns("base")
        for e, _ in self.present:
            cols += space.owner_columns(e.name)
        return cols

    def start(self, space: ParamSpace) -> np.ndarray:
        """Start vector: zero values, with present effects at their stored values."""
        th = space.zero.copy()
        for e, vals in self.present:
            for k, v in vals.items():
                th[space.index(e.name, k)] = v
        return th

    def needs_missing(self, effect: Effect) -> list[str]:
        """The ``needs`` of ``effect`` that the data does not meet."""
        return [n for n in effect.needs if n not in self.prep.excitation]

    # ---- fitting --------------------------------------------------------------------------
    def fit(
        self,
        space: ParamSpace,
        problems: Sequence[Problem],
        *,
        progress: Callable[[int, int], None] | None = None,
        max_iter: int = 20,
        residual: ResidualFn | None = None,
    ) -> list[FitOutcome]:
        """Fit problems over ``space`` (all at once); intervals include the leave-one-trajectory-
        out jackknife (``fit_problems(cluster_jackknife=True)``): a release speed off by encoder
        noise shifts a whole slide, and a few fast slides carry most of the drag information.
        ``residual``: fit this function of :meth:`residual_fn`'s instead (the gate's null
        draws, :func:`robogs.physics.gate.draw_offset`)."""
        fn = self.residual_fn(space) if residual is None else residual
        step = None if self._mujoco is None else self._mujoco.fd_rel_step  # None: the default
        return fit_problems(
            fn,
            space,
            problems,
            n_traj=self.prep.n_traj,
            progress=progress,
            max_iter=max_iter,
            cluster_jackknife=True,
            **({} if step is None else {"rel_step": step}),
        )

    def residual_fn(self, space: ParamSpace) -> ResidualFn:
        """``fn(theta [M, Q], local [M, T, 3]) -> weighted residuals`` on the chosen backend."""
        if self._mujoco is None:
            return residual_fn(self.prep, space)
        sim, prep = self._mujoco, self.prep

        def fn(theta: torch.Tensor, local: torch.Tensor) -> torch.Tensor:
            out = sim.simulate(theta, space, prep.drive, prep.scene, init_offset=local)
            return weighted_residuals(out, prep)

        return fn

    def evaluate(self, space: ParamSpace, thetas: np.ndarray, locals_: np.ndarray) -> np.ndarray:
        """Weighted residuals [M, T, N*4] of parameter sets ``thetas`` [M, Q]."""
        fn = self.residual_fn(space)
        with torch.no_grad():
            return fn(torch.as_tensor(thetas), torch.as_tensor(locals_)).numpy()

    def raw(self, weighted: np.ndarray) -> np.ndarray:
        """Weighted residuals [..., T, N*4 (+ force block)] -> raw pose [..., T, N, 4] (m, rad)."""
        r = weighted[..., : self.sig.shape[-1]] * self.sig
        return r.reshape(*r.shape[:-1], -1, 4)

    def summarise(self, out: FitOutcome, free: list[int]) -> FitSummary:
        raw = self.raw(out.resid)
        yaw = raw[self.mask][:, 3]
        return FitSummary(
            out, free, rms_mm(raw, self.mask), float(np.degrees(np.sqrt(np.mean(yaw**2))))
        )

    def check_effects(self, names: Sequence[str]) -> list[Effect]:
        """Registered rigid-model effects by name (InputError for unknown or foreign ones)."""
        out = []
        for n in names:
            e = get_effect(n)
            if e.model != "rigid":
                raise InputError(
                    f"effect {n!r} belongs to the {e.model!r} model, not to the rigid-object model",
                    where="effects",
                )
            out.append(e)
        return out

"""Smooth start-pose (nuisance) columns for the gate, the stencil chosen from the data.

The fitter differentiates each trajectory's start pose forward by one small step
(:func:`robogs.physics.fit.fit_problems`' ``local_h``: 0.1 mm, 0.1 mm, 1 mrad). On MuJoCo a
shift that small moves a contact onset by a fraction of a 1 ms step, so the forward difference
lands on the onset's jump or misses it: the column is rough. The gate profiles these columns out
of every trajectory's residual (:mod:`robogs.physics.gate`), and a rough column removes an
arbitrary part of it, the effect-aligned part included (design-B null seed 1, pusher pair
3 x 1.7: the tilt's wild-null threshold 16.8 sigma^2 with the fitter's columns, 30.5 with
central differences over 30 steps, planar 51.8; bench/RESULTS.md, issue 16, h47). The fits keep
the fitter's step (a wider one moved them: h47, "2. A fix?"); only the gate's linearisation
takes the columns from here.

Columns (:func:`stencil_columns`, one batched rollout of ``2 L S`` rows): the fitter's forward
column ``F``, then central differences ``C_m = (r(a + m h) - r(a - m h)) / (2 m h)`` at the
stencils ``m`` of :data:`STENCILS` (multiples of the fitter's step ``h``), per trajectory and
nuisance dimension.

Rule (:func:`choose_columns`): along the chain ``F, C_1, C_3, C_10, C_30`` take the first
column that agrees with *every* wider one; the widest agrees with itself. Agreement is measured
as the angle ``theta`` between two columns, because the gate uses a column only through the
projection that profiles it out, which its scale does not change. Two columns agree when
``2 sin(theta) chi2_t <= 1``, ``chi2_t = ||r_t||^2`` the base fit's whitened chi^2 of that
trajectory: the projections ``I - q q^T`` of two unit columns differ by exactly ``sin(theta)``
in operator norm, so the trajectory's profiled residual moves by at most ``sin(theta) ||r_t||``
and its profiled chi^2 by at most ``2 sin(theta) chi2_t``. Every statistic of the gate (fits'
chi^2 falls, held-out falls, their nulls) is a difference of such profiled chi^2, read to one
sigma^2 (one parameter's worth of evidence); a change under that is one the data cannot resolve.
The tolerance is the data's: sin 0.0013 on design B's 400-sample trajectories, tighter with more
samples, any angle where ``chi2_t <= 1/2``.

Why every wider stencil and not the next one: on a staircase (a contact onset every ``D`` of the
step) the narrow columns agree with each other wherever no onset falls within their reach, and
all miss the onsets' average slope. A first, looser rule (the next two columns, within
``sin(theta) ||r_t|| <= 1``, the residual's one-sigma bound) kept such columns: on design-B null
seed 1 (MuJoCo, 4 ms x 2) 22 of 27 tilt columns stayed the fitter's, up to sin 0.10 from the
central 30 one, and the tilt's wild null on planar's residual with MuJoCo's columns read 29.2
sigma^2 against 39.6 with central 30 everywhere; with this rule 39.5 (3 x 1.7: 51.6 against
planar's own 51.8; bench/RESULTS.md, h48). The cost: a smooth column curved at the scale of the
widest stencil disagrees with it and is replaced by a wider one (planar design B: thresholds
move by under 1 %).

Roughness (:class:`NuisanceColumns`): the fitter's column against the one chosen, as the sine
of their angle and as h47's ``||F - C|| / ||C||``, per trajectory and dimension; diagnose puts
them in the gate's record (``DiagnoseResult.gate["nuisance_columns"]``).

Central differences of a staircase converge to its mean slope as the stencil widens
(the smoothing of a noisy function's derivative by a wider difference: Moré & Wild 2012,
"Estimating derivatives of noisy simulations", ACM TOMS 38).

Behind :data:`SMOOTH_NUISANCE`, off for the default (wild) gate: measured end to end on
MuJoCo it lost a found effect (design A table tilt seed 0: the unscaled tilt null 2246 -> 4148
sigma^2) and made a design-B null report restitution (seed 4), while design A's Stribeck and
anisotropic-friction false positives stayed (bench/RESULTS.md, issue 16/17, h48).

Always on for the parametric null (:data:`SMOOTH_NUISANCE_METHODS`, :func:`smooth_for`; h99).
Its input columns are the residual's responses to the drive's own error
(:mod:`robogs.physics.drive_noise`), and about 96 % of them lies in the span of the base and
start-pose columns, which the gate profiles out: the null is set by the remainder, and a
start-pose column turned by an angle ``theta`` moves that remainder by up to ``sin(theta)``
times the whole response, several times the remainder's own size at MuJoCo's ``sin`` 0.05-0.17.
Design-B null seed 1, tilt threshold (sigma^2; planar 111.4): MuJoCo with the fitter's columns
30.2, with central columns at 1, 3, 10, 30, 100 steps 27.5, 96.8, 101.4, 104.3, 101.9, with
this module's rule 104.2 (bench/RESULTS.md, issue 17, h99). Matching the stencil to the drive
error's own scale does not work: the start-pose coefficients of its responses are 0.01-0.04 mm
on the pushes (0.1-0.4 mm on the slides), under the fitter's step, where MuJoCo's columns are
rough (central 1: 27.5).
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from robogs.physics.fit import ResidualFn, fit_problems

__all__ = [
    "SMOOTH_NUISANCE",
    "SMOOTH_NUISANCE_METHODS",
    "smooth_for",
    "STENCILS",
    "NuisanceColumns",
    "fitter_local_h",
    "stencil_columns",
    "choose_columns",
    "smooth_nuisance",
    "sin_angle",
]

SMOOTH_NUISANCE = False
"""Whether :func:`robogs.physics.diagnose.diagnose_recording`'s gate linearises each
candidate's start-pose columns with :func:`smooth_nuisance` instead of the fitter's."""

SMOOTH_NUISANCE_METHODS = ("parametric",)
"""Gate methods (:data:`robogs.physics.gate.METHODS`) whose nuisance columns come from
:func:`smooth_nuisance` whatever :data:`SMOOTH_NUISANCE` says (module docstring, h99)."""


def smooth_for(method: str) -> bool:
    """Whether the gate of ``method`` linearises the start-pose columns with
    :func:`smooth_nuisance` (:data:`SMOOTH_NUISANCE` or a method of
    :data:`SMOOTH_NUISANCE_METHODS`) rather than taking the fitter's."""
    return bool(SMOOTH_NUISANCE) or method in SMOOTH_NUISANCE_METHODS


STENCILS = (1, 3, 10, 30)
"""Central-difference stencils, multiples of the fitter's nuisance step (0.1 mm to 3 mm in
position, 1 to 30 mrad in yaw)."""


def fitter_local_h() -> np.ndarray:
    """The fitter's nuisance steps ``local_h`` (read from :func:`fit_problems`, not copied)."""
    return np.asarray(inspect.signature(fit_problems).parameters["local_h"].default, float)


@dataclass
class NuisanceColumns:
    """The stencil chosen per trajectory and nuisance dimension, and the fitter's roughness.

    Attributes:
        stencil: [T, L] multiple of the fitter's step chosen; 0: the fitter's forward column.
        sin_fwd: [T, L] sine of the angle between the fitter's column and the one chosen.
        rel_fwd: [T, L] ``||F - C|| / ||C||`` (h47's measure), C the column chosen.
        tol: [T] the sine two columns may differ by (``1 / (2 chi2_t)``; inf: any).
        unresolved: [T, L] no narrower column agreed with every wider one; the widest taken.
        rows, seconds: the rollout's rows and its wall time.
    """

    stencil: np.ndarray
    sin_fwd: np.ndarray
    rel_fwd: np.ndarray
    tol: np.ndarray
    unresolved: np.ndarray
    rows: int = 0
    seconds: float = 0.0
    stencils: tuple[int, ...] = field(default=STENCILS)

    def to_dict(self) -> dict[str, Any]:
        labels = [0, *self.stencils]
        count = {
            ("fitter" if m == 0 else f"central {m}"): int(np.sum(self.stencil == m)) for m in labels
        }
        return {
            "stencil_counts": count,
            "unresolved": int(np.sum(self.unresolved)),
            "max_sin_fwd": float(np.max(self.sin_fwd, initial=0.0)),
            "max_rel_fwd": float(np.max(self.rel_fwd, initial=0.0)),
            "stencil": self.stencil.astype(int).tolist(),
            "rel_fwd": np.round(self.rel_fwd, 4).tolist(),
            "sin_fwd": np.round(self.sin_fwd, 4).tolist(),
            "rows": self.rows,
            "seconds": self.seconds,
        }


def sin_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sine of the angle between columns ``a`` and ``b`` [..., K] -> [...] (0 where either is 0)."""
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    den = na * nb
    cos = np.divide(np.sum(a * b, axis=-1), den, out=np.ones_like(den), where=den > 0)
    return np.sqrt(np.clip(1.0 - cos**2, 0.0, 1.0))


def stencil_columns(
    fn: ResidualFn,
    theta: np.ndarray,
    local: np.ndarray,
    *,
    local_h: Sequence[float] | None = None,
    stencils: Sequence[int] = STENCILS,
) -> np.ndarray:
    """Central-difference nuisance columns at each stencil from ONE batched rollout.

    Args:
        fn: weighted residual function ``fn(theta [M, Q], local [M, T, L]) -> [M, T, K]``.
        theta: [Q] the fit's global parameters.
        local: [T, L] its nuisance parameters.
        local_h: the base steps (default: the fitter's, :func:`fitter_local_h`).
        stencils: multiples of the step.

    Returns:
        [S, T, K, L]: ``(r(a + m h e_d) - r(a - m h e_d)) / (2 m h_d)``, every trajectory's
        dimension ``d`` shifted in the same row (trajectories do not interact).
    """
    h = fitter_local_h() if local_h is None else np.asarray(local_h, float)
    n_l = local.shape[1]
    if h.shape != (n_l,):
        raise ValueError(f"local_h has {h.shape[0]} steps for {n_l} nuisance dimensions")
    locs = []
    for m in stencils:
        for d in range(n_l):
            for sgn in (1.0, -1.0):
                lo = np.array(local, float)
                lo[:, d] += sgn * m * h[d]
                locs.append(lo)
    th = torch.as_tensor(np.repeat(np.asarray(theta, float)[None], len(locs), 0))
    with torch.no_grad():
        out = fn(th, torch.as_tensor(np.stack(locs))).cpu().numpy()
    out = out.reshape(len(stencils), n_l, 2, *out.shape[1:])  # [S, L, 2, T, K]
    steps = 2.0 * np.asarray(stencils, float)[:, None] * h[None, :]  # [S, L]
    cols = (out[:, :, 0] - out[:, :, 1]) / steps[:, :, None, None]  # [S, L, T, K]
    return np.moveaxis(cols, 1, -1)


def choose_columns(
    fwd: np.ndarray,
    central: np.ndarray,
    resid: np.ndarray,
    valid: np.ndarray,
    stencils: Sequence[int] = STENCILS,
) -> tuple[np.ndarray, NuisanceColumns]:
    """The rule of the module docstring.

    Args:
        fwd: [T, K, L] the fitter's forward columns.
        central: [S, T, K, L] central columns at ``stencils`` (:func:`stencil_columns`).
        resid: [T, K] the base fit's whitened residual (sets each trajectory's tolerance).
        valid: [T, K] entries that are samples.

    Returns:
        (columns [T, K, L], the record).
    """
    if central.shape[0] != len(stencils) or central.shape[1:] != fwd.shape:
        raise ValueError(
            f"central columns {central.shape} do not match {len(stencils)} stencils of "
            f"the forward columns {fwd.shape}"
        )
    v = np.asarray(valid, bool)[..., None]
    chain = np.concatenate([fwd[None], central], 0) * v[None]  # [S+1, T, K, L]
    t_n, _, n_l = fwd.shape
    chi2 = np.sum((resid * valid) ** 2, axis=-1)  # [T]
    tol = np.divide(1.0, 2.0 * chi2, out=np.full(t_n, np.inf), where=chi2 > 0.5)
    lcols = np.moveaxis(chain, -1, -2)  # [S+1, T, L, K]
    n_c = chain.shape[0]
    pick = np.full((t_n, n_l), n_c - 1)
    unresolved = np.ones((t_n, n_l), bool)  # only the widest agrees with every wider one
    for i in range(n_c - 2, -1, -1):  # the first i that qualifies wins: go from the end
        ok = np.all(sin_angle(lcols[i][None], lcols[i + 1 :]) <= tol[None, :, None], axis=0)
        pick = np.where(ok, i, pick)
        unresolved &= ~ok
    zero = ~np.any(chain[0] != 0, axis=1)  # a dimension the trajectory does not feel: keep F
    pick = np.where(zero, 0, pick)
    unresolved &= ~zero
    out = np.take_along_axis(chain, pick[None, :, None, :], axis=0)[0]
    f = np.moveaxis(chain[0], -1, -2)  # [T, L, K]
    c = np.moveaxis(out, -1, -2)
    nc = np.linalg.norm(c, axis=-1)
    rel = np.divide(np.linalg.norm(f - c, axis=-1), nc, out=np.zeros_like(nc), where=nc > 0)
    labels = np.asarray([0, *stencils])
    rec = NuisanceColumns(
        stencil=labels[pick],
        sin_fwd=np.where(pick == 0, 0.0, sin_angle(f, c)),
        rel_fwd=rel,
        tol=tol,
        unresolved=unresolved,
        stencils=tuple(int(m) for m in stencils),
    )
    return np.where(pick[:, None, :] == 0, fwd, out), rec


def smooth_nuisance(
    fn: ResidualFn,
    theta: np.ndarray,
    local: np.ndarray,
    fwd: np.ndarray,
    resid: np.ndarray,
    valid: np.ndarray,
    *,
    stencils: Sequence[int] = STENCILS,
) -> tuple[np.ndarray, NuisanceColumns]:
    """The gate's nuisance columns [T, K, L] of a fit at ``(theta, local)`` whose forward
    columns are ``fwd`` (the fitter's ``jac_local``): :func:`stencil_columns` then
    :func:`choose_columns` (``resid``, ``valid``: the base fit's whitened residual and its
    samples). Where the fitter's column is chosen it is returned bit for bit."""
    t0 = time.perf_counter()
    central = stencil_columns(fn, theta, local, stencils=stencils)
    cols, rec = choose_columns(fwd, central, resid, valid, stencils)
    rec.rows = 2 * local.shape[1] * len(stencils)
    rec.seconds = time.perf_counter() - t0
    return cols, rec

"""The drive's own measurement error, as the gate's parametric null simulates it (issue 17).

The pusher path the model is driven by is measured (encoders through the arm's kinematics, or a
tracked tool) and smoothed (:func:`robogs.physics.prepare.build_drive`: a degree-4 tricube local
polynomial over the position window, its derivative over the carry window). What the smoother
keeps of the path's white noise is a smooth error of the whole push: a release speed off by a
few mm/s shifts a whole slide, an error shared by every pose sample of one trajectory that the
camera's white noise does not have.

This module draws that error from a model of its source, with nothing tuned on a generator:

- the path's noise ``s`` per axis and its rate come from the recording's own path
  (:func:`robogs.physics.smoothing.drive_windows`: the MAD of second divided differences,
  :func:`robogs.physics.smoothing.path_noise`), and so do the two windows;
- a draw is white noise of deviation ``s`` at each trajectory's own path stamps, put through
  the same smoother and the same resampling onto the simulation grid as the measured path
  (linear in the noise, so the draw is exactly the drive error that noise makes);
- :func:`drive_response` turns ``M`` such draws into the whitened residual's response to each
  (one rollout per draw, every trajectory at once: a trajectory's residual depends only on its
  own drive). Their ``1/M`` weighted outer products are a Monte Carlo estimate of the
  residual's covariance from the drive error, ``G Cov(dp) G^T`` (``G`` the residual's
  Jacobian with respect to the drive), without forming ``G`` (``S x 3`` columns a trajectory).

The gate draws ``e = white + J_in delta``, ``delta ~ N(0, I / M)`` per trajectory
(:func:`robogs.physics.gate.calibrate`, ``method="parametric"``): a parametric bootstrap of the
fitted base model with this dataset's design, noise, jitter and drops, linearised like the rest
of the gate (Efron & Tibshirani 1993, "An Introduction to the Bootstrap", ch. 6; the drive
error's propagation is the errors-in-variables term of a linearised model, e.g. Carroll,
Ruppert, Stefanski & Crainiceanu 2006, "Measurement Error in Nonlinear Models", ch. 4).

Checked against the truth (h85, bench/RESULTS.md, issue 17): on design-B null seeds 0-7 the
one-sided responses' trace is 1.03 +- 0.03 of the actual drive error's expectation (96 fresh
realisations of the generator's path noise a trajectory, around the noise-free drive); central
differences ``(r(+d) - r(-d)) / 2`` give 0.91 (they drop the contact's rectification, which the
actual error has) and a quarter-size step scaled up 1.45 (the rollout is rough at that scale).
The single realisation a recording holds is skewed (a trajectory's median is about half its
mean), so one recording's drive error often reads well under the model (0.69 on seeds 0-7,
0.95 on seeds 8-23).

Not modelled: the EE yaw's noise (the scenarios' tool yaw is noise-free; a round pusher does
not see it), and anything shared by one trajectory's samples that does not come from the drive
(the simulator's own misfit of a contact, a camera error that changes between trajectories).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import fields, replace
from typing import Any

import numpy as np
import torch

from robogs.physics.model import Drive
from robogs.physics.smoothing import drive_windows, local_polynomial

__all__ = [
    "N_INPUT_DRAWS",
    "BATCH",
    "InputColumns",
    "describe_path_noise",
    "drive_error_draws",
    "perturbed_drive",
    "drive_response",
    "stack_drives",
    "tiled_evaluator",
]

N_INPUT_DRAWS = 48
"""Drive-error draws whose responses make the parametric null's input columns (one rollout
each). The variance along a direction the responses share is estimated to ``sqrt(2 / M)``
(20 % at 48)."""
BATCH = 16
"""Draws evaluated in one rollout by :func:`tiled_evaluator` (the planar engine steps every
trajectory of a batch together, so 16 draws cost about one rollout)."""


class InputColumns(np.ndarray):
    """The parametric null's input columns [T, K, M] (a plain array to every numpy operation)
    with ``note``: what made them, for the calibration's method line
    (:func:`robogs.physics.gate.calibrate` reads it; :func:`describe_path_noise`)."""

    note: str = ""

    def __array_finalize__(self, obj: object) -> None:
        self.note = getattr(obj, "note", "")


def describe_path_noise(info: dict[str, Any]) -> str:
    """The drive error model in words, from :func:`drive_error_draws`'s ``info``: the path noise
    (value, unit, how it was estimated, its rate) and the smoother's windows. A noise-free path
    says so: its draws are zero and the parametric null is white noise alone."""
    s = float(info["path_noise_m"])
    how = (
        "1.4826 MAD of the recorded EE path's second differences, largest axis"
        if info.get("estimated", True)
        else "the reference value: no trajectory has 3 EE samples to estimate it from"
    )
    if s <= 0.0:
        return (
            f"drive path noise 0 um ({how}): the recorded EE path is noise-free, so there is no "
            "drive error to simulate and the null is white noise only"
        )
    return (
        f"drive path noise {s * 1e6:.0f} um per axis at {info['rate_hz']:.0f} Hz ({how}), "
        f"smoothed over {info['window_s'] * 1e3:.0f} / {info['carry_window_s'] * 1e3:.0f} ms"
    )


def drive_error_draws(
    rec: object, t0_ns: np.ndarray, dt: float, n_steps: int, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """``n`` draws of the drive's position and carried-velocity errors on the simulation grid.

    Args:
        rec: the recording (its trajectories' ``ee_t_ns`` [E] and ``ee_pos`` [E, 3] m).
        t0_ns: each trajectory's model time 0 [T] (``Prepared.t0_ns``).
        dt: simulation step [s]; n_steps: grid length ``S``.
        n: draws; seed: their random seed.

    Returns:
        ``(dpos [n, T, S, 3] m, dcarry [n, T, S, 3] m/s, info)``, ``info`` the path noise
        ``s`` [m] per axis, its rate [Hz], the two windows [s] the draws were smoothed with, and
        ``estimated`` (False where no trajectory has the 3 samples :func:`drive_windows` needs:
        ``s`` is then its reference value). :func:`describe_path_noise` puts it in words.
    """
    trs = rec.trajectories
    paths = [((t.ee_t_ns - t.ee_t_ns[0]) * 1e-9, t.ee_pos) for t in trs]
    w_pos, w_ee, s, rate = drive_windows(paths)
    grid = np.arange(n_steps) * dt
    rng = np.random.default_rng(seed)
    dpos = np.zeros((n, len(trs), n_steps, 3))
    dcar = np.zeros((n, len(trs), n_steps, 3))
    for i, tr in enumerate(trs):
        te = (tr.ee_t_ns - int(t0_ns[i])) * 1e-9
        w = rng.standard_normal((len(te), n * 3)) * s  # the smoother is linear: all at once
        p = local_polynomial(te, w, w_pos).reshape(len(te), n, 3)
        v = local_polynomial(te, w, w_ee, deriv=1).reshape(len(te), n, 3)
        for j in range(n):
            for a in range(3):
                dpos[j, i, :, a] = np.interp(grid, te, p[:, j, a])
                dcar[j, i, :, a] = np.interp(grid, te, v[:, j, a])
    info = {
        "path_noise_m": s,
        "rate_hz": rate,
        "window_s": w_pos,
        "carry_window_s": w_ee,
        "estimated": any(len(t.ee_t_ns) >= 3 for t in trs),
    }
    return dpos, dcar, info


def perturbed_drive(drive: Drive, dpos: np.ndarray, dcarry: np.ndarray) -> Drive:
    """``drive`` with its pusher path moved by ``dpos`` [T, S, 3] m (its forward-difference
    velocity with it, as :func:`robogs.physics.prepare.build_drive` makes it) and its carried
    velocity by ``dcarry`` [T, S, 3] m/s."""
    dp = torch.as_tensor(dpos, dtype=drive.pusher.dtype)
    dv = torch.zeros_like(dp)
    dv[:, :-1] = (dp[:, 1:] - dp[:, :-1]) / drive.dt
    carry = drive.pusher_vel if drive.carry_vel is None else drive.carry_vel
    return replace(
        drive,
        pusher=drive.pusher + dp,
        pusher_vel=drive.pusher_vel + dv,
        carry_vel=carry + torch.as_tensor(dcarry, dtype=carry.dtype),
    )


def drive_response(
    evaluate: Callable[[Sequence[Drive]], np.ndarray],
    drive: Drive,
    dpos: np.ndarray,
    dcarry: np.ndarray,
    batch: int = BATCH,
) -> np.ndarray:
    """The whitened residual's response to each drive-error draw, [T, K, n].

    ``evaluate(drives) -> [B, T, K]`` the weighted residual at the base fit's parameters
    (nuisance included) driven by each of ``drives``; column ``j`` is ``evaluate(drive + draw
    j) - evaluate(drive)`` (the draws are at the noise's own size, so this is the response the
    data's own drive error makes, contact events included). ``batch`` draws per call."""
    r0 = np.asarray(evaluate([drive]))[0]
    cols = []
    for a in range(0, len(dpos), batch):
        ds = [
            perturbed_drive(drive, dpos[j], dcarry[j]) for j in range(a, min(a + batch, len(dpos)))
        ]
        cols.extend(np.asarray(evaluate(ds)) - r0[None])
    return np.stack(cols, axis=-1)


def stack_drives(drives: Sequence[Drive]) -> Drive:
    """``B`` drives of the same ``T`` trajectories as one drive of ``B T`` (draw-major)."""
    first = drives[0]
    out = {}
    for f in fields(first):
        x = getattr(first, f.name)
        if isinstance(x, torch.Tensor):
            out[f.name] = torch.cat([getattr(d, f.name) for d in drives], dim=0)
    return replace(first, **out)


def tiled_evaluator(prep: object, space: object, theta: np.ndarray, local: np.ndarray):
    """``evaluate(drives) -> [B, T, K]`` for :func:`drive_response` on the planar engine: the
    ``B`` drives run as one rollout of ``B T`` trajectories (the recording's measurements
    tiled), at parameters ``theta`` [Q] and nuisance ``local`` [T, 3]. None where the
    recording has other tracked objects or a wrench (their blocks are not tiled here)."""
    from robogs.physics.residuals import residual_fn

    if getattr(prep, "tracked", None) or getattr(prep, "wrench", None) is not None:
        return None
    n_t = int(prep.mask.shape[0])

    def evaluate(drives: Sequence[Drive]) -> np.ndarray:
        b = len(drives)

        def tile(x):
            if isinstance(x, torch.Tensor):
                return x.repeat(b, *([1] * (x.dim() - 1)))
            return np.concatenate([x] * b, axis=0)

        big = replace(
            prep,
            drive=stack_drives(drives),
            t0_ns=tile(prep.t0_ns),
            meas_pos=tile(prep.meas_pos),
            meas_yaw=tile(prep.meas_yaw),
            sig_pos=tile(prep.sig_pos),
            sig_yaw=tile(prep.sig_yaw),
            mask=tile(prep.mask),
            phase=tile(prep.phase),
            labels=list(prep.labels) * b,
        )
        fn = residual_fn(big, space)
        lo = torch.as_tensor(np.concatenate([local] * b, axis=0))[None]
        with torch.no_grad():
            r = fn(torch.as_tensor(theta)[None], lo).numpy()[0]
        return r.reshape(b, n_t, -1)

    return evaluate


def drive_inputs(eng: Any, space: Any, base: Any, valid: np.ndarray, key: str) -> np.ndarray:
    """The parametric null's input columns [T, K, M]: the base fit's whitened residual's
    response to ``M`` draws of the drive's own measurement error
    (:func:`drive_error_draws`; draws seeded from the data fingerprint ``key``). ``eng`` is
    the diagnosis's engine (its ``prep``; MuJoCo runs one rollout a draw), ``base`` the base
    fit (``theta``, ``local``), ``valid`` [T, K] the samples kept.

    Returns an :class:`InputColumns` whose ``note`` gives the path noise the draws used
    (:func:`describe_path_noise`; the gate puts it in its method line). A noise-free path
    (noise 0) costs no rollout: its columns are zero, and the gate warns that its null is then
    white noise only."""
    from robogs.physics.residuals import weighted_residuals

    prep = eng.prep
    seed = int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "big")
    n_s = int(prep.drive.pusher.shape[1])
    dpos, dcar, info = drive_error_draws(
        prep.rec, prep.t0_ns, prep.drive.dt, n_s, N_INPUT_DRAWS, seed
    )
    note = describe_path_noise(info)
    if not info["path_noise_m"] > 0.0:
        cols = np.zeros((*np.shape(valid), N_INPUT_DRAWS)).view(InputColumns)
        cols.note = note
        return cols
    evaluate = (
        None if eng._mujoco is not None else tiled_evaluator(prep, space, base.theta, base.local)
    )
    if evaluate is None:  # MuJoCo, or blocks the tiling does not cover: one rollout a draw
        th = torch.as_tensor(base.theta)[None]
        lo = torch.as_tensor(base.local)[None]

        def evaluate(drives):
            out = []
            for d in drives:
                with torch.no_grad():
                    if eng._mujoco is None:
                        from robogs.physics.residuals import residual_fn

                        r = residual_fn(replace(prep, drive=d), space)(th, lo)
                    else:
                        sim = eng._mujoco.simulate(th, space, d, prep.scene, init_offset=lo)
                        r = weighted_residuals(sim, prep)
                out.append(r.numpy()[0])
            return np.stack(out)

    cols = (drive_response(evaluate, prep.drive, dpos, dcar) * valid[..., None]).view(InputColumns)
    cols.note = note
    return cols

"""Design B: a second hidden-effect scenario design that differs from the first in every variable.

=========================  ======================================  ===============================
variable                   design A (:mod:`.generate`)             design B (this module)
=========================  ======================================  ===============================
trajectories               20 (9 pushes, 4 off-centre, 4 slides,   9 (6 pushes in 3 opposite
                           3 drops)                                pairs, 2 slides, 1 drop)
free slide after contact   up to ~130 mm                           <= 60 mm (:data:`MAX_SLIDE_M`)
pusher                     capsule r 10 mm, 40 mm long             sphere r 12 mm
object                     80 x 60 x 50 mm, 0.40 kg, mu_d 0.35     50 x 50 x 40 mm, 0.25 kg,
                                                                   mu_d 0.30, mu_s 0.40
camera                     30 fps, 1 mm, 0.5 deg, jitter 2 ms,     60 fps, 2 mm, 1 deg, jitter
                           no drops                                4 ms, 8 % dropped samples
encoders                   500 Hz, 1e-4 rad                        250 Hz, 2e-4 rad
gaps between trajectories  10 s                                    2-6 s, random
=========================  ======================================  ===============================

Detectability is decided here, from the power of the test the gate makes, with the effect's
noise-level signal as its non-centrality, against white plus drive-path noise
(:func:`detectability`). The noiseless observations
with the effect (``obs_e``) are fitted by the plain model with the parameters the diagnosis
refits on its own: the dynamic friction and each trajectory's start-pose correction (dx, dy,
dyaw), the nuisance parameters that absorb part of an effect. The fit is Gauss-Newton on this
module's own simulator (:func:`plain_fit`: forward differences, one stacked rollout for the
three nuisance columns of every trajectory at once, steps halved until chi^2 falls, stopped
when the linearised minimum is reached within 5 %). Its minimum ``lambda = sum ((obs_e -
obs_0) / sigma)^2`` over the samples kept (times the kept fraction) is the non-centrality of
the likelihood-ratio statistic of adding the effect's ``k`` parameters: on data with the effect
it is distributed as a non-central ``chi^2_k(lambda)`` (noise variance known, the model linear
near the fit; Wilks 1938 and its local alternatives, e.g. Lehmann & Romano 2005, "Testing
Statistical Hypotheses", ch. 13). The gate tests the ``C`` candidates of the catalogue at a
family-wise level ``alpha`` = 5 %; the per-candidate level ``alpha / C`` (Bonferroni; the gate's
min-P level is at least this, 0.0075 measured against 0.005 on design B) gives the critical
value ``c = chi^2_k.isf(alpha / C)`` and the power ``P[chi^2_k(lambda) > c]``
(``scipy.stats.ncx2``): ``power_white``, the power against the camera's white noise alone.

That is not the recording's whole noise. The object is moved by the true pusher path while a
model is driven by the measured one: :data:`DRIVE_NOISE_B` (white, per axis, at every encoder
stamp; the stamps, the EE yaw and the grasp flags are exact), read through a smoother
(:data:`DRIVE_WINDOWS_B`), leaves a smooth error of each push and release that moves whole
slides, and along a dynamics effect's direction it is several times the white noise (h94,
bench/RESULTS.md). :func:`_drive_response` runs :data:`N_DRIVE_DRAWS` noisy drive paths through
this module's own simulator (one-sided, nonlinear responses: the contact's rectification is
kept); their whitened responses, projected on the effect's test space with the same nuisance
columns profiled out (:func:`_effect_subspace`), give its covariance ``D`` there. The statistic
is then ``||a + e||^2``, ``e ~ N(0, I + D)`` (Gaussian and linear, as the gate's parametric
null draws the drive error), its null a weighted sum of chi^2_1 whose quantile at ``alpha / C``
is the critical value, and its power ``power`` (:func:`design_power_full`, by numerical
integration). An effect is **detectable by design when that full-noise power is >= 90 %**
(:data:`POWER_DETECTABLE`). It is an upper bound on the power of the gate's held-out
statistic: the held-out fall of whole trajectories sees less than the in-sample fit, and the
gate's wild-cluster null (a sign per trajectory) cannot reach a p-value below ``2^-(m-1)`` when
only ``m`` trajectories carry the effect; :func:`detectability` also returns ``m`` (trajectories
with ``lambda_t >= 9``, i.e. moved by 3 sigma: the gate's ``AFFECTED_Z``), the fewest ``m`` with
which that null can pass an effect at the level ``alpha / C`` over its ``2^(T-1)`` patterns
(:func:`sign_flip_needs`: 8 of 9 on design B) and a verdict that says which noise decided and
when the power is there but the cluster-robust gate cannot reach the level (restitution and
camera extrinsics on design B); ``detectable`` stays the full-noise power's. On design B the
drive noise turns viscous damping, quadratic drag and Stribeck friction (white-noise power
0.995-1.000) undetectable (0.16, 0.23, 0.86). Cost: the drive draws once per design (about
20-50 s on one loaded core), then a few seconds an effect on top of its plain fit.

The expected ΔBIC, ``E[ΔBIC] ~= -(lambda + k) + k ln n`` (Schwarz 1978, ``n`` the samples
kept), is reported alongside; it no longer decides. The generator shares no code with
``robogs.physics``.

``trajectories`` selects a subset of the nine motions (a smaller design, e.g. five pushes and
slides), for the gate's few-trajectory null.

``quasi_static=True`` replaces the motions by six slow pushes (0.04-0.06 m/s) whose objects
stop within a sample of losing contact: the data of item 6 of issue 17.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robogs.synth.scenarios.generate import (
    FAMILY,
    FINE_DT,
    TRUE_PARAMS,
    ScenarioRecording,
    ScenarioTrajectory,
    _observe,
    _path,
    _quat_mul,
    _quat_yaw,
    _sample,
    _small_rot,
    observed_with_sigma,
)
from robogs.synth.scenarios.motions import Motion, grasp_place, push, release_slide
from robogs.synth.scenarios.sim import EEPath, TruthBox, TruthEffect, simulate_truth

__all__ = [
    "BOX_B",
    "NOISE_B",
    "CAMERA_HZ_B",
    "ENCODER_HZ_B",
    "MAX_SLIDE_M",
    "N_PARAMS",
    "make_design_b",
    "expected_delta_bic",
    "profiled_chi2",
    "plain_fit",
    "detectable_b",
    "detectability",
    "design_power",
    "design_power_full",
    "DRIVE_NOISE_B",
    "DRIVE_WINDOWS_B",
    "N_DRIVE_DRAWS",
    "ALPHA_FAMILY",
    "N_CANDIDATES",
    "POWER_DETECTABLE",
    "MIN_PATTERNS_GATE",
    "sign_flip_needs",
]

BOX_B = TruthBox(
    size=(0.05, 0.05, 0.04),
    mass=0.25,
    mu_s=0.40,
    mu_d=0.30,
    pusher_radius=0.012,
    pusher_length=0.0,
)
"""Object, friction and a sphere pusher of design B."""
CAMERA_HZ_B = 60.0
ENCODER_HZ_B = 250.0
NOISE_B: dict[str, float] = {
    "pos": 2e-3,
    "rot": float(np.radians(1.0)),
    "jitter": 4e-3,
    "encoder": 2e-4,
    "drop": 0.08,
}
"""Camera position [m] and orientation [rad] noise, stamp jitter [s], encoder noise [rad],
fraction of camera samples dropped."""
PUSH_SPEEDS = (0.30, 0.42, 0.36, 0.45, 0.33, 0.39)
"""Release speeds of the six pushes [m/s]: free slides v^2 / (2 mu_d g) of 15-34 mm."""
SLIDE_SPEEDS_B = (0.35, 0.52)
"""Release speeds of the two release-and-slide motions [m/s] (slides of 21-46 mm)."""
MAX_SLIDE_M = 0.06
N_PARAMS = {k: len(v) for k, v in TRUE_PARAMS.items()}
"""Parameters of each effect (the ``k`` of the expected ΔBIC)."""
ALPHA_FAMILY = 0.05
"""Family-wise false-positive rate of the gate (its ``ALPHA``, restated: no code shared)."""
N_CANDIDATES = len(TRUE_PARAMS) - 1
"""Candidates the gate tests at once on design B: every effect of the catalogue."""
POWER_DETECTABLE = 0.9
"""Detectable by design: power of the gate's test at least this (module docstring)."""
MIN_PATTERNS_GATE = 128
"""Fewest sign patterns (``2^(T-1)``) with which the gate's wild null flips a sign per
trajectory (its ``MIN_PATTERNS``, restated: T >= 8); under it the gate uses Webb's weights."""
LAMBDA_ACTS = 9.0
"""A trajectory carries the effect when its share of the non-centrality is >= 9 sigma^2
(moved by 3 sigma, the gate's ``AFFECTED_Z``)."""


Subset = tuple[int, ...] | None
"""Indices of the motions kept (None: all of them)."""
H_FD = (2e-4, 2e-4, 2e-3, 1e-3)
"""Forward-difference steps of the plain fit: start-pose dx, dy [m], dyaw [rad], and the
dynamic friction (relative)."""


def _motions(box: TruthBox, quasi_static: bool, subset: Subset = None) -> list[Motion]:
    out: list[Motion] = []
    speeds = (0.04, 0.05, 0.06, 0.04, 0.05, 0.06) if quasi_static else PUSH_SPEEDS
    for j, v in enumerate(speeds):
        heading = 0.4 + np.pi * (j % 2) + (j // 2) * 2 * np.pi / 3  # three opposite pairs
        out.append(push(box, FINE_DT, heading, float(v), 0.0, f"bpush_{j}", contact=0.03))
    if not quasi_static:
        for j, v in enumerate(SLIDE_SPEEDS_B):
            out.append(release_slide(box, FINE_DT, 2.5 + 2.2 * j, v, f"bslide_{j}"))
        out.append(grasp_place(box, FINE_DT, -0.8, 0.03, "bplace_0"))
    if subset is not None:
        if not subset or any(not 0 <= i < len(out) for i in subset):
            raise ValueError(f"trajectories {subset} must index the {len(out)} motions")
        out = [out[i] for i in subset]
    return out


def _simulate(
    effect: str,
    quasi_static: bool,
    subset: Subset,
    mu_d: float | None,
    offsets: np.ndarray,
    params: dict[str, float] | None = None,
    drive: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Noiseless truth of the motions with ``effect``'s dynamics, once per start-pose offset.

    ``offsets`` [S, T, 3] (dx, dy [m], dyaw [rad] of each trajectory's start pose); returns
    positions [S, T, K, 3] and yaw [S, T, K]: the S copies run as one stacked rollout.
    ``params``: the effect's values (default :data:`TRUE_PARAMS`); ``drive`` [S, T, K, 3] m:
    the pusher's positions of each copy (default the commanded path, as the truth moves).
    """
    motions = _motions(BOX_B, quasi_static, subset)
    path = _path(motions)
    vals = TRUE_PARAMS[effect] if params is None else params
    eff = TruthEffect(effect, dict(vals)) if effect != "none" else TruthEffect()
    dyn = eff if FAMILY[effect] == "contact" else TruthEffect()
    n_s, n_t = offsets.shape[:2]

    def tile(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a] * n_s)

    xy = np.stack([m.box_xy for m in motions])
    yaw0 = np.array([m.box_yaw for m in motions])
    ee = tile(path.pos) if drive is None else drive.reshape(n_s * n_t, *path.pos.shape[1:])
    pos, yaw = simulate_truth(
        BOX_B,
        dyn,
        EEPath(path.dt, ee, tile(path.yaw), tile(path.grasp)),
        tile(xy) + offsets[..., :2].reshape(-1, 2),
        tile(yaw0) + offsets[..., 2].reshape(-1),
        mu_d=mu_d,
    )
    return pos.reshape(n_s, n_t, *pos.shape[1:]), yaw.reshape(n_s, n_t, -1)


@functools.lru_cache(maxsize=32)
def _truth(effect: str, quasi_static: bool, mu_d: float | None, subset: Subset = None):
    motions = _motions(BOX_B, quasi_static, subset)
    pos, yaw = _simulate(effect, quasi_static, subset, mu_d, np.zeros((1, len(motions), 3)))
    return motions, _path(motions), pos[0], yaw[0]


def profiled_chi2(
    effect: str, quasi_static: bool = False, subset: Subset = None, max_iter: int = 6
) -> float:
    """Non-centrality of adding ``effect``: chi^2 [sigma^2] of the noiseless observations with
    the effect against the plain model refitted (dynamic friction and every trajectory's
    start pose), times the kept fraction of samples (module docstring)."""
    return float(np.sum(_profiled_per_trajectory(effect, quasi_static, subset, max_iter)))


@functools.lru_cache(maxsize=64)
def _profiled_per_trajectory(
    effect: str, quasi_static: bool = False, subset: Subset = None, max_iter: int = 6
) -> np.ndarray:
    """Each trajectory's share [T] of :func:`profiled_chi2` (zeros for ``"none"``)."""
    if effect == "none":
        return np.zeros(len(_motions(BOX_B, quasi_static, subset)))
    return _profile(effect, quasi_static, subset, max_iter)["per_traj"]


@functools.lru_cache(maxsize=64)
def _profile(
    effect: str, quasi_static: bool = False, subset: Subset = None, max_iter: int = 6
) -> dict[str, Any]:
    """:func:`_plain_fit` of ``effect``'s noiseless observations (not ``"none"``)."""
    _, _, pos, yaw = _truth(effect, quasi_static, None, subset)
    shift = TRUE_PARAMS[effect].get("delta", 0.0) if effect == "time_offset" else 0.0
    return _plain_fit(pos, yaw, shift, effect, quasi_static, subset, max_iter)


def plain_fit(
    pos: np.ndarray,
    yaw: np.ndarray,
    shift: float,
    effect: str,
    quasi_static: bool = False,
    subset: Subset = None,
    max_iter: int = 6,
) -> tuple[float, float, np.ndarray]:
    """:func:`plain_fit_per_trajectory` without the per-trajectory chi^2."""
    fit = _plain_fit(pos, yaw, shift, effect, quasi_static, subset, max_iter)
    return fit["chi2"], fit["mu"], fit["loc"]


def plain_fit_per_trajectory(
    pos: np.ndarray,
    yaw: np.ndarray,
    shift: float,
    effect: str,
    quasi_static: bool = False,
    subset: Subset = None,
    max_iter: int = 6,
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Fit the plain model to the noiseless truth ``pos`` [T, K, 3], ``yaw`` [T, K] seen through
    ``effect``'s sensor model ``shift`` s late: returns (chi^2 times the kept fraction, the
    dynamic friction, start-pose corrections [T, 3], that chi^2 per trajectory [T]).

    Gauss-Newton on this module's simulator: forward differences (:data:`H_FD`), the three
    nuisance columns of every trajectory from one stacked rollout (trajectories do not
    interact), the step halved until chi^2 falls, stopped when chi^2 is within 5 % of the
    linearised minimum. The chi^2 returned was evaluated, never extrapolated.
    """
    fit = _plain_fit(pos, yaw, shift, effect, quasi_static, subset, max_iter)
    return fit["chi2"], fit["mu"], fit["loc"], fit["per_traj"]


def _plain_fit(
    pos: np.ndarray,
    yaw: np.ndarray,
    shift: float,
    effect: str,
    quasi_static: bool = False,
    subset: Subset = None,
    max_iter: int = 6,
) -> dict[str, Any]:
    """:func:`plain_fit_per_trajectory`, with what the power needs as well: ``resid`` [T, N]
    (whitened residual at the minimum, unit-free), ``jac`` [T N, 1 + 3 T] (whitened Jacobian of
    the prediction w.r.t. the friction and the start poses, from the last Gauss-Newton
    linearisation), ``sig`` [T, N_t, 3] m and ``sig_y`` [T, N_t] rad (the sigmas) and the
    camera times ``t`` [N_t] s."""
    n_t = pos.shape[0]
    t = np.arange(0.0, (pos.shape[1] - 1) * FINE_DT - 0.05, 1 / CAMERA_HZ_B)
    keep = 1.0 - NOISE_B["drop"]
    obs, pe, ye, sig, sig_y = observed_with_sigma(pos, yaw, t, shift, effect, NOISE_B, CAMERA_HZ_B)

    def resid(p: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Whitened residual [T, N] of the plain model's observations ``p``, ``y``."""
        a, b = obs(p, y, 0.0, "none")
        return np.concatenate(
            [((pe - a) / sig).reshape(n_t, -1), ((ye - b) / sig_y).reshape(n_t, -1)], axis=1
        )

    def cost(r: np.ndarray) -> float:
        return keep * float(np.sum(r * r))

    def per_traj(r: np.ndarray) -> np.ndarray:
        return keep * np.sum(r * r, axis=1)

    mu, loc = BOX_B.mu_d, np.zeros((n_t, 3))
    h_mu = H_FD[3] * mu
    best = np.inf
    for _ in range(max_iter):
        offs = np.stack([loc] + [loc + np.eye(3)[j] * H_FD[j] for j in range(3)])
        p, y = _simulate("none", quasi_static, subset, mu, offs)
        pm, ym = _simulate("none", quasi_static, subset, mu + h_mu, loc[None])
        r0 = resid(p[0], y[0])
        if cost(r0) < best:
            best, best_t, best_r = cost(r0), per_traj(r0), r0
        # Jacobian of the prediction: friction column and three nuisance columns per trajectory
        j_mu = (r0 - resid(pm[0], ym[0])) / h_mu  # [T, N]
        j_loc = np.stack([(r0 - resid(p[j + 1], y[j + 1])) / H_FD[j] for j in range(3)], -1)
        n = r0.shape[1]
        jac = np.zeros((n_t, n, 1 + 3 * n_t))
        jac[:, :, 0] = j_mu
        for i in range(n_t):
            jac[i, :, 1 + 3 * i : 4 + 3 * i] = j_loc[i]
        jac = jac.reshape(n_t * n, -1)
        step = np.linalg.lstsq(jac, r0.reshape(-1), rcond=None)[0]
        lin = keep * float(np.sum((r0.reshape(-1) - jac @ step) ** 2))
        for _half in range(4):  # halve the step until chi^2 falls
            mu_n = float(np.clip(mu + step[0], 0.3 * BOX_B.mu_d, 3.0 * BOX_B.mu_d))
            loc_n = loc + step[1:].reshape(n_t, 3)
            pn, yn = _simulate("none", quasi_static, subset, mu_n, loc_n[None])
            c_n = cost(resid(pn[0], yn[0]))
            if c_n < best:
                break
            step = 0.5 * step
        if c_n >= best:
            break
        mu, loc, gain = mu_n, loc_n, best - c_n
        best_r = resid(pn[0], yn[0])
        best, best_t = c_n, per_traj(best_r)
        if best <= 1.05 * lin + 0.5 or gain <= 1e-3 * best:
            break
    return {
        "chi2": float(best),
        "mu": float(mu),
        "loc": loc,
        "per_traj": best_t,
        "resid": best_r,
        "jac": jac,
        "sig": sig,
        "sig_y": sig_y,
        "t": t,
    }


@functools.lru_cache(maxsize=64)
def expected_delta_bic(effect: str, quasi_static: bool = False, subset: Subset = None) -> float:
    """Expected ΔBIC of adding ``effect`` to the plain model on design B (module docstring)."""
    if effect == "none":
        return 0.0
    chi2 = profiled_chi2(effect, quasi_static, subset)
    _, _, pos, _ = _truth(effect, quasi_static, None, subset)
    t = np.arange(0.0, (pos.shape[1] - 1) * FINE_DT - 0.05, 1 / CAMERA_HZ_B)
    n = (1.0 - NOISE_B["drop"]) * 4 * pos.shape[0] * len(t)
    k = N_PARAMS[effect]
    return float(-(chi2 + k) + k * np.log(n))


DRIVE_NOISE_B = 0.6 * NOISE_B["encoder"]
"""White noise [m] per axis of the recorded EE path, at each encoder stamp (:data:`ENCODER_HZ_B`):
the encoders' 2e-4 rad at the tool, as :func:`make_design_b` puts it on ``ee_pos``. It is the
generator's only drive-side noise: the encoder stamps are exact, the EE yaw and the grasp flags
noise-free."""
DRIVE_WINDOWS_B = (0.08, 0.06)
"""How a consumer reads the noisy path [s]: a degree-4 tricube-weighted local polynomial
(Cleveland 1979) over 80 ms for the pusher's positions, its derivative over 60 ms for the
velocity a released object carries. These are the windows the diagnosis uses on design B's path
(its reference windows, never lengthened; restated here, no code shared)."""
N_DRIVE_DRAWS = 96
"""Noisy drive paths simulated for the drive noise's covariance (one stacked rollout per 24)."""


def _local_poly_operator(n: int, period: float, window: float, deriv: int = 0) -> np.ndarray:
    """Linear operator [n, n] of a degree-4 tricube-weighted local polynomial fit of ``n``
    samples ``period`` s apart over ``window`` s (Cleveland 1979, "Robust locally weighted
    regression and smoothing scatterplots", JASA 74): row ``e`` gives the fitted value
    (``deriv`` 0) or first derivative [1/s] (``deriv`` 1) at sample ``e`` from all samples;
    one-sided at the ends."""
    half = 0.5 * window
    idx = np.arange(n)
    out = np.zeros((n, n))
    for e in range(n):
        s = (idx - e) * period / half
        inside = np.abs(s) < 1.0
        w = (1.0 - np.abs(s[inside]) ** 3) ** 3
        v = s[inside, None] ** np.arange(5)  # [m, 5] polynomial basis in the scaled offset
        coef = np.linalg.solve(v.T @ (w[:, None] * v), (w[:, None] * v).T)  # [5, m]
        out[e, inside] = coef[deriv] / (half if deriv else 1.0)
    return out


def _interp_operator(t: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Linear interpolation [len(t), len(knots)] from samples at ``knots`` to times ``t``
    (held constant outside, as ``numpy.interp``)."""
    eye = np.eye(len(knots))
    return np.stack([np.interp(t, knots, eye[j]) for j in range(len(knots))], axis=1)


def _consumer_drives(quasi_static: bool, subset: Subset, noise: np.ndarray) -> np.ndarray:
    """Pusher paths [S, T, K, 3] m as a consumer of a recording drives its model: the commanded
    path sampled at the encoder stamps plus ``noise`` [S, T, E, 3] m, smoothed and interpolated
    onto the fine grid (:data:`DRIVE_WINDOWS_B`). Where the grasp opens, the next fine sample is
    set so that the simulator's finite-difference velocity there is the 60 ms derivative: the
    velocity the released object carries (the pusher is inside the held box then, no contact)."""
    motions = _motions(BOX_B, quasi_static, subset)
    path = _path(motions)
    a_pos, a_vel, enc_t = _drive_operators(path.pos.shape[1])
    samples = np.stack([_sample(path.pos[i], enc_t) for i in range(len(motions))])
    x = samples[None] + noise  # [S, T, E, 3]
    out = np.matmul(a_pos, x)  # [S, T, K, 3]
    for i in range(len(motions)):
        g = path.grasp[i]
        for k in np.nonzero(g[:-1] & ~g[1:])[0]:
            out[:, i, k + 1] = out[:, i, k] + FINE_DT * np.einsum("e,sea->sa", a_vel[k], x[:, i])
    return out


@functools.lru_cache(maxsize=4)
def _drive_operators(n_fine: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The consumer's reading of a path sampled at the encoder stamps, as linear operators
    onto the fine grid of ``n_fine`` steps: positions [K, E], carried velocity [K, E] 1/s, and
    the encoder stamps [E] s."""
    fine_t = np.arange(n_fine) * FINE_DT
    enc_t = np.arange(0.0, (n_fine - 1) * FINE_DT, 1 / ENCODER_HZ_B)
    interp = _interp_operator(fine_t, enc_t)
    a_pos = interp @ _local_poly_operator(len(enc_t), 1 / ENCODER_HZ_B, DRIVE_WINDOWS_B[0])
    a_vel = interp @ _local_poly_operator(len(enc_t), 1 / ENCODER_HZ_B, DRIVE_WINDOWS_B[1], 1)
    return a_pos, a_vel, enc_t


@functools.lru_cache(maxsize=8)
def _drive_response(quasi_static: bool = False, subset: Subset = None) -> np.ndarray:
    """Change [M, T, N_t, 4] of the plain model's noiseless observations (x, y, z [m], yaw [rad]
    at the camera times) when its drive is read from a path with the generator's noise
    (:data:`DRIVE_NOISE_B`, :data:`N_DRIVE_DRAWS` realisations, seed 0) instead of the
    noise-free path, read the same way. Nonlinear and one-sided (the contact's rectification
    is kept), true friction, start poses as commanded."""
    motions = _motions(BOX_B, quasi_static, subset)
    n_t = len(motions)
    n_fine = _path(motions).pos.shape[1]
    t = np.arange(0.0, (n_fine - 1) * FINE_DT - 0.05, 1 / CAMERA_HZ_B)
    n_enc = len(np.arange(0.0, (n_fine - 1) * FINE_DT, 1 / ENCODER_HZ_B))
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, DRIVE_NOISE_B, (N_DRIVE_DRAWS, n_t, n_enc, 3))
    noise = np.concatenate([np.zeros((1, n_t, n_enc, 3)), noise])  # copy 0: noise-free
    obs_all = []
    for lo in range(0, len(noise), 24):
        chunk = noise[lo : lo + 24]
        p, y = _simulate(
            "none",
            quasi_static,
            subset,
            None,
            np.zeros((len(chunk), n_t, 3)),
            drive=_consumer_drives(quasi_static, subset, chunk),
        )
        for j in range(len(chunk)):
            ps = np.stack([_sample(p[j, i], t) for i in range(n_t)])
            ys = np.stack([_sample(y[j, i], t) for i in range(n_t)])
            obs_all.append(np.concatenate([ps, ys[..., None]], axis=-1))
    obs = np.stack(obs_all)
    return obs[1:] - obs[0]


def _whiten(d: np.ndarray, sig: np.ndarray, sig_y: np.ndarray) -> np.ndarray:
    """Observation changes [..., T, N_t, 4] as whitened residual vectors [..., T, 4 N_t], laid
    out as :func:`_plain_fit`'s residual (positions, then yaw)."""
    lead = d.shape[:-3]
    n_t = d.shape[-3]
    p = (d[..., :3] / sig).reshape(*lead, n_t, -1)
    y = (d[..., 3] / sig_y).reshape(*lead, n_t, -1)
    return np.concatenate([p, y], axis=-1)


def _effect_columns(effect: str, quasi_static: bool, subset: Subset, fit: dict) -> np.ndarray:
    """Whitened forward-difference columns [T N, k] of the noiseless observations w.r.t. the
    effect's ``k`` parameters at their true values (steps 1 % of each)."""
    t = fit["t"]
    true = TRUE_PARAMS[effect]

    def observe(vals: dict[str, float]) -> np.ndarray:
        eff = effect if FAMILY[effect] == "contact" else "none"
        pos, yaw = _simulate(
            eff, quasi_static, subset, None, np.zeros((1, len(fit["loc"]), 3)), params=vals
        )
        shift = vals["delta"] if effect == "time_offset" else 0.0
        ps = np.stack([_sample(pos[0, i], t - shift) for i in range(pos.shape[1])])
        ys = np.stack([_sample(yaw[0, i], t - shift) for i in range(pos.shape[1])])
        if effect == "camera_extrinsics":
            c, s = np.cos(vals["dyaw"]), np.sin(vals["dyaw"])
            x = c * ps[..., 0] - s * ps[..., 1] + vals["dx"]
            y = s * ps[..., 0] + c * ps[..., 1] + vals["dy"]
            ps, ys = np.stack([x, y, ps[..., 2]], axis=-1), ys + vals["dyaw"]
        return np.concatenate([ps, ys[..., None]], axis=-1)

    base = observe(dict(true))
    cols = []
    for key, val in true.items():
        h = 0.01 * abs(val)
        d = (observe({**true, key: val + h}) - base) / h
        cols.append(_whiten(d, fit["sig"], fit["sig_y"]).reshape(-1))
    return np.stack(cols, axis=1)


def _orth_complement(x: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Columns of ``x`` [n, c] with their least-squares fit on ``basis`` [n, b] removed."""
    return x - basis @ np.linalg.lstsq(basis, x, rcond=None)[0]


@functools.lru_cache(maxsize=64)
def _effect_subspace(effect: str, quasi_static: bool, subset: Subset) -> dict[str, Any]:
    """The gate's test space of ``effect`` with the nuisances profiled, and the drive noise in it.

    ``q`` [T N, k]: orthonormal, its first column the direction of the profiled effect signal
    (:func:`_plain_fit`'s residual, with what the last linearisation's nuisance columns still
    fit of it removed), the other ``k - 1`` the effect's own parameter columns outside the
    nuisances and that direction (largest singular directions). ``drive_cov`` [k, k]: the
    second moment of the drive noise's whitened response in those coordinates, times the kept
    fraction (as the non-centrality: the statistic sums over the samples kept).
    """
    fit = _profile(effect, quasi_static, subset)
    jac = fit["jac"]
    u = _orth_complement(fit["resid"].reshape(-1, 1), jac)
    k = N_PARAMS[effect]
    if not np.linalg.norm(u) > 0:  # no signal left (e.g. the mass): no direction to test
        return {"q": np.zeros((u.shape[0], k)), "drive_cov": np.zeros((k, k))}
    u = u / np.linalg.norm(u)
    q = u
    if k > 1:
        rest = _orth_complement(_effect_columns(effect, quasi_static, subset, fit), jac)
        rest = rest - u @ (u.T @ rest)
        left = np.linalg.svd(rest, full_matrices=False)[0][:, : k - 1]
        q = np.concatenate([u, left], axis=1)
    resp = _whiten(_drive_response(quasi_static, subset), fit["sig"], fit["sig_y"])
    proj = resp.reshape(len(resp), -1) @ q  # [M, k]
    keep = 1.0 - NOISE_B["drop"]
    return {"q": q, "drive_cov": keep * proj.T @ proj / len(proj)}


N_QUAD_NODES = 256
"""Gauss-Legendre nodes per conditioned term of :func:`_quadform_sf`."""


def _quadform_sf(x: float, weights: np.ndarray, shifts: np.ndarray) -> float:
    """``P[sum_j w_j (z_j + s_j)^2 > x]``, ``z ~ N(0, I)``, ``w > 0`` (:func:`_quadform_sf_many`)."""
    return float(
        _quadform_sf_many(
            np.array([float(x)]), np.asarray(weights, dtype=float), np.asarray(shifts, dtype=float)
        )[0]
    )


def _quadform_sf_many(x: np.ndarray, w: np.ndarray, s: np.ndarray) -> np.ndarray:
    """:func:`_quadform_sf` at each of ``x`` [n], by conditioning on the first term: with
    ``y = z_1 + s_1`` it is ``P[|y| >= r] + int_{-r}^{r} phi(y - s_1) sf_rest(x - w_1 y^2) dy``,
    ``r = sqrt(x / w_1)`` (one term in closed form). The integral in ``y = r sin(t)`` (the
    rest's argument ``x cos^2 t`` is smooth in ``t``) by :data:`N_QUAD_NODES`-point
    Gauss-Legendre quadrature; ~1e-9 against the closed forms for the catalogue's k <= 3."""
    from scipy.stats import norm

    x = np.maximum(x, 0.0)
    r = np.sqrt(x / w[0])
    out = norm.sf(r - s[0]) + norm.cdf(-r - s[0])
    if w.size == 1:
        return out
    nodes, gw = np.polynomial.legendre.leggauss(N_QUAD_NODES)
    t = 0.5 * np.pi * nodes
    y = r[:, None] * np.sin(t)[None]  # [n, Q]
    rest = _quadform_sf_many((x[:, None] * np.cos(t)[None] ** 2).ravel(), w[1:], s[1:])
    jac = 0.5 * np.pi * gw[None] * r[:, None] * np.cos(t)[None]
    return out + np.sum(norm.pdf(y - s[0]) * rest.reshape(y.shape) * jac, axis=1)


def design_power_full(
    noncentrality: float, k: int, level: float, drive_cov: np.ndarray | None = None
) -> tuple[float, float]:
    """Power and critical value of the gate's statistic against white plus drive noise.

    In the test space's orthonormal coordinates (:func:`_effect_subspace`) the statistic is
    ``||a + e||^2``, ``a = (sqrt(lambda), 0, ...)``, ``e ~ N(0, C)``, ``C = I_k + drive_cov``
    [sigma^2] (white noise in sigma units plus the drive noise, linearised and Gaussian, as the
    gate's parametric null draws it). With ``C = V diag(w) V^T`` it is ``sum_j w_j (z_j +
    s_j)^2``, ``s = diag(w)^-1/2 V^T a``: under the null (``s = 0``) a weighted sum of chi^2_1,
    not chi^2_k (its distribution by numerical integration, :func:`_quadform_sf`; e.g. Imhof
    1961, Biometrika 48, for the general form). The critical value is that null's ``1 - level`` quantile (Brent's root of
    :func:`_quadform_sf`, bracketed by the extreme weights times ``chi^2_k.isf(level)``) and
    the power ``P[||a + e||^2 > crit]``. ``drive_cov`` None or zero: the white-noise
    ``chi^2_k`` test (:func:`design_power`). Returns (power, critical value [sigma^2]).
    """
    from scipy.optimize import brentq
    from scipy.stats import chi2

    cov = np.eye(k) if drive_cov is None else np.eye(k) + np.asarray(drive_cov, dtype=float)
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    a = np.zeros(k)
    a[0] = np.sqrt(max(noncentrality, 0.0))
    shifts = (v.T @ a) / np.sqrt(w)
    q = float(chi2.isf(level, k))
    lo, hi = float(w.min()) * q, float(w.max()) * q
    if hi - lo <= 1e-12 * hi:
        crit = hi
    else:
        zeros = np.zeros(k)
        crit = float(brentq(lambda c: _quadform_sf(c, w, zeros) - level, lo, hi, xtol=1e-9 * hi))
    return float(np.clip(_quadform_sf(crit, w, shifts), 0.0, 1.0)), crit


def sign_flip_needs(n_traj: int, level: float) -> int | None:
    """Fewest trajectories ``m`` carrying an effect with which a sign-per-trajectory wild
    cluster null over all ``N = 2^(T-1)`` patterns (``T = n_traj``) can pass it at ``level``.

    The null statistic of a pattern that flips only trajectories the effect does not act on
    equals the data's own (the effect's part, linearised): ``g = 2^(T-m)`` patterns tie at the
    top. The threshold is the null's ``1 - level`` quantile (linear interpolation between order
    statistics, as the gate's ``numpy.quantile``), below the tied value exactly when
    ``g < 1 + level (N - 1)``. With fewer ``m`` the effect passes only where its real held-out
    fall exceeds its linearisation. None when ``N < MIN_PATTERNS_GATE`` (Webb's weights, no such
    ties) or when no ``m <= T`` reaches it.
    """
    n = 2 ** (n_traj - 1)
    if n < MIN_PATTERNS_GATE:
        return None
    for m in range(1, n_traj + 1):
        if 2 ** (n_traj - m) < 1.0 + level * (n - 1):
            return m
    return None


def design_power(noncentrality: float, k: int, level: float) -> float:
    """Power of a chi^2 test of ``k`` parameters at ``level`` when the statistic is a
    non-central ``chi^2_k(noncentrality)``: ``P[chi^2_k(lambda) > chi^2_k.isf(level)]``."""
    from scipy.stats import chi2, ncx2

    crit = float(chi2.isf(level, k))
    if noncentrality <= 0.0:
        return float(level)
    return float(ncx2.sf(crit, k, noncentrality))


SYNTH_CACHE_ENV = "ROBOGS_SYNTH_CACHE_DIR"
"""Folder of :func:`detectability`'s disk memo (unset or empty: none, every process computes)."""
_SOURCES = ("design_b", "generate", "motions", "sim")
"""The generator's modules (``robogs.synth.scenarios``) whose source keys the disk memo."""


@functools.cache
def _source_key() -> str:
    """blake2b of the generator's source (:data:`_SOURCES`) and the numpy and scipy versions."""
    import scipy

    h = hashlib.blake2b(digest_size=20)
    for name in _SOURCES:
        h.update(name.encode() + (Path(__file__).with_name(f"{name}.py")).read_bytes())
    h.update(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    return h.hexdigest()


def _memo_path(folder: str, effect: str, quasi_static: bool, subset: Subset) -> Path:
    """The memo file of one :func:`detectability` call: its inputs and :func:`_source_key`."""
    h = hashlib.blake2b(digest_size=20)
    h.update(json.dumps([_source_key(), effect, bool(quasi_static), subset]).encode())
    return Path(folder) / f"detectability-{h.hexdigest()}.json"


def _to_json(d: dict[str, Any]) -> str:
    """``d`` as JSON, arrays as ``{"dtype", "shape", "data"}`` (floats round-trip exactly)."""

    def enc(v: Any) -> Any:
        if isinstance(v, np.ndarray):
            return {"dtype": v.dtype.str, "shape": list(v.shape), "data": v.ravel().tolist()}
        if isinstance(v, np.generic):
            raise TypeError(f"detectability returned a numpy scalar {v!r}")
        return v

    return json.dumps({k: enc(v) for k, v in d.items()})


def _from_json(text: str) -> dict[str, Any]:
    """:func:`_to_json`'s inverse."""

    def dec(v: Any) -> Any:
        if isinstance(v, dict):
            return np.array(v["data"], dtype=np.dtype(v["dtype"])).reshape(v["shape"])
        return v

    return {k: dec(v) for k, v in json.loads(text).items()}


@functools.lru_cache(maxsize=64)
def detectability(effect: str, quasi_static: bool = False, subset: Subset = None) -> dict[str, Any]:
    """:func:`_detectability`, memoised per process and, where ``$ROBOGS_SYNTH_CACHE_DIR`` names
    a folder, on disk there: one JSON file per call keyed by its inputs and the generator's
    source (:func:`_source_key`), written whole then renamed; an unreadable file is recomputed
    and rewritten. The values read back are the computed ones bit for bit (JSON floats
    round-trip exactly). The tests share one folder between their workers (tests/conftest.py):
    a design's drive draws and an effect's plain fit cost 10-30 s each."""
    folder = os.environ.get(SYNTH_CACHE_ENV, "")
    if not folder:
        return _detectability(effect, quasi_static, subset)
    path = _memo_path(folder, effect, quasi_static, subset)
    try:
        return _from_json(path.read_text())
    except (OSError, ValueError, KeyError, TypeError):
        pass
    out = _detectability(effect, quasi_static, subset)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp")
        tmp.write_text(_to_json(out))
        os.replace(tmp, path)
    except OSError:
        pass
    return out


def _detectability(
    effect: str, quasi_static: bool = False, subset: Subset = None
) -> dict[str, Any]:
    """Whether ``effect`` is detectable by design on design B, and why (module docstring).

    Returns ``expected_delta_bic``, ``noncentrality`` [sigma^2] (nuisances profiled), ``k``,
    ``level`` (per-candidate, ``ALPHA_FAMILY / N_CANDIDATES``), ``power_white`` (the chi^2_k
    test against white noise alone, :func:`design_power`), ``drive_variance`` [sigma^2] (the
    drive-path noise's variance along the profiled effect signal, samples kept),
    ``drive_cov`` [k, k] (the same in the whole test space), ``critical_value`` [sigma^2] (the
    statistic's null quantile at ``level`` under white plus drive noise), ``power`` (against
    white plus drive noise, :func:`design_power_full`), ``detectable`` (``power`` >=
    :data:`POWER_DETECTABLE`), ``carrying`` (trajectories with a share >= 9 sigma^2),
    ``sign_flip_floor`` (``2^-(carrying-1)``: the smallest p-value a sign-per-trajectory
    null can give it), ``trajectories`` ``T``, ``cluster_needs`` (:func:`sign_flip_needs` at
    ``level``: the gate's family-wise level is at least this Bonferroni level, 0.0075 measured,
    which needs the same 8 of 9), ``cluster_ok`` (``carrying >= cluster_needs``, True under
    Webb's weights) and ``verdict``, a line that says which noise decided and the cluster check.
    """
    level = ALPHA_FAMILY / N_CANDIDATES
    if effect == "none":
        k, lam, m = 0, 0.0, 0
        power = power_white = level
        crit, drive = float("nan"), np.zeros((0, 0))
        n_t = len(_motions(BOX_B, quasi_static, subset))
    else:
        k = N_PARAMS[effect]
        per = _profiled_per_trajectory(effect, quasi_static, subset)
        lam = float(np.sum(per))
        m = int(np.sum(per >= LAMBDA_ACTS))
        power_white = design_power(lam, k, level)
        drive = _effect_subspace(effect, quasi_static, subset)["drive_cov"]
        power, crit = design_power_full(lam, k, level, drive)
        n_t = int(per.size)
    needs = sign_flip_needs(n_t, level)
    det = bool(effect != "none" and power >= POWER_DETECTABLE)
    ok = needs is None or m >= needs
    dv = float(drive[0, 0]) if k else 0.0
    noise = (
        f"white + drive-path noise ({dv:.1f} sigma^2 along the effect; white alone "
        f"{power_white:.3f})"
    )
    if not det and power_white >= POWER_DETECTABLE:
        verdict = (
            f"no: power {power:.3f} < {POWER_DETECTABLE:.2f} against {noise}: the drive decided"
        )
    elif not det:
        verdict = f"no: power {power:.3f} < {POWER_DETECTABLE:.2f} against {noise}"
    elif ok:
        verdict = f"yes: power {power:.3f} against {noise}, evidence in {m} of {n_t} trajectories"
    else:
        verdict = (
            f"no for a cluster-robust gate: evidence in {m} of {n_t} trajectories, a sign-flip "
            f"cluster null ({2 ** (n_t - 1)} patterns, level {level:.4f}) needs >= {needs} "
            f"(power {power:.3f} against {noise})"
        )
    return {
        "expected_delta_bic": expected_delta_bic(effect, quasi_static, subset),
        "noncentrality": lam,
        "k": k,
        "level": level,
        "power_white": power_white,
        "drive_variance": dv,
        "drive_cov": drive,
        "critical_value": crit,
        "power": power,
        "detectable": det,
        "carrying": m,
        "sign_flip_floor": 2.0 ** -(m - 1) if m >= 1 else 1.0,
        "trajectories": n_t,
        "cluster_needs": needs,
        "cluster_ok": bool(ok),
        "verdict": verdict,
    }


def detectable_b(effect: str, quasi_static: bool = False, subset: Subset = None) -> bool:
    """Whether the generator deems ``effect`` detectable on design B: the power of the gate's
    test at its per-candidate level, against white plus drive-path noise, is >= 90 %
    (:func:`detectability`)."""
    return bool(detectability(effect, quasi_static, subset)["detectable"])


def make_design_b(
    effect: str = "none",
    *,
    seed: int = 0,
    quasi_static: bool = False,
    trajectories: Sequence[int] | None = None,
    with_detectability: bool = True,
) -> ScenarioRecording:
    """One design-B scenario with ``effect`` hidden (``"none"``: null data).

    ``trajectories``: indices of the motions kept (default all nine: pushes 0-5, slides 6-7,
    the drop 8). ``meta`` carries the truth, ``expected_delta_bic``, the ``noncentrality`` and
    ``power`` of the gate's test, ``detectable`` and ``carrying_trajectories`` (:func:`detectability`).
    ``with_detectability=False`` leaves those design entries out of ``meta`` (10-50 s less where
    no caller reads them); the recording itself is the same.
    """
    if effect not in TRUE_PARAMS:
        raise ValueError(f"unknown effect {effect!r}; known: {sorted(TRUE_PARAMS)}")
    rng = np.random.default_rng(10_000 + seed)
    subset = None if trajectories is None else tuple(int(i) for i in trajectories)
    motions, path, pos, yaw = _truth(effect, quasi_static, None, subset)
    n_t, n_fine = pos.shape[:2]
    dur = (n_fine - 1) * FINE_DT
    delta = TRUE_PARAMS[effect]["delta"] if effect == "time_offset" else 0.0
    enc_t = np.arange(0.0, dur, 1 / ENCODER_HZ_B)
    t0 = 1_750_000_000_000_000_000
    trajs = []
    for i, m in enumerate(motions):
        tc = np.arange(rng.uniform(0, 1 / CAMERA_HZ_B), dur - 0.05, 1 / CAMERA_HZ_B)
        tc = tc[rng.uniform(size=len(tc)) >= NOISE_B["drop"]]  # dropped samples
        p_obs, y_obs = _observe(effect, _sample(pos[i], tc), _sample(yaw[i], tc))
        p_obs = p_obs + rng.normal(0.0, NOISE_B["pos"], p_obs.shape)
        q = _quat_mul(_quat_yaw(y_obs), _small_rot(rng.normal(0.0, NOISE_B["rot"], (len(tc), 3))))
        stamps = tc + delta + rng.normal(0.0, NOISE_B["jitter"], len(tc))
        order = np.argsort(stamps)
        ee_p = _sample(path.pos[i], enc_t) + rng.normal(0.0, DRIVE_NOISE_B, (len(enc_t), 3))
        grasp = path.grasp[i][np.clip(np.round(enc_t / FINE_DT).astype(int), 0, n_fine - 1)]
        trajs.append(
            ScenarioTrajectory(
                name=m.name,
                t_ns=t0 + np.round(stamps[order] * 1e9).astype(np.int64),
                object_pos=p_obs[order],
                object_quat=q[order],
                ee_t_ns=t0 + np.round(enc_t * 1e9).astype(np.int64),
                ee_pos=ee_p,
                ee_quat=_quat_yaw(_sample(path.yaw[i], enc_t)),
                grasp=grasp,
                kind=m.kind,
            )
        )
        t0 += int((dur + rng.uniform(2.0, 6.0)) * 1e9)  # gap before the next trajectory
    box = BOX_B
    sx, sy, sz = box.size
    physics: dict[str, Any] = {
        "revision": 1,
        "gravity_mps2": [0.0, 0.0, -box.gravity],
        "objects": {
            "box": {
                "equation": "rigid",
                "mass_kg": box.mass,
                "com_m": [0.0, 0.0, 0.0],
                "inertia_kgm2": [
                    [box.mass * (sy**2 + sz**2) / 12.0, 0.0, 0.0],
                    [0.0, box.mass * (sx**2 + sz**2) / 12.0, 0.0],
                    [0.0, 0.0, box.inertia_z],
                ],
                "size_m": list(box.size),
                "friction_static": box.mu_s,
                "friction_dynamic": round(float(box.mu_d * rng.uniform(0.85, 1.15)), 4),
                "restitution": box.restitution,
                "damping_linear": 0.0,
                "damping_angular": 0.0,
            },
            "table": {"equation": "static", "plane_z_m": box.table_z},
            "pusher": {
                "equation": "kinematic",
                "link": "ee",
                "shape": "sphere",
                "radius_m": box.pusher_radius,
                "length_m": 0.0,
                "grasp_joint": "grasp",
                "grasp_threshold": 0.5,
            },
        },
        "effects": [],
        "sensors": {"camera": {"time_offset_ns": 0}},
    }
    meta: dict[str, Any] = {
        "design": ("B-quasi-static" if quasi_static else "B")
        + ("" if subset is None else f"-{len(subset)}"),
        "effect": effect,
        "family": FAMILY[effect],
        "true_params": dict(TRUE_PARAMS[effect]),
        "true_friction_dynamic": box.mu_d,
        "noise_levels": dict(NOISE_B),
        "seed": seed,
    }
    if with_detectability:
        det = detectability(effect, quasi_static, subset)
        meta |= {
            "expected_delta_bic": det["expected_delta_bic"],
            "noncentrality": det["noncentrality"],
            "power": det["power"],
            "power_white": det["power_white"],
            "drive_variance": det["drive_variance"],
            "detectable": det["detectable"],
            "carrying_trajectories": det["carrying"],
            "cluster_needs": det["cluster_needs"],
            "detectable_verdict": det["verdict"],
        }
    meta["trajectories"] = None if subset is None else list(subset)
    return ScenarioRecording(trajectories=trajs, physics=physics, object_name="box", meta=meta)

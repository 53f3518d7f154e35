"""Turn a :class:`Recording` into model inputs and weighted measurements.

:func:`prepare` resamples the measured end effector onto the simulation grid (the
:class:`~robogs.physics.model.Drive`), segments phases, estimates the noise, and stacks
the measured object poses with their per-sample deviations into padded tensors.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from robogs.physics.model import BoxScene, Drive
from robogs.physics.noise import NoiseModel, estimate_noise
from robogs.physics.phases import PHASES, PhaseLabels, runs, segment_phases
from robogs.physics.recording import Recording, Trajectory, as_recording, yaw_of
from robogs.physics.scene import scene_from_physics
from robogs.physics.smoothing import drive_windows, local_polynomial

__all__ = [
    "Prepared",
    "phase_labels",
    "TrackedObject",
    "WrenchData",
    "CHAIN_FORCE_BIN_S",
    "FORCE_BIN_S",
    "RING_BIN_PERIODS",
    "RING_BIN_RANGE_S",
    "ring_period",
    "chain_force_bin",
    "prepare",
    "build_drive",
    "excitations",
    "wrench_data",
    "force_rms",
]

REST_MARGIN_M = 0.005
"""A wrench sample counts as out of contact (its offset and noise are estimated from such
samples) when the pusher's surface is this far from the object's box."""
MIN_REST_SAMPLES = 20
FORCE_BIN_S = 0.02
"""Forces are compared as means over bins of this duration: the model's contact impulse of
the bin's steps over its duration against the mean of the sensor samples in it. (A kinematic
pusher's force is the mass times its acceleration, a second derivative of measured positions:
per 1 ms step it is noise; over 20 ms it is the force.)"""
CHAIN_FORCE_BIN_S = 0.1
"""Force bins [s] of a recording with other tracked objects (one pushed into another) when the
measured force shows no ring (:func:`chain_force_bin`). The pusher-object-object chain of soft
contacts on MuJoCo rings at about 25 Hz (+-0.4 N from one 20 ms bin to the next): a mean over a
window of W passes ``|sinc(W / P)|`` of a ring of period P = 40 ms, 64 % at 20 ms, 13 % at
100 ms (2.5 periods). On the two-box scenario (seed 0) the fitted force residual is 0.22 N RMS
with 20 ms bins, 0.023 N with 100 ms bins (noise floor 0.011 N); bins stay impulse-preserving
through the impacts."""
RING_BIN_PERIODS = 3
"""A chain's force bin spans this many periods of the measured ring (:func:`chain_force_bin`).
A mean over whole periods passes none of a steady ring, but the chain's ring starts at an impact
and decays, at any phase of the bin grid: the part of a period left in a bin passes. On the
two-box scenario with a 25 Hz ring (0.3 N, decaying over 2 periods) added to the sensor, seeds
0-5, the largest |error| of mu_a, mu_b was 2.5-35 % (median 3.7 %) with bins of one period
(40 ms), 0.7-3.5 % (1.6 %) of two, 0.8-2.5 % (1.6 %) of three, 1.2-5.7 % (1.9 %) with the fixed
100 ms; with the derived bins (115-123 ms: three measured periods) 0.3-6.7 % (1.9 %): the fits
move by a few % with the bin's length (``bench/chain_force_bin.py``; ``bench/RESULTS.md``,
issue 16, h36)."""
RING_BIN_RANGE_S = (0.02, 0.25)
"""A chain's force bin (:data:`RING_BIN_PERIODS` ring periods) is clamped to this range [s]: no
shorter than a single object's bins (:data:`FORCE_BIN_S`, the sensor noise per bin), no longer
than 250 ms (a push of the two-box scenario touches for 0.2-0.3 s: a longer bin averages the
push away)."""
RING_TROUGH = 0.2
"""A ring is found when the autocorrelation of the force's increments, after its first zero
crossing, falls below ``-RING_TROUGH`` within three times that lag (an oscillation swings back;
a step, a ramp or white noise does not)."""

_log = logging.getLogger(__name__)


@dataclass
class WrenchData:
    """The measured force on the pusher, as the residuals use it.

    Attributes:
        meas: [T, W, 3] mean force on the tool per bin [N], world axes, offset removed.
        sigma: [3] noise floor of one sample per axis [N] (1.4826 MAD out of contact).
        count: [T, W] samples per bin (the bin's deviation is ``sigma / sqrt(count)``).
        mask: [T, W] bins in the residuals (holding samples, none while grasping).
        offset: [T, 3] the offset removed per trajectory [N] (median out of contact).
        n_rest: number of out-of-contact samples the offset and noise come from.
    """

    meas: torch.Tensor
    sigma: torch.Tensor
    count: torch.Tensor
    mask: torch.Tensor
    offset: np.ndarray
    n_rest: int


@dataclass
class TrackedObject:
    """Another tracked object of the scene (not the one the pusher drives), as the residuals
    use it: its own stamps, poses, noise and start (:attr:`Trajectory.others`).

    Attributes:
        name: physics.json object name; size: its box edges [m].
        obs_t: [T, K] s from each trajectory's start (``Prepared.t0_ns``); mask: [T, K] valid.
        meas_pos: [T, K, 3] m; meas_yaw: [T, K] rad (unwrapped).
        sig_pos: [T, K, 3] m; sig_yaw: [T, K] rad - per-sample deviations from this object's
            own noise estimate (:func:`robogs.physics.noise.estimate_noise` on its poses).
        init_pos: [T, 3] m; init_yaw: [T] rad - start pose (median of the first static samples,
            snapped onto the table within ``z_snap``).
        noise: its noise model.
    """

    name: str
    size: tuple[float, float, float]
    obs_t: torch.Tensor
    mask: torch.Tensor
    meas_pos: torch.Tensor
    meas_yaw: torch.Tensor
    sig_pos: torch.Tensor
    sig_yaw: torch.Tensor
    init_pos: np.ndarray
    init_yaw: np.ndarray
    noise: NoiseModel

    @property
    def width(self) -> int:
        """Columns of its block in the weighted residuals (4 per sample)."""
        return int(self.mask.shape[1]) * 4


@dataclass
class Prepared:
    """Everything a rollout-vs-measurement comparison needs.

    Attributes:
        rec, scene, drive, labels, noise: inputs, constants, drive, phases, noise model.
        t0_ns: start stamp of every trajectory [T] (model time 0).
        meas_pos: [T, N, 3] m; meas_yaw: [T, N] rad (unwrapped); mask: [T, N] valid samples.
        sig_pos: [T, N, 3] m; sig_yaw: [T, N] rad - per-sample deviations (jitter included).
        phase: [T, N] phase index (-1 padding).
        excitation: which needs the data meets (``contact``, ``sliding``, ``impact``...).
        wrench: the measured pusher force (None when not used); ``wrench_note`` says how it
            is used, or why not.
        tracked: the other tracked objects (their pose blocks follow the free object's in the
            weighted residuals, :mod:`robogs.physics.residuals`).
    """

    rec: Recording
    scene: BoxScene
    drive: Drive
    labels: list[PhaseLabels]
    noise: NoiseModel
    t0_ns: np.ndarray
    meas_pos: torch.Tensor
    meas_yaw: torch.Tensor
    sig_pos: torch.Tensor
    sig_yaw: torch.Tensor
    mask: torch.Tensor
    phase: np.ndarray
    excitation: set[str]
    wrench: WrenchData | None = None
    wrench_note: str = ""
    tracked: list[TrackedObject] = field(default_factory=list)

    @property
    def n_traj(self) -> int:
        return len(self.rec.trajectories)

    @property
    def pose_width(self) -> int:
        """Columns of the pose blocks (free object, then each tracked one) per trajectory."""
        return int(self.mask.shape[1]) * 4 + sum(o.width for o in self.tracked)

    @property
    def n_residuals(self) -> int:
        """Number of scalar residuals (4 per valid pose sample: x, y, z, yaw; 3 per force)."""
        n_w = 0 if self.wrench is None else int(self.wrench.mask.sum()) * 3
        n_o = sum(int(o.mask.sum()) * 4 for o in self.tracked)
        return int(self.mask.sum()) * 4 + n_o + n_w


def _initial_pose(pos: np.ndarray, yaw: np.ndarray, lab: PhaseLabels) -> tuple[np.ndarray, float]:
    static = ~lab.moving & np.isin(lab.label, [PHASES.index("rest"), PHASES.index("grasp")])
    for a, b in runs(static):
        if a > 5:
            break
        if b - a >= 3:
            b = b - 1  # the last static sample may already move
            return np.median(pos[a:b], axis=0), float(np.median(yaw[a:b]))
    return pos[0].copy(), float(yaw[0])


def build_drive(
    rec: Recording,
    scene: BoxScene,
    labels: list[PhaseLabels],
    dt: float,
    z_snap: float = 0.003,
    ee_window: float | None = None,
    pos_window: float | None = None,
) -> tuple[Drive, np.ndarray]:
    """Resample the EE onto a grid of step ``dt`` from each trajectory's first stamp.

    Contacts use the EE positions smoothed by a degree-4 tricube-weighted local polynomial over
    ``pos_window`` s, and the velocity an object inherits when the grasp opens is that fit's
    derivative over ``ee_window`` s (:func:`~robogs.physics.smoothing.local_polynomial`
    says why: the one-sided pusher contact rectifies the noise a smoother lets through, and a
    rounded braking onset releases the box too slowly). None (the default): both from the
    recorded path's own noise and sample rate (:func:`~robogs.physics.smoothing.drive_windows`:
    80 ms and 60 ms at the scenarios' 60 um and 500 Hz or noisier, shorter on a cleaner path,
    none on a noise-free one, so that a clean sharp brake is not rounded).

    The initial object pose is the median of the first static samples; a start height within
    ``z_snap`` of the resting height is snapped onto the table.

    The robot pusher's other servo DOFs (``Trajectory.pusher_dofs``: the end effector's pitch
    and roll, the joints below the pusher link that move) are interpolated linearly onto the
    grid as the yaw is (``Drive.pusher_dofs``).

    The drive records each trajectory's EE sample interval (``Drive.sample_dt`` [T] s: the
    median spacing of its ``ee_t_ns``; NaN with fewer than two samples): the linear
    interpolation puts a velocity step at every sample, wherever the stamps fall on the grid,
    and the MuJoCo engine smooths its servo targets over that interval.

    Returns:
        the drive and the start stamps [T] (int64 ns).
    """
    trs = rec.trajectories
    t0 = np.array([min(int(t.t_ns[0]), int(t.ee_t_ns[0])) for t in trs], dtype=np.int64)
    dur = max(
        (max(int(t.t_ns[-1]), int(t.ee_t_ns[-1])) - s) * 1e-9 for t, s in zip(trs, t0, strict=True)
    )
    n_s = int(np.ceil(dur / dt)) + 2
    grid = np.arange(n_s) * dt
    n_obs = max(len(t.t_ns) for t in trs)
    n_t = len(trs)
    pusher = np.zeros((n_t, n_s, 3))
    eyaw = np.zeros((n_t, n_s))
    carry = np.zeros((n_t, n_s, 3))
    grasp = np.zeros((n_t, n_s), dtype=bool)
    obs_t = np.zeros((n_t, n_obs))
    obs_mask = np.zeros((n_t, n_obs), dtype=bool)
    ipos = np.zeros((n_t, 3))
    iyaw = np.zeros(n_t)
    sample_dt = np.array(
        [np.median(np.diff(t.ee_t_ns)) * 1e-9 if len(t.ee_t_ns) > 1 else np.nan for t in trs]
    )
    if pos_window is None or ee_window is None:
        w_pos, w_ee, s, rate = drive_windows(
            [((t.ee_t_ns - t.ee_t_ns[0]) * 1e-9, t.ee_pos) for t in trs]
        )
        _log.info(
            "drive smoothing: EE path noise %.3g um per axis at %.0f Hz -> windows %.1f ms "
            "(positions), %.1f ms (carried velocity)",
            s * 1e6,
            rate,
            w_pos * 1e3,
            w_ee * 1e3,
        )
        pos_window = w_pos if pos_window is None else pos_window
        ee_window = w_ee if ee_window is None else ee_window
    for i, (tr, lab) in enumerate(zip(trs, labels, strict=True)):
        te = (tr.ee_t_ns - t0[i]) * 1e-9
        ee_yaw = np.unwrap(yaw_of(tr.ee_quat))
        ee_v = local_polynomial(te, tr.ee_pos, ee_window, deriv=1)
        ee_p = local_polynomial(te, tr.ee_pos, pos_window)
        for a in range(3):
            pusher[i, :, a] = np.interp(grid, te, ee_p[:, a])
            carry[i, :, a] = np.interp(grid, te, ee_v[:, a])
        eyaw[i] = np.interp(grid, te, ee_yaw)
        j = np.clip(np.searchsorted(te, grid, side="right") - 1, 0, len(te) - 1)
        grasp[i] = tr.grasp[j]
        n = len(tr.t_ns)
        obs_t[i, :n] = (tr.t_ns - t0[i]) * 1e-9
        obs_mask[i, :n] = True
        ipos[i], iyaw[i] = _initial_pose(tr.object_pos, np.unwrap(yaw_of(tr.object_quat)), lab)
        z_rest = scene.table_z + 0.5 * scene.size[2]
        if abs(ipos[i, 2] - z_rest) < z_snap:
            ipos[i, 2] = z_rest  # resting on the table: the measured height is noise
    dofs = _grid_dofs(trs, t0, grid)
    pvel = np.zeros_like(pusher)
    pvel[:, :-1] = np.diff(pusher, axis=1) / dt
    yrate = np.zeros_like(eyaw)
    yrate[:, :-1] = np.diff(eyaw, axis=1) / dt
    f = torch.float64
    drive = Drive(
        dt=dt,
        pusher=torch.as_tensor(pusher, dtype=f),
        pusher_vel=torch.as_tensor(pvel, dtype=f),
        ee_yaw=torch.as_tensor(eyaw, dtype=f),
        ee_yaw_rate=torch.as_tensor(yrate, dtype=f),
        grasp=torch.as_tensor(grasp),
        init_pos=torch.as_tensor(ipos, dtype=f),
        init_yaw=torch.as_tensor(iyaw, dtype=f),
        obs_t=torch.as_tensor(obs_t, dtype=f),
        obs_mask=torch.as_tensor(obs_mask),
        carry_vel=torch.as_tensor(carry, dtype=f),
        sample_dt=torch.as_tensor(sample_dt, dtype=f),
        pusher_dofs=None if dofs is None else torch.as_tensor(dofs, dtype=f),
    )
    return drive, t0


def _grid_dofs(trs: list[Trajectory], t0: np.ndarray, grid: np.ndarray) -> np.ndarray | None:
    """[T, S, J] the trajectories' ``pusher_dofs`` [E, J] (at their EE stamps) linearly
    interpolated on ``grid`` [S] s from each start ``t0`` [T] ns; None when none has them.

    Raises:
        InputError: some trajectories have them and others not, or not as many.
    """
    vals = [getattr(t, "pusher_dofs", None) for t in trs]
    if all(v is None for v in vals):
        return None
    widths = {None if v is None else np.shape(v)[-1] for v in vals}
    if len(widths) != 1 or None in widths:
        from robogs.format.errors import InputError

        raise InputError(
            "some trajectories carry the robot pusher's DOFs (pusher_dofs) and others do not, "
            "or not as many",
            where="Trajectory.pusher_dofs",
            hint="load every trajectory with the same robot pusher (load_recording)",
        )
    out = np.zeros((len(trs), len(grid), widths.pop()))
    for i, (tr, v) in enumerate(zip(trs, vals, strict=True)):
        te = (tr.ee_t_ns - t0[i]) * 1e-9
        v = np.asarray(v, dtype=float)
        for j in range(v.shape[1]):
            out[i, :, j] = np.interp(grid, te, v[:, j])
    return out


def _interp_rows(t: np.ndarray, tp: np.ndarray, xp: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t, tp, xp[:, a]) for a in range(xp.shape[1])], axis=-1)


def _capsule_box_gap(
    ee_pos: np.ndarray,
    ee_yaw: np.ndarray,
    obj_pos: np.ndarray,
    obj_yaw: np.ndarray,
    scene: BoxScene,
) -> np.ndarray:
    """Planar distance [m] from the pusher's surface (sphere, or capsule along the EE y axis,
    sampled at 5 points) to the box footprint; negative inside. Shapes [K, 3], [K] -> [K]."""
    hx, hy = 0.5 * scene.size[0], 0.5 * scene.size[1]
    best = np.full(len(ee_pos), np.inf)
    for u in np.linspace(-0.5, 0.5, 5 if scene.pusher_length > 0 else 1):
        px = ee_pos[:, 0] - np.sin(ee_yaw) * u * scene.pusher_length - obj_pos[:, 0]
        py = ee_pos[:, 1] + np.cos(ee_yaw) * u * scene.pusher_length - obj_pos[:, 1]
        c, s = np.cos(obj_yaw), np.sin(obj_yaw)
        lx, ly = c * px + s * py, -s * px + c * py
        ex, ey = np.abs(lx) - hx, np.abs(ly) - hy
        out = np.hypot(np.maximum(ex, 0.0), np.maximum(ey, 0.0))
        d = np.where((ex > 0) | (ey > 0), out, np.maximum(ex, ey))
        best = np.minimum(best, d - scene.pusher_radius)
    return best


def ring_period(
    segments: Sequence[np.ndarray], h: float, noise_sd: float = 0.0, max_lag_s: float = 0.25
) -> tuple[float | None, str]:
    """The dominant ring period [s] of a force measured during contact, or None and why not.

    ``segments``: force samples [N] along one axis, each an uninterrupted contact sampled every
    ``h`` s; ``noise_sd``: the sensor's noise per sample [N] (white). The increments
    ``f[k+1] - f[k]`` are used, not the force: a step (an impact, a push that starts or stops)
    becomes one or two large increments, set to 0 beyond 6 robust deviations (clipping them
    instead biased 25 Hz rings by up to +10 %), instead of a trend that would dominate the
    autocorrelation; a ring keeps its period. Their autocovariance R is pooled over the
    segments; white noise of deviation s adds ``2 s^2`` at lag 0 and ``-s^2`` at lag 1, which
    are taken out. The first zero crossing of R / R(0) (linearly interpolated) is a quarter
    period (within 3 % on rings decaying over 2-4 periods, 12-40 Hz, 0.03 N noise; a ring gone
    within one period reads up to 5 % short). The ring is accepted when R then swings below
    ``-RING_TROUGH`` R(0) within three times that lag (:data:`RING_TROUGH`), by more than four
    sampling errors of an autocovariance (``R_total(0) / sqrt(n)``), and its increments carry
    more than three times the noise's sampling error. Lags up to ``max_lag_s`` are searched.
    """
    d = [np.diff(np.asarray(x, float)) for x in segments if len(x) >= 4]
    n = sum(len(x) for x in d)
    if n < 20:
        return None, f"{n} force increments during contact (at least 20 are needed)"
    pool = np.concatenate(d)
    med = float(np.median(pool))
    dev = 1.4826 * float(np.median(np.abs(pool - med)))
    d = [np.where(np.abs(x - med) > 6.0 * dev, 0.0, x - med) for x in d]  # steps out
    n_lag = max(int(np.ceil(max_lag_s / h)), 4)
    r = np.zeros(n_lag + 1)
    for lag in range(n_lag + 1):
        num = sum(float(np.dot(x[: len(x) - lag], x[lag:])) for x in d if len(x) > lag)
        cnt = sum(len(x) - lag for x in d if len(x) > lag)
        r[lag] = num / cnt if cnt else 0.0
    se = r[0] / np.sqrt(n)  # sampling error of an autocovariance of these increments
    r[0] -= 2.0 * noise_sd**2
    r[1] += noise_sd**2
    if r[0] <= 3.0 * 2.0 * noise_sd**2 * np.sqrt(2.0 / n):
        return None, "the force's increments during contact are its sensor noise (no ring)"
    se /= r[0]
    r = r / r[0]
    cross = np.flatnonzero(r[1:] <= 0.0)
    if not cross.size:
        return None, f"no zero crossing of the force's autocorrelation within {max_lag_s} s"
    k = int(cross[0]) + 1
    tau = (k - 1) + r[k - 1] / (r[k - 1] - r[k])  # lags
    trough = float(r[k : min(int(np.ceil(3.0 * tau)) + 1, n_lag + 1)].min())
    if trough > -max(RING_TROUGH, 4.0 * se):
        return None, (
            f"the force's autocorrelation does not swing back after its zero crossing at "
            f"{tau * h * 1e3:.0f} ms (least {trough:.2f} > -{max(RING_TROUGH, 4.0 * se):.2f}): "
            "no ring"
        )
    period = 4.0 * tau * h
    return period, (
        f"ring of {period * 1e3:.0f} ms ({1.0 / period:.1f} Hz) in the measured force during "
        f"contact (autocorrelation of its increments: zero at {tau * h * 1e3:.1f} ms, trough "
        f"{trough:.2f})"
    )


def chain_force_bin(
    segments: Sequence[np.ndarray], h: float, noise_sd: float = 0.0
) -> tuple[float, str]:
    """Force bin [s] of a recording with a chain of contacts (other tracked objects):
    :data:`RING_BIN_PERIODS` periods of the measured ring (:func:`ring_period`), clamped to
    :data:`RING_BIN_RANGE_S`; a mean over whole periods passes none of a steady ring. Without a
    ring found, :data:`CHAIN_FORCE_BIN_S`, with the reason logged and returned."""
    period, why = ring_period(segments, h, noise_sd)
    lo, hi = RING_BIN_RANGE_S
    if period is None:
        why = f"{CHAIN_FORCE_BIN_S * 1e3:.0f} ms bins (CHAIN_FORCE_BIN_S): {why}"
        _log.info("chain force bin: %s", why)
        return CHAIN_FORCE_BIN_S, why
    bin_s = float(np.clip(RING_BIN_PERIODS * period, lo, hi))
    if bin_s != RING_BIN_PERIODS * period:
        why += f"; {RING_BIN_PERIODS} periods clamped to [{lo * 1e3:.0f}, {hi * 1e3:.0f}] ms"
    return bin_s, f"{RING_BIN_PERIODS} ring periods per bin: {why}"


def wrench_data(
    rec: Recording,
    scene: BoxScene,
    drive: Drive,
    t0: np.ndarray,
    bin_s: float | None = FORCE_BIN_S,
) -> tuple[WrenchData | None, str]:
    """Wrench residual inputs; sets ``drive.wrench_bin`` / ``wrench_width`` in place.

    Forces are compared per bin of ``bin_s`` (default :data:`FORCE_BIN_S`; None: periods of
    the ring of the measured force during contact, :func:`chain_force_bin`) on the
    simulation grid: the model's contact
    impulses of the bin's steps over its duration against the mean of the sensor samples in it.
    The sensor's offset (tool weight, drift) and noise floor come from the samples at which the
    pusher's surface is more than ``REST_MARGIN_M`` from the box (out of contact, so the true
    contact force is zero): per trajectory the median (pooled over trajectories when one has
    fewer than ``MIN_REST_SAMPLES``), and the pooled 1.4826 MAD. Returns (data, how it is used)
    or (None, why not): a note in both cases, for every command to print.
    """
    trs = rec.trajectories
    if not any(t.wrench_t_ns is not None and len(t.wrench_t_ns) for t in trs):
        return None, "no wrench stream in the data: forces are not compared"
    n_t, n_s = drive.n_traj, drive.n_steps
    dt = drive.dt
    times: list[np.ndarray] = []
    samples: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    # samples on the grid's bins (a derived bin is not known yet: on the grid's steps)
    k_pre = None if bin_s is None else max(int(round(bin_s / dt)), 1)
    n_pre = int(np.ceil(n_s / k_pre)) if k_pre else 0
    for i, tr in enumerate(trs):
        if tr.wrench_t_ns is None or len(tr.wrench_t_ns) == 0:
            times.append(np.zeros(0))
            samples.append((np.zeros((0, 3)), np.zeros(0, bool), np.zeros(0, bool), np.zeros(0)))
            continue
        tw = (tr.wrench_t_ns - t0[i]) * 1e-9
        te = (tr.ee_t_ns - t0[i]) * 1e-9
        to = (tr.t_ns - t0[i]) * 1e-9
        jg = np.clip(np.searchsorted(te, tw, side="right") - 1, 0, len(te) - 1)
        on_grid = np.floor(tw / (k_pre * dt)) < n_pre if k_pre else tw < n_s * dt
        usable = (tw >= 0.0) & on_grid & ~tr.grasp[jg]
        gap = _capsule_box_gap(
            _interp_rows(tw, te, tr.ee_pos),
            np.interp(tw, te, np.unwrap(yaw_of(tr.ee_quat))),
            _interp_rows(tw, to, tr.object_pos),
            np.interp(tw, to, np.unwrap(yaw_of(tr.object_quat))),
            scene,
        )
        times.append(tw)
        samples.append((tr.wrench_force, usable & (gap > REST_MARGIN_M), usable, gap))
    n_rest = int(sum(r.sum() for _, r, _, _ in samples))
    if n_rest < MIN_REST_SAMPLES:
        return None, (
            f"wrench not used: {n_rest} samples out of contact (at least {MIN_REST_SAMPLES} "
            "are needed to estimate the sensor's offset and noise)"
        )
    pooled = np.median(np.concatenate([f[r] for f, r, _, _ in samples]), axis=0)
    offset = np.zeros((n_t, 3))
    for i, (f, r, _, _) in enumerate(samples):
        offset[i] = np.median(f[r], axis=0) if r.sum() >= MIN_REST_SAMPLES else pooled
    dev = np.concatenate([f[r] - offset[i] for i, (f, r, _, _) in enumerate(samples)])
    sigma = np.maximum(1.4826 * np.median(np.abs(dev), axis=0), 1e-3)
    why_bin = ""
    if bin_s is None:
        bin_s, why_bin = chain_force_bin(*_contact_segments(times, samples, sigma))
    k_bin = max(int(round(bin_s / dt)), 1)
    n_b = int(np.ceil(n_s / k_bin))
    meas = np.zeros((n_t, n_b, 3))
    count = np.zeros((n_t, n_b))
    for i, (f, _, u, _) in enumerate(samples):
        b = np.floor(times[i] / (k_bin * dt)).astype(np.int64)
        u = u & (b < n_b)
        np.add.at(meas[i], b[u], f[u] - offset[i])
        np.add.at(count[i], b[u], 1.0)
    mask = count > 0
    meas = meas / np.maximum(count, 1.0)[..., None]
    bins = np.broadcast_to(np.arange(n_s) // k_bin, (n_t, n_s)).copy()
    width = np.full((n_t, n_b), k_bin * dt)
    f64 = torch.float64
    drive.wrench_bin = torch.as_tensor(bins)
    drive.wrench_width = torch.as_tensor(width, dtype=f64)
    data = WrenchData(
        meas=torch.as_tensor(meas, dtype=f64),
        sigma=torch.as_tensor(sigma, dtype=f64),
        count=torch.as_tensor(np.maximum(count, 1.0), dtype=f64),
        mask=torch.as_tensor(mask),
        offset=offset,
        n_rest=n_rest,
    )
    note = (
        f"wrench used: {int(count.sum())} samples in {int(mask.sum())} bins of "
        f"{k_bin * dt * 1000:.0f} ms enter the residuals in N; the sensor's offset and noise "
        f"({', '.join(f'{x:.3g}' for x in sigma)} N per sample) from {n_rest} samples out of contact"
    )
    if why_bin:
        note += f"; force bins: {why_bin}"
    return data, note


def _contact_segments(
    times: list[np.ndarray], samples: list[tuple], sigma: np.ndarray
) -> tuple[list[np.ndarray], float, float]:
    """(the measured force during contact, one array per uninterrupted run of samples within
    ``REST_MARGIN_M`` of the pushed box, along the principal axis of its horizontal increments;
    the median sample period [s]; the sensor noise along that axis [N]) for :func:`ring_period`."""
    runs_f: list[np.ndarray] = []
    steps: list[np.ndarray] = []
    for tw, (f, _, usable, gap) in zip(times, samples, strict=True):
        on = usable & (gap <= REST_MARGIN_M)
        steps.append(np.diff(tw))
        runs_f += [f[a:b, :2] for a, b in runs(on) if b - a >= 4]
    h = float(np.median(np.concatenate(steps))) if sum(map(len, steps)) else FORCE_BIN_S
    if not runs_f:
        return [], h, 0.0
    inc = np.concatenate([np.diff(x, axis=0) for x in runs_f])
    axis = np.linalg.eigh(inc.T @ inc)[1][:, -1]  # principal axis of the increments
    noise = float(np.sqrt(np.sum((axis * sigma[:2]) ** 2)))
    return [x @ axis for x in runs_f], h, noise


def excitations(rec: Recording, labels: list[PhaseLabels]) -> set[str]:
    """Which ``needs`` words the data satisfies."""
    have = {"object_poses", "ee_poses"}
    names = set()
    for lab in labels:
        names.update(lab.names())
    for ph in ("contact", "sliding", "impact"):
        if ph in names:
            have.add(ph)
    heads = []
    for tr in rec.trajectories:
        d = tr.object_pos[-1, :2] - tr.object_pos[0, :2]
        if np.hypot(*d) > 0.01:
            heads.append(np.arctan2(d[1], d[0]))
    distinct: list[float] = []
    for h in heads:
        if all(abs(np.angle(np.exp(1j * (h - g)))) > np.radians(30) for g in distinct):
            distinct.append(h)
    if len(distinct) >= 3:
        have.add("directions")
    return have


def phase_labels(
    rec: Recording, scene: BoxScene, noise: NoiseModel | None = None
) -> tuple[list[PhaseLabels], NoiseModel]:
    """Per-trajectory phases and the pose noise model (estimated from the rest phases unless
    ``noise`` is given): a first pass with the high-frequency noise sets the thresholds."""
    seg = dict(
        size=scene.size,
        table_z=scene.table_z,
        pusher_radius=scene.pusher_radius,
        pusher_length=scene.pusher_length,
    )
    rough = estimate_noise(rec, None)
    labels = [segment_phases(tr, sigma_pos=rough.sigma_pos, **seg) for tr in rec.trajectories]
    if noise is None:
        noise = estimate_noise(rec, labels)
        labels = [segment_phases(tr, sigma_pos=noise.sigma_pos, **seg) for tr in rec.trajectories]
    return labels, noise


def prepare(
    recording: object,
    *,
    dt: float = 1e-3,
    noise: NoiseModel | None = None,
    ee_window: float | None = None,
) -> Prepared:
    """Prepare a recording (or recording-like object) for rollouts and residuals.

    ``ee_window``: window [s] of the carried velocity at a grasp's release; None derives it,
    and the drive's position window, from the recorded path's noise (:func:`build_drive`)."""
    rec = as_recording(recording)
    scene = scene_from_physics(rec.physics, rec.object_name, dt=dt)
    labels, noise = phase_labels(rec, scene, noise)
    drive, t0 = build_drive(
        rec, scene, labels, dt, z_snap=max(0.003, 4 * noise.sigma_z), ee_window=ee_window
    )
    n_t, n_obs = drive.obs_t.shape
    mpos = np.zeros((n_t, n_obs, 3))
    myaw = np.zeros((n_t, n_obs))
    spos = np.ones((n_t, n_obs, 3))
    syaw = np.ones((n_t, n_obs))
    phase = -np.ones((n_t, n_obs), dtype=np.int64)
    for i, (tr, lab) in enumerate(zip(rec.trajectories, labels, strict=True)):
        n = len(tr.t_ns)
        mpos[i, :n] = tr.object_pos
        myaw[i, :n] = np.unwrap(yaw_of(tr.object_quat))
        spos[i, :n], syaw[i, :n] = noise.per_sample(lab.vel, lab.yaw_rate)
        phase[i, :n] = lab.label
    tracked = [
        _tracked_object(rec, name, t0, dt, max(0.003, 4 * noise.sigma_z)) for name in rec.tracked
    ]
    bin_s = None if tracked else FORCE_BIN_S  # a chain of contacts rings: whole ring periods
    wrench, wrench_note = wrench_data(rec, scene, drive, t0, bin_s)
    excitation = excitations(rec, labels)
    if wrench is not None:
        excitation.add("wrenches")
    f = torch.float64
    return Prepared(
        rec=rec,
        scene=scene,
        drive=drive,
        labels=labels,
        noise=noise,
        t0_ns=t0,
        meas_pos=torch.as_tensor(mpos, dtype=f),
        meas_yaw=torch.as_tensor(myaw, dtype=f),
        sig_pos=torch.as_tensor(spos, dtype=f),
        sig_yaw=torch.as_tensor(syaw, dtype=f),
        mask=drive.obs_mask.clone(),
        phase=phase,
        excitation=excitation,
        wrench=wrench,
        wrench_note=wrench_note,
        tracked=tracked,
    )


def _tracked_object(
    rec: Recording, name: str, t0: np.ndarray, dt: float, z_snap: float
) -> TrackedObject:
    """Residual inputs of the other tracked object ``name``: its phases and noise from its own
    poses (the recording seen as if it were the free object), stacked like the free object's."""
    scene = scene_from_physics(rec.physics, name, dt=dt)
    seg = dict(
        size=scene.size,
        table_z=scene.table_z,
        pusher_radius=scene.pusher_radius,
        pusher_length=scene.pusher_length,
    )
    trs: list[Trajectory] = [
        replace(tr, t_ns=o.t_ns, object_pos=o.pos, object_quat=o.quat, others={})
        for tr in rec.trajectories
        for o in (tr.others[name],)
    ]
    view = replace(rec, trajectories=trs, object_name=name)
    rough = estimate_noise(view, None)
    labels = [segment_phases(tr, sigma_pos=rough.sigma_pos, **seg) for tr in trs]
    noise = estimate_noise(view, labels)
    labels = [segment_phases(tr, sigma_pos=noise.sigma_pos, **seg) for tr in trs]
    n_t, n_k = len(trs), max(len(tr.t_ns) for tr in trs)
    obs_t, mask = np.zeros((n_t, n_k)), np.zeros((n_t, n_k), dtype=bool)
    mpos, myaw = np.zeros((n_t, n_k, 3)), np.zeros((n_t, n_k))
    spos, syaw = np.ones((n_t, n_k, 3)), np.ones((n_t, n_k))
    ipos, iyaw = np.zeros((n_t, 3)), np.zeros(n_t)
    z_rest = scene.table_z + 0.5 * scene.size[2]
    for i, (tr, lab) in enumerate(zip(trs, labels, strict=True)):
        n = len(tr.t_ns)
        yaw = np.unwrap(yaw_of(tr.object_quat))
        obs_t[i, :n] = (tr.t_ns - t0[i]) * 1e-9
        mask[i, :n] = True
        mpos[i, :n], myaw[i, :n] = tr.object_pos, yaw
        spos[i, :n], syaw[i, :n] = noise.per_sample(lab.vel, lab.yaw_rate)
        ipos[i], iyaw[i] = _initial_pose(tr.object_pos, yaw, lab)
        if abs(ipos[i, 2] - z_rest) < z_snap:
            ipos[i, 2] = z_rest
    f = torch.float64
    return TrackedObject(
        name=name,
        size=tuple(float(x) for x in scene.size),
        obs_t=torch.as_tensor(obs_t, dtype=f),
        mask=torch.as_tensor(mask),
        meas_pos=torch.as_tensor(mpos, dtype=f),
        meas_yaw=torch.as_tensor(myaw, dtype=f),
        sig_pos=torch.as_tensor(spos, dtype=f),
        sig_yaw=torch.as_tensor(syaw, dtype=f),
        init_pos=ipos,
        init_yaw=iyaw,
        noise=noise,
    )


def force_rms(prep: Prepared, weighted: np.ndarray) -> dict[str, float] | None:
    """Pusher force residual of weighted residuals ``weighted`` [T, K] (the force block after
    the pose blocks, :func:`robogs.physics.residuals.weighted_residuals`), None without a wrench.

    Returns ``rms_n``: RMS over the used bins of the 3-D bin-mean force error [N];
    ``noise_floor_n``: the RMS the true model would leave (per bin ``sigma / sqrt(count)`` per
    axis, the sensor's noise floor); ``bins``: bins used.
    """
    w = prep.wrench
    n_pose = prep.pose_width
    if w is None or weighted.shape[-1] <= n_pose:
        return None
    n_t, n_b = w.mask.shape
    rf = np.asarray(weighted)[:, n_pose:].reshape(n_t, n_b, 4)[..., :3]
    sf = w.sigma.numpy()[None, None, :] / np.sqrt(w.count.numpy())[..., None]  # [T, W, 3] N
    m = w.mask.numpy()
    if not m.any():
        return None
    err2 = np.sum((rf * sf) ** 2, axis=-1)[m]
    floor2 = np.sum(sf**2, axis=-1)[m]
    return {
        "rms_n": float(np.sqrt(err2.mean())),
        "noise_floor_n": float(np.sqrt(floor2.mean())),
        "bins": int(m.sum()),
    }

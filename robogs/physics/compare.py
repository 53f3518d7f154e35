"""Residuals of the model against every measured stream, cut into phases.

Streams of the rigid model: the tracked object position [mm] and orientation [deg] of each
trajectory. (End-effector poses drive the model, so they have no residual here; the arm model
in ``robogs.physics.arm`` compares them with forward kinematics.) Phases come from the
measured data (:mod:`robogs.physics.phases`); the noise floor from the data itself
(:mod:`robogs.physics.noise`). Datasets with cameras, panoptic masks and a Gaussian
binding also get a mask-boundary stream (:mod:`robogs.physics.masks`, attached by
:func:`robogs.physics.api.compare`) rendered from the model's predicted object poses
(:attr:`CompareResult.predicted`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from robogs.physics.engine import Engine
from robogs.physics.phases import PHASES, runs

__all__ = ["Segment", "StreamResidual", "CompareResult", "compare_recording", "residual_table"]


@dataclass
class Segment:
    """A contiguous run of one phase in one trajectory, with its residual RMS."""

    trajectory: str
    phase: str
    t_start: float
    t_end: float
    rms_mm: float
    rms_deg: float
    n: int


@dataclass
class StreamResidual:
    """Residual summary of one stream (``object_poses/<object>`` in one trajectory)."""

    stream: str
    trajectory: str
    rms_mm: float
    max_mm: float
    rms_deg: float
    per_phase_mm: dict[str, float]


@dataclass
class CompareResult:
    """Model-versus-measurement comparison.

    Attributes:
        streams: one entry per trajectory and stream.
        phases_mm: position RMS per phase over all trajectories [mm].
        worst: the worst segments, largest RMS first.
        rms_mm / rms_deg: overall position [mm] and yaw [deg] RMS.
        noise_floor_mm: RMS the true model would leave (data-estimated noise, jitter included).
        noise: estimated noise (sigma_pos_mm, sigma_yaw_deg, sigma_t_ms, source).
        times: per trajectory, sample times [s] from the episode start; residual_mm: [N, 3];
            residual_deg: [N]; phase: [N] names (for plots).
        predicted: per trajectory, the model's object poses at the valid samples: ``t_ns``,
            ``pos`` [N, 3] m, ``quat`` [N, 4] wxyz (the measured tilt turned by the model's yaw).
        masks: the mask-boundary stream (a :class:`robogs.physics.masks.MaskStream`),
            or None with the reason in ``masks_absent``.
        force: the pusher force residual where a wrench is used (``rms_n``,
            ``noise_floor_n`` [N], ``bins``; :func:`robogs.physics.prepare.force_rms`), else
            None; ``wrench_note``: how the wrench is used, or why not.
    """

    streams: list[StreamResidual]
    phases_mm: dict[str, float]
    worst: list[Segment]
    rms_mm: float
    rms_deg: float
    noise_floor_mm: float
    noise: dict[str, Any]
    series: list[dict[str, Any]] = field(default_factory=list, repr=False)
    predicted: list[dict[str, Any]] = field(default_factory=list, repr=False)
    masks: Any = None
    masks_absent: str = "not computed"
    force: dict[str, Any] | None = None
    wrench_note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (without the per-sample series)."""
        return {
            "mask_boundary": self.masks.to_dict() if self.masks is not None else None,
            "mask_boundary_absent": None if self.masks is not None else self.masks_absent,
            "streams": [asdict(s) for s in self.streams],
            "phases_mm": self.phases_mm,
            "worst": [asdict(s) for s in self.worst],
            "rms_mm": self.rms_mm,
            "rms_deg": self.rms_deg,
            "noise_floor_mm": self.noise_floor_mm,
            "noise": self.noise,
            "force": self.force,
            "wrench_note": self.wrench_note,
        }


def residual_table(eng: Engine, raw: np.ndarray) -> CompareResult:
    """Summarise raw residuals [T, N, 4] (m, rad) of an engine's recording."""
    prep = eng.prep
    mask = eng.mask
    obj = prep.rec.object_name
    streams: list[StreamResidual] = []
    segs: list[Segment] = []
    series: list[dict[str, Any]] = []
    predicted: list[dict[str, Any]] = []
    acc: dict[str, list[np.ndarray]] = {p: [] for p in PHASES}
    steps = [np.diff(tr.t_ns) for tr in prep.rec.trajectories]
    period = float(np.median(np.concatenate(steps))) * 1e-9 if sum(map(len, steps)) else 1e-3
    for i, tr in enumerate(prep.rec.trajectories):
        m = mask[i]
        e = raw[i][m]
        mn = m[: len(tr.t_ns)]
        predicted.append(_predicted(tr.name, tr.t_ns[mn], tr.object_pos[mn], tr.object_quat[mn], e))
        pos_mm = np.linalg.norm(e[:, :3], axis=-1) * 1000.0
        yaw_deg = np.degrees(e[:, 3])
        ph = prep.phase[i][m]
        t = (tr.t_ns[mn] - tr.t_ns[0]) * 1e-9
        # a segment of samples a..b-1 spans [t[a], t[b]): it ends where the next one starts;
        # the last one (and a single-sample one) ends one median sample period after its sample
        t_next = np.append(t[1:], t[-1] + period)
        per = {}
        for j, name in enumerate(PHASES):
            sel = ph == j
            if sel.any():
                per[name] = float(np.sqrt(np.mean(pos_mm[sel] ** 2)))
                acc[name].append(pos_mm[sel])
            for a, b in runs(sel):
                segs.append(
                    Segment(
                        tr.name,
                        name,
                        float(t[a]),
                        float(t_next[b - 1]),
                        float(np.sqrt(np.mean(pos_mm[a:b] ** 2))),
                        float(np.sqrt(np.mean(yaw_deg[a:b] ** 2))),
                        int(b - a),
                    )
                )
        streams.append(
            StreamResidual(
                stream=f"object_poses/{obj}",
                trajectory=tr.name,
                rms_mm=float(np.sqrt(np.mean(pos_mm**2))),
                max_mm=float(pos_mm.max()),
                rms_deg=float(np.sqrt(np.mean(yaw_deg**2))),
                per_phase_mm=per,
            )
        )
        series.append(
            {
                "trajectory": tr.name,
                "t": t,
                "residual_mm": e[:, :3] * 1000.0,
                "residual_deg": yaw_deg,
                "phase": [PHASES[k] for k in ph],
            }
        )
    phases_mm = {p: float(np.sqrt(np.mean(np.concatenate(v) ** 2))) for p, v in acc.items() if v}
    segs.sort(key=lambda s: -s.rms_mm)
    sel = raw[mask]
    floor = float(np.sqrt(np.mean(np.sum(prep.sig_pos.numpy()[mask] ** 2, axis=-1))) * 1000.0)
    return CompareResult(
        streams=streams,
        phases_mm=phases_mm,
        worst=segs[:5],
        rms_mm=float(np.sqrt(np.mean(np.sum(sel[:, :3] ** 2, axis=-1))) * 1000.0),
        rms_deg=float(np.degrees(np.sqrt(np.mean(sel[:, 3] ** 2)))),
        noise_floor_mm=floor,
        noise={
            "sigma_pos_mm": prep.noise.sigma_pos * 1000,
            "sigma_yaw_deg": float(np.degrees(prep.noise.sigma_yaw)),
            "sigma_t_ms": prep.noise.sigma_t * 1000,
            "source": prep.noise.source,
        },
        series=series,
        predicted=predicted,
    )


def _predicted(
    name: str, t_ns: np.ndarray, pos: np.ndarray, quat: np.ndarray, e: np.ndarray
) -> dict[str, Any]:
    """Model poses from measured ones and residuals ``e`` [N, 4] (measured minus predicted)."""
    half = -0.5 * e[:, 3]  # turn the measured orientation by the yaw error, about world z
    cz, sz = np.cos(half), np.sin(half)
    w, x, y, z = (quat[:, k] for k in range(4))
    q = np.stack([cz * w - sz * z, cz * x - sz * y, cz * y + sz * x, cz * z + sz * w], -1)
    return {"trajectory": name, "t_ns": t_ns, "pos": pos - e[:, :3], "quat": q}


def compare_recording(
    recording: object, *, dt: float = 1e-3, engine: Engine | None = None
) -> CompareResult:
    """Compare the model with stored (physics.json) parameters against the measurements.

    Nothing is refitted; the initial object pose of every trajectory is the measured one.
    """
    eng = engine or Engine(recording, dt=dt)
    space = eng.space([])
    th = eng.start(space)
    r = eng.evaluate(space, th[None], np.zeros((1, eng.prep.n_traj, 3)))[0]
    return residual_table(eng, eng.raw(r))

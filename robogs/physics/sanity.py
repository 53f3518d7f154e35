"""Does the model reproduce the gross motion at all? Checks run before any effect is judged.

An effect ranking is only meaningful when the base model already follows the data to within a
few noise floors. :func:`assess` looks, per trajectory, at the measured data and the base
model's residuals and names the likely cause when it does not:

* **pusher never reaches the object** - the object moves by more than ``move_m`` but the
  pusher (``objects.pusher``: link, ``offset_m``, ``radius_m``) never comes within
  ``max(10 mm, 10 sigma)`` of the box surface (a wrong link, offset or radius, or a missing
  stream);
* **no contact phase found** - the object moves but no sample is close enough to be contact;
* **motion without contact** - the object starts to move while the pusher is still more than
  that margin away (a pusher offset or a clock offset the model cannot bridge);
* **residual >> noise** - the base fit's position RMS exceeds ``ratio`` (10) x the noise floor.

Every physics command prints these findings (:func:`finish_command`); ``diagnose`` that finds
no effect while the model fails says so instead of "none above the noise" and exits 1.

Apart from those, a trajectory the base model follows much worse than the others is named
(``outliers``, printed by every command, exit code unchanged): its position RMS lies more than
``z_out`` (5) robust standard deviations (1.4826 x the median absolute deviation across this
recording's trajectories) above their median. The spread comes from the recording itself, and
a bias of the noise floor estimate, common to all trajectories, cancels. Such a trajectory pulls
every fitted parameter, and no catalogue effect may explain it: a strike whose outcome the
engine models differently, a tracking glitch, a mislabelled episode.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "Finding",
    "Sanity",
    "assess",
    "trajectory_outliers",
    "bound_notes",
    "note_diagnosis",
    "none_found_text",
    "finish_command",
]


@dataclass
class Finding:
    """One reason the model cannot reproduce a trajectory (``trajectory`` "all": overall)."""

    trajectory: str
    cause: str
    message: str
    figures: dict[str, float] = field(default_factory=dict)


@dataclass
class Sanity:
    """Outcome of :func:`assess`: findings (empty: the model follows the gross motion)."""

    findings: list[Finding]
    rms_mm: float
    noise_floor_mm: float
    ratio: float
    outliers: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.findings

    def lines(self) -> list[str]:
        """Human-readable lines (empty when ok)."""
        if self.ok:
            return []
        out = [
            f"the model does not reproduce the data: position rms {self.rms_mm:.1f} mm vs noise "
            f"floor {self.noise_floor_mm:.2f} mm ({self.rms_mm / max(self.noise_floor_mm, 1e-9):.0f}x)"
        ]
        out += [f"  {f.trajectory}: {f.message}" for f in self.findings]
        return out

    def outlier_lines(self) -> list[str]:
        """One line per trajectory the model follows far worse than the others (may be empty)."""
        return [f"{f.trajectory}: {f.message}" for f in self.outliers]

    def to_dict(self) -> dict[str, Any]:
        return {
            "reproduces_data": self.ok,
            "rms_mm": self.rms_mm,
            "noise_floor_mm": self.noise_floor_mm,
            "ratio_limit": self.ratio,
            "findings": [asdict(f) for f in self.findings],
            "outliers": [asdict(f) for f in self.outliers],
        }


def trajectory_outliers(per_traj: dict[str, float], z_out: float = 5.0) -> list[Finding]:
    """Trajectories whose base-model position RMS [mm] lies more than ``z_out`` robust standard
    deviations above the median across trajectories (fewer than 5 trajectories, or no spread:
    none). The spread is 1.4826 x the median absolute deviation, taken on this recording."""
    if len(per_traj) < 5:
        return []
    names = list(per_traj)
    r = np.array([per_traj[n] for n in names], float)
    med = float(np.median(r))
    spread = 1.4826 * float(np.median(np.abs(r - med)))
    if not spread > 0:
        return []
    out = []
    for name, x in zip(names, r, strict=True):
        z = (x - med) / spread
        if z > z_out:
            out.append(
                Finding(
                    name,
                    "trajectory_not_reproduced",
                    f"the base model's residual {x:.2f} mm is {x / med:.1f}x the median "
                    f"trajectory's {med:.2f} mm ({z:.0f} robust sd above it, limit {z_out:g}); "
                    "this trajectory pulls every fitted parameter and may hold what no "
                    "catalogue effect explains (a strike the engine models differently, a "
                    "tracking glitch); look at it (robogs report), and where its data "
                    "are at fault leave the episode out of the dataset",
                    {"rms_mm": float(x), "median_mm": med, "robust_sd_mm": spread, "z": float(z)},
                )
            )
    return out


def assess(
    rec: Any,
    base: Any | None = None,
    *,
    dt: float = 1e-3,
    ratio: float = 10.0,
    move_m: float = 0.01,
) -> Sanity:
    """Check that the base model can follow ``rec`` (a :class:`~robogs.physics.recording.
    Recording`); ``base``: its baseline :class:`~robogs.physics.compare.CompareResult`
    (default: :func:`robogs.physics.baseline.baseline`, memoised)."""
    from robogs.physics.noise import estimate_noise
    from robogs.physics.phases import PHASES, segment_phases
    from robogs.physics.recording import as_recording
    from robogs.physics.scene import scene_from_physics

    rec = as_recording(rec)
    if base is None:
        from robogs.physics.baseline import baseline

        base = baseline(rec, dt=dt, backend=_backend(rec)).result
    scene = scene_from_physics(rec.physics, rec.object_name, dt=dt)
    sig = float(estimate_noise(rec, None).sigma_pos)
    margin = max(0.010, 10.0 * sig)
    half = 0.5 * min(scene.size[0], scene.size[1])
    floor = float(base.noise_floor_mm)
    mine = f"object_poses/{rec.object_name}"  # not the other tracked objects' rows
    per_traj = {s.trajectory: s.rms_mm for s in base.streams if s.stream == mine}
    findings: list[Finding] = []
    for tr in rec.trajectories:
        lab = segment_phases(
            tr,
            size=scene.size,
            table_z=scene.table_z,
            pusher_radius=scene.pusher_radius,
            pusher_length=scene.pusher_length,
            sigma_pos=sig,
        )
        p0 = np.median(tr.object_pos[: min(3, len(tr.t_ns))], axis=0)
        moved = float(np.max(np.linalg.norm(tr.object_pos[:, :2] - p0[:2], axis=1)))
        if moved < move_m or bool(np.any(tr.grasp)):
            continue
        gap = lab.pusher_gap
        g_min = float(np.min(gap)) if np.isfinite(gap).any() else float("inf")
        figs = {
            "object_moved_mm": 1e3 * moved,
            "closest_approach_mm": 1e3 * g_min,
            "pusher_radius_mm": 1e3 * scene.pusher_radius,
            "half_size_mm": 1e3 * half,
        }
        if g_min > margin:
            findings.append(
                Finding(
                    tr.name,
                    "pusher_never_reaches",
                    f"the object moves {1e3 * moved:.0f} mm but the pusher never reaches it: "
                    f"closest approach {1e3 * g_min:.0f} mm from the box surface (pusher radius "
                    f"{1e3 * scene.pusher_radius:.0f} mm, box half size {1e3 * half:.0f} mm); "
                    "check objects.pusher.link, offset_m and radius_m, and the box size",
                    figs,
                )
            )
            continue
        if not np.any(lab.label == PHASES.index("contact")):
            findings.append(
                Finding(
                    tr.name,
                    "no_contact_phase",
                    f"the object moves {1e3 * moved:.0f} mm but no contact phase is found "
                    f"(closest approach {1e3 * g_min:.1f} mm); check the pusher geometry",
                    figs,
                )
            )
            continue
        disp = np.linalg.norm(tr.object_pos[:, :2] - p0[:2], axis=1)
        i_mv = int(np.argmax(disp > max(0.005, 5.0 * sig)))  # first clearly displaced sample
        g_before = float(np.min(gap[: i_mv + 1]))
        if g_before > margin:
            t = 1e-9 * (int(tr.t_ns[i_mv]) - int(tr.t_ns[0]))
            findings.append(
                Finding(
                    tr.name,
                    "motion_without_contact",
                    f"the object has moved {1e3 * disp[i_mv]:.0f} mm at {t:.2f} s while the "
                    f"pusher has come no closer than {1e3 * g_before:.0f} mm; check "
                    "objects.pusher.offset_m and the clocks of the streams",
                    {**figs, "gap_before_motion_mm": 1e3 * g_before},
                )
            )
            continue
        r = per_traj.get(tr.name)
        if r is not None and floor > 0 and r > ratio * floor:
            findings.append(
                Finding(
                    tr.name,
                    "residual_above_noise",
                    f"base-model residual {r:.1f} mm is {r / floor:.0f}x the noise floor "
                    f"{floor:.2f} mm before any effect",
                    {"rms_mm": float(r), "noise_floor_mm": floor},
                )
            )
    rms = float(base.rms_mm)
    if not findings and floor > 0 and rms > ratio * floor:
        findings.append(
            Finding(
                "all",
                "residual_above_noise",
                f"base-model residual {rms:.1f} mm is {rms / floor:.0f}x the noise floor "
                f"{floor:.2f} mm before any effect",
                {"rms_mm": rms, "noise_floor_mm": floor},
            )
        )
    return Sanity(findings, rms, floor, ratio, trajectory_outliers(per_traj))


def _backend(rec: Any) -> str:
    """The engine of the sanity baseline: planar where it represents the scene, else the one
    ``auto`` picks (two objects: mujoco)."""
    from robogs.physics.engine import recording_backend

    return recording_backend(rec, "auto")[0]


def bound_notes(rec: Any, dt: float = 1e-3) -> list[str]:
    """One line per refitted base parameter that sits on a bound of its prior (or of the
    model's range): the data pull it outside what the prior allows, so its value is the bound,
    not an estimate (:func:`robogs.physics.fit.on_bounds` on the memoised baseline fit)."""
    from robogs.physics.baseline import baseline

    b = baseline(rec, dt=dt, backend=_backend(rec))
    sources = b.physics.get("sources") or {}
    out = []
    for c, side in zip(b.free, b.outcome.on_bound, strict=False):
        if not side:
            continue
        slot = b.space.slots[c]
        bound = slot.param.lower if side == "lower" else slot.param.upper
        key = f"objects.{rec.object_name}.{slot.param.name}"
        src = sources.get(key, {}).get("source") if slot.owner == "base" else None
        where = f" of {src}" if src and str(src).startswith("prior") else ""
        out.append(
            f"{slot.key} = {float(b.outcome.theta[c]):.4g} sits on its {side} bound "
            f"{bound:.4g}{where}: the data pull it beyond; check the prior "
            f"(robogs physics set ... {key}=...) or the model"
        )
    return out


def _recordings() -> list[Any]:
    from robogs.physics.split import current_split

    log = current_split()
    seen: list[Any] = []
    for r in log.recordings if log is not None else []:
        if all(r is not s for s in seen):
            seen.append(r)
    return seen


def _assess_all() -> list[Sanity]:
    """The findings on the first recording the command loaded (memoised in the log)."""
    from robogs.physics.split import current_split

    log = current_split()
    if log is None:
        return []
    if "sanity" not in log.notes:
        log.notes["sanity"] = [assess(r) for r in _recordings()[:1]]
        log.notes["at_bound"] = [line for r in _recordings()[:1] for line in bound_notes(r)]
    return log.notes["sanity"]


def note_diagnosis(d: dict[str, Any]) -> None:
    """Record a diagnose result (its ``to_dict()``, which gains a ``sanity`` entry) so that
    :func:`finish_command` exits 1 when no effect is reported while the model fails."""
    from robogs.physics.split import current_split

    log = current_split()
    sanities = _assess_all()
    if log is None or not sanities:
        return
    d["sanity"] = sanities[0].to_dict()
    log.notes["diagnose_found"] = any(e.get("reported") for e in d.get("effects", []))


def none_found_text() -> str:
    """What diagnose prints when no effect is reported: "none above the noise", unless the base
    model does not reproduce the data (then :func:`finish_command` explains and exits 1)."""
    if any(not s.ok for s in _assess_all()):
        return "none - the model does not reproduce the data (see below)"
    return "none above the noise"


def finish_command(args: argparse.Namespace, rc: int) -> int:
    """After a physics command inside :func:`~robogs.physics.split.split_option`: print the
    trajectory cut and the sanity findings; a failing ``diagnose`` that reported no effect
    exits 1. In ``--json`` mode both go to stderr as one JSON object."""
    from robogs.physics.split import current_split, cut_table

    log = current_split()
    if log is None or not log.recordings:
        return rc
    pieces = list({(p.trajectory, round(p.start_s, 6)): p for p in log.pieces}.values())
    sanities = _assess_all()
    bad = [s for s in sanities if not s.ok]
    as_json = bool(getattr(args, "json", False))
    if as_json:
        doc = {
            "split": {"mode": log.mode, "trajectories": [asdict(p) for p in pieces]},
            "sanity": [s.to_dict() for s in sanities],
            "at_bound": log.notes.get("at_bound", []),
        }
        print(json.dumps(doc, default=float), file=sys.stderr)
    else:
        if any(p.why_start != "episode start" or p.why_end != "episode end" for p in pieces):
            print(f"trajectories cut from the episodes (--split {log.mode}):")
            print(cut_table(pieces))
        for s in bad:
            for line in s.lines():
                print(line)
        for s in sanities:
            lines = s.outlier_lines()
            if lines:
                print("trajectories the model follows far worse than the others:")
            for line in lines:
                print(f"  {line}")
        for line in log.notes.get("at_bound", []):
            print(line)
    if bad and log.notes.get("diagnose_found") is False and rc == 0:
        return 1  # diagnose found nothing while the model fails: not "none above the noise"
    return rc

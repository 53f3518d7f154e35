"""Is a pose topic an object or the robot's end effector? Compare it with forward kinematics.

A pose topic whose role is a guess from its type alone is subsampled (about
:data:`PROBE_SAMPLES` poses) together with the joint states on both sides of each sample, read
after the static topics and before the main pass. If its path tracks a robot link
(:mod:`robogs.convert.ingest.ee_track`) it becomes ``ee_pose:<link>``; a tracked point that no
URDF link sits at (offset over :data:`MAX_EE_OFFSET_M`) becomes a generic table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .msg_fields import floats
from .provenance import Provenance
from .roles import Role
from .stamps import StampClock
from .topic_plan import TopicPlan

__all__ = ["MAX_EE_OFFSET_M", "PROBE_SAMPLES", "PoseProbe", "robot_chain"]

PROBE_SAMPLES = 3000
MAX_EE_OFFSET_M = 0.01


@dataclass
class _Samples:
    """Samples of a pose topic kept to compare it with forward kinematics."""

    stride: int
    seen: int = 0
    frame: str | None = None
    t: list[int] = field(default_factory=list)
    xyz: list[tuple[float, float, float]] = field(default_factory=list)


def robot_chain(urdf: Path | None, description: str | None, prov: Provenance) -> Any:
    """The robot's :class:`~robogs.format.kinematics.Chain` from ``--urdf`` or the
    ``/robot_description`` text, or None (with a note when it does not load)."""
    import tempfile

    from robogs.format.errors import RobogsError
    from robogs.format.kinematics import Chain
    from robogs.format.urdf import load_urdf

    try:
        if urdf is not None:
            return Chain.from_urdf(load_urdf(urdf, load_meshes=False))
        if description:
            with tempfile.TemporaryDirectory(prefix="robogs-urdf-") as tmp:
                path = Path(tmp) / "robot_description.urdf"
                path.write_text(description, encoding="utf-8")
                return Chain.from_urdf(load_urdf(path, load_meshes=False))
    except RobogsError as exc:
        prov.note(f"pose roles not compared with the robot ({exc.message})")
    return None


class PoseProbe:
    """Subsamples of the probed pose topics and of the joint states around them.

    Args:
        plan: the topic plan (its ``probe`` topics, ``joint_topic`` and ``counts``).
        clock: stamps of the probed messages.
        prov: where the decisions are recorded.
    """

    def __init__(self, plan: TopicPlan, clock: StampClock, prov: Provenance) -> None:
        self.plan = plan
        self.clock = clock
        self.prov = prov
        self._samples = {t: _Samples(max(1, plan.counts[t] // PROBE_SAMPLES)) for t in plan.probe}
        self._joints: dict[int, tuple[list[str], np.ndarray]] = {}
        self._last: tuple[int, list[str], np.ndarray] | None = None
        self._want_next = False

    @property
    def topics(self) -> list[str]:
        """The topics to read in the probe pass (the probed poses and the joint topic)."""
        if not self._samples or self.plan.joint_topic is None:
            return []
        return sorted([*self._samples, self.plan.joint_topic])

    def add(self, topic: str, log_time: int, msg: Any) -> None:
        """Keep a subsample of a probed pose topic, and the joint states around each sample."""
        t = self.clock.probe_stamp(msg, log_time)
        if topic == self.plan.joint_topic:
            names, pos = list(msg.name), floats(msg.position)
            if pos.size != len(names):
                return
            self._last = (t, names, pos)
            if self._want_next:
                self._joints[t] = (names, pos)
                self._want_next = False
            return
        pr = self._samples.get(topic)
        if pr is None:
            return
        pr.seen += 1
        if (pr.seen - 1) % pr.stride:
            return
        if hasattr(msg, "transform"):
            p = msg.transform.translation
        else:
            pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
            p = pose.position
        xyz = (float(p.x), float(p.y), float(p.z))
        if not all(math.isfinite(v) for v in xyz):
            return
        if pr.frame is None:
            pr.frame = str(msg.header.frame_id).lstrip("/")
        pr.t.append(t)
        pr.xyz.append(xyz)
        if self._last is not None:  # the joint states on both sides of the pose
            self._joints[self._last[0]] = self._last[1:]
        self._want_next = True

    def decide(self, urdf: Path | None, description: str | None) -> None:
        """Pose topics that track a robot link become ``ee_pose:<link>`` in the plan."""
        if not self._samples:
            return
        from .ee_track import link_fits, tracked_link

        plan = self.plan
        chain = robot_chain(urdf, description, self.prov)
        joints = self._joint_arrays(chain)
        for topic, pr in sorted(self._samples.items()):
            if chain is None or joints is None or pr.frame not in chain.link_names:
                if chain is not None and pr.frame is not None and joints is not None:
                    plan.reasons[topic] += f"; frame {pr.frame!r} is not a robot link"
                continue
            fits = link_fits(chain, pr.frame, *joints, np.array(pr.t), np.array(pr.xyz))
            hit = tracked_link(fits)
            if hit is None:
                if fits:
                    best = min(fits, key=lambda f: f.rms_m)
                    plan.reasons[topic] += (
                        f"; tracks no robot link (best {best.link}: rms "
                        f"{best.rms_m * 1e3:.1f} mm over {best.spread_m * 1e3:.0f} mm of motion)"
                    )
                continue
            fit = (
                f"path tracks link {hit.link} (rms {hit.rms_m * 1e3:.2f} mm, offset "
                f"{hit.offset_m * 1e3:.1f} mm, {hit.samples} samples)"
            )
            if hit.offset_m <= MAX_EE_OFFSET_M:
                role, why = Role("ee_pose", hit.link), f"{fit}: end-effector, not an object"
            else:
                role, why = (
                    Role("generic"),
                    (
                        f"{fit}: no URDF link sits at the tracked point, so it is neither an object "
                        "nor a link's pose; decoded into a generic table (add a TCP link to the URDF "
                        f"and map it with --topic ee_pose:LINK={topic})"
                    ),
                )
            plan.roles[topic] = role
            plan.reasons[topic] = why
            rec = self.prov.topic(topic)
            rec.role, rec.reason = str(role), why

    def _joint_arrays(self, chain: Any) -> tuple[np.ndarray, np.ndarray] | None:
        """Kept joint samples as sorted ``([M] t_ns, [M, J] q)`` in the chain's joint order."""
        if chain is None:
            return None
        rows = [(t, n, p) for t, (n, p) in self._joints.items()]
        out_t, out_q = [], []
        for t, names, pos in rows:
            idx = {n: i for i, n in enumerate(names)}
            if any(j not in idx for j in chain.joint_names):
                continue
            out_t.append(t)
            out_q.append([pos[idx[j]] for j in chain.joint_names])
        if len(out_t) < 2:
            missing = sorted(set(chain.joint_names) - set(rows[0][1])) if rows else []
            self.prov.note(
                "pose roles not compared with the robot: "
                + (f"joint states lack {missing[:5]}" if missing else "too few joint states")
            )
            return None
        t = np.asarray(out_t, np.int64)
        order = np.argsort(t, kind="stable")
        t, q = t[order], np.asarray(out_q, np.float64)[order]
        keep = np.concatenate([[True], np.diff(t) > 0])
        return t[keep], q[keep]

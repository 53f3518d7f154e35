"""Turn decoded ROS messages into dataset streams (shared by the bag and MCAP readers).

A reader (``rosbag_source``, ``mcap_source``) lists its topics, asks :meth:`MessageIngest.plan`
which to read, feeds the first-pass topics (``/tf_static``, ``/tf``, ``/robot_description``, and
``camera_info`` when there is a ``/tf``) first through :meth:`MessageIngest.handle`, then every
other wanted message in log-time order, and finally calls :meth:`MessageIngest.finish`. Moving TF
frames become object poses and camera extrinsics (:mod:`robogs.convert.ingest.tf_ingest`). Messages are duck-typed: rosbags and ``mcap_ros2`` objects
both work, with ROS 1 (``K``, ``D``) or ROS 2 (``k``, ``d``) field names.

Stamps: per topic, ``header.stamp`` is used when the first message's stamp is plausible
(non-zero and within the recording's time range +- ``stamp_tolerance_ns``); otherwise the
log time. Later messages of a header-stamped topic whose stamp is implausible are dropped and
recorded with topic and stamp. The chosen source is recorded per stream (``stamp_source``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format.cameras import CameraModel
from robogs.format.errors import InputError
from robogs.format.images import encode_label_png

from .bag_options import BagOptions
from .calibration import camera_from_info_msg
from .context import IngestContext
from .generic import GenericTable
from .roles import Role, camera_name_from_topic, default_role, normalize_type, parse_role, safe_name
from .ros_images import decode_compressed_image, decode_raw_image
from .sinks import CameraSink, TableSink, median_rate_hz
from .tf_buffer import Hop, poses_of
from .tf_ingest import TfIngest, TfObject, stamp_ns
from .tf_tree import matrix_to_pose, pose_to_matrix

__all__ = ["TopicInfo", "MessageIngest", "PRODUCTIVE_ROLES", "STATIC_ROLES"]

#: roles that put data into the dataset
PRODUCTIVE_ROLES = frozenset(
    {
        "joint_states",
        "camera_image",
        "camera_info",
        "camera_labels",
        "object_pose",
        "ee_pose",
        "wrench",
    }
)
#: roles read before everything else (``/tf`` too: the whole tree is known before the main pass)
STATIC_ROLES = frozenset({"tf_static", "tf", "robot_description"})

_ROLE_TYPES: dict[str, set[str]] = {
    "joint_states": {"sensor_msgs/msg/JointState"},
    "camera_image": {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"},
    "camera_labels": {"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"},
    "camera_info": {"sensor_msgs/msg/CameraInfo"},
    "object_pose": {
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "geometry_msgs/msg/TransformStamped",
    },
    "ee_pose": {
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "geometry_msgs/msg/TransformStamped",
    },
    "wrench": {"geometry_msgs/msg/WrenchStamped"},
    "tf_static": {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"},
    "tf": {"tf2_msgs/msg/TFMessage", "tf/msg/tfMessage"},
    "robot_description": {"std_msgs/msg/String"},
}
_WORLD_CANDIDATES = ("world", "base_link", "base", "map", "odom")
_POSE_COLS = ["x", "y", "z", "qw", "qx", "qy", "qz"]
_WRENCH_COLS = ["fx", "fy", "fz", "tx", "ty", "tz"]
_MAX_PENDING_LABELS = 256
_PROBE_SAMPLES = 3000
_MAX_EE_OFFSET_M = 0.01


@dataclass
class _Probe:
    """Samples of a pose topic kept to compare it with forward kinematics."""

    stride: int
    seen: int = 0
    frame: str | None = None
    t: list[int] = field(default_factory=list)
    xyz: list[tuple[float, float, float]] = field(default_factory=list)


def _wrench_streams(topics: list[str]) -> dict[str, tuple[str, str]]:
    """Stream name and file stem of each wrench topic: ``wrenches`` for one topic, else one
    stream per topic named after it (``wrenches/netft_data``)."""
    if len(topics) == 1:
        return {topics[0]: ("wrenches", "wrenches")}
    out: dict[str, tuple[str, str]] = {}
    used: set[str] = set()
    for t in sorted(topics):
        base = safe_name(t)
        name = base
        k = 1
        while name in used:
            k += 1
            name = f"{base}_{k}"
        used.add(name)
        out[t] = (f"wrenches/{name}", f"wrenches_{name}")
    return out


@dataclass(frozen=True)
class TopicInfo:
    """A topic as listed by a reader: name, message type, indexed message count."""

    topic: str
    msgtype: str
    count: int


@dataclass
class _JointLayout:
    names: list[str]
    index: dict[str, int]
    has_vel: bool
    has_eff: bool


@dataclass
class _Camera:
    name: str
    image_topic: str | None = None
    info_topic: str | None = None
    model: CameraModel | None = None
    info_key: tuple | None = None
    frame_id: str = ""
    sink: CameraSink | None = None
    stamp_source: str | None = None
    frame_of: dict[int, int] | None = None
    labels_topic: str | None = None


def _floats(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=np.float64).reshape(-1)


class MessageIngest:
    """Routes decoded messages to table and camera sinks by topic role.

    Args:
        ctx: the conversion context.
        time_range: ``(start_ns, end_ns)`` of the recording's log times, for plausibility of
            header stamps (``None``: any non-zero stamp is plausible).
    """

    def __init__(self, ctx: IngestContext, *, time_range: tuple[int, int] | None) -> None:
        self.ctx = ctx
        self.opts = ctx.options
        self.bag: BagOptions = ctx.options.source_as(BagOptions)
        self.prov = ctx.provenance
        self.time_range = time_range
        self.roles: dict[str, Role] = {}
        self.types: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.read: dict[str, int] = {}
        self.tf = TfIngest(
            self.prov,
            self._plausible,
            tolerance_ns=self.bag.tf_tolerance_ns,
            spill_rows=self.bag.tf_spill_rows,
        )
        self._static_topics: set[str] = set()
        self._main_started = False
        self._stamp_src: dict[str, str] = {}
        self._joint_topic: str | None = None
        self._joint_layout: _JointLayout | None = None
        self._joint_sink: TableSink | None = None
        self._pose_sinks: dict[str, TableSink] = {}
        self._wrench_sinks: dict[str, TableSink] = {}
        self._generic: dict[str, GenericTable] = {}
        self.reasons: dict[str, str] = {}
        self.probe_topics: list[str] = []
        self._wrench_streams: dict[str, tuple[str, str]] = {}
        self._probe: dict[str, _Probe] = {}
        self._probe_joints: dict[int, tuple[list[str], np.ndarray]] = {}
        self._probe_last: tuple[int, list[str], np.ndarray] | None = None
        self._probe_want_next = False
        self._cameras: dict[str, _Camera] = {}
        self._pose_frames: dict[str, np.ndarray | list[Hop] | None] = {}
        self._pending_labels: dict[str, list[tuple[int, np.ndarray]]] = {}
        self._labels_writers: dict[str, tuple[pq.ParquetWriter, int]] = {}
        self._world: str | None = None
        ctx.clock = ctx.clock or "ros_time"

    # ------------------------------------------------------------------ planning
    def plan(self, topics: list[TopicInfo]) -> tuple[list[str], list[str]]:
        """Give every topic a role and record the ignored ones in the provenance.

        Returns:
            ``(static_topics, main_topics)``: read the first list completely before the second.

        Raises:
            InputError: a role that does not fit the topic's type, a role naming an absent
                topic, or no topic that puts data into the dataset.
        """
        overrides = {
            t: parse_role(r, where=f"role of {t}") if isinstance(r, str) else r
            for t, r in {**self.bag.role_map, **self.opts.roles}.items()
        }
        known = {t.topic for t in topics}
        missing = sorted(set(overrides) - known)
        if missing:
            raise InputError(
                f"role given for topics not in the source: {', '.join(missing)}",
                where="--topic/--map",
                hint=f"topics: {', '.join(sorted(known)) or 'none'}",
            )
        reasons = self.reasons
        for info in topics:
            t = normalize_type(info.msgtype)
            self.types[info.topic] = t
            self.counts[info.topic] = info.count
            if info.topic in overrides:
                role = overrides[info.topic]
                if role.kind not in ("ignore", "generic") and t not in _ROLE_TYPES.get(
                    role.kind, set()
                ):
                    raise InputError(
                        f"topic {info.topic} has type {t}, which cannot be {role}",
                        where="--topic/--map",
                        hint=f"{role.kind} takes {', '.join(sorted(_ROLE_TYPES[role.kind]))}",
                    )
                reason = "mapped to ignore" if role.kind == "ignore" else "given by --topic/--map"
            else:
                role, reason = default_role(info.topic, t)
            self.roles[info.topic] = role
            reasons[info.topic] = reason
        self._choose_joint_topic(overrides, reasons)
        for info in topics:
            role = self.roles[info.topic]
            rec = self.prov.topic(info.topic, self.types[info.topic], str(role))
            rec.messages = info.count
            rec.reason = reasons.get(info.topic)
            if role.kind == "ignore" and info.count:
                self.prov.drop(info.topic, reasons.get(info.topic, "ignored"), info.count)
        productive = [
            t for t, r in self.roles.items() if r.kind in PRODUCTIVE_ROLES and self.counts[t] > 0
        ]
        has_tf = any(r.kind == "tf" and self.counts[t] > 0 for t, r in self.roles.items())
        if not productive and not has_tf:
            listing = (
                "; ".join(f"{t.topic} {normalize_type(t.msgtype)} x{t.count}" for t in topics)
                or "none"
            )
            raise InputError(
                "nothing to convert: no joint states, images, camera info, poses or wrenches",
                where=f"topics: {listing}",
                hint="map topics to roles with --topic ROLE=TOPIC or --map roles.yaml",
            )
        static = [t for t, r in self.roles.items() if r.kind in STATIC_ROLES and self.counts[t] > 0]
        if has_tf:  # camera frames must be known before tf frames are chosen as objects
            static += [t for t in productive if self.roles[t].kind == "camera_info"]
            productive = [t for t in productive if self.roles[t].kind != "camera_info"]
        self._static_topics = set(static)
        generic = [t for t, r in self.roles.items() if r.kind == "generic" and self.counts[t] > 0]
        self._plan_probe(overrides)
        wrench = [t for t in productive if self.roles[t].kind == "wrench"]
        self._wrench_streams = _wrench_streams(wrench)
        return sorted(static), sorted(productive + generic)

    def _plan_probe(self, overrides: dict[str, Role]) -> None:
        """Pose topics whose role is a guess from the type alone are probed against FK."""
        robot = self.opts.urdf is not None or any(
            r.kind == "robot_description" and self.counts[t] for t, r in self.roles.items()
        )
        cands = [
            t
            for t, r in self.roles.items()
            if r.kind == "object_pose"
            and t not in overrides
            and self.counts[t] > 0
            and [p for p in t.split("/") if p][:1] != ["objects"]
        ]
        if cands and robot and self._joint_topic is not None:
            self._probe = {t: _Probe(max(1, self.counts[t] // _PROBE_SAMPLES)) for t in cands}
            self.probe_topics = sorted([*cands, self._joint_topic])

    def _choose_joint_topic(self, overrides: dict[str, Role], reasons: dict[str, str]) -> None:
        cands = [t for t, r in self.roles.items() if r.kind == "joint_states"]
        if len(cands) <= 1:
            self._joint_topic = cands[0] if cands else None
            return
        forced = [t for t in cands if t in overrides]
        if len(forced) > 1:
            raise InputError(
                f"several topics mapped to joint_states: {', '.join(forced)}",
                where="--topic/--map",
                hint="map one; ignore the others",
            )
        chosen = (
            forced[0]
            if forced
            else (
                "/joint_states"
                if "/joint_states" in cands
                else max(cands, key=lambda t: (self.counts[t], t))
            )
        )
        for t in cands:
            if t != chosen:
                self.roles[t] = Role("generic")
                reasons[t] = (
                    f"another topic provides joint_states ({chosen}); decoded into a generic table"
                )
        self._joint_topic = chosen

    # ------------------------------------------------------------------ stamps
    def _plausible(self, t: int) -> bool:
        if t <= 0:
            return False
        if self.time_range is None:
            return True
        tol = self.bag.stamp_tolerance_ns
        return self.time_range[0] - tol <= t <= self.time_range[1] + tol

    def _stamp(self, topic: str, msg: Any, log_time: int) -> int | None:
        header = getattr(msg, "header", None)
        src = self._stamp_src.get(topic)
        if src is None:
            t_hdr = stamp_ns(header.stamp) if header is not None else 0
            src = "sensor_header" if header is not None and self._plausible(t_hdr) else "log_time"
            if header is not None and src == "log_time":
                self.prov.note(
                    f"{topic}: header.stamp {t_hdr} is zero or outside the recording's time range; "
                    "log time used for this topic"
                )
            self._stamp_src[topic] = src
            self.prov.topic(topic).stamp_source = src
        if src == "log_time":
            return int(log_time)
        t = stamp_ns(header.stamp)
        if not self._plausible(t):
            self.prov.issue(
                topic, "header stamp zero or outside the recording's time range (sample dropped)", t
            )
            return None
        return t

    def _log_stamp(self, topic: str, log_time: int) -> int:
        """Log time as the stamp of a topic whose messages have no header stamp."""
        if topic not in self._stamp_src:
            self._stamp_src[topic] = "log_time"
            self.prov.topic(topic).stamp_source = "log_time"
        return int(log_time)

    def _sink_kwargs(self) -> dict[str, Any]:
        return {
            "provenance": self.prov,
            "jump_back_ns": self.bag.jump_back_ns,
            "jump_forward_ns": self.bag.jump_forward_ns,
        }

    # ------------------------------------------------------------------ probing
    def probe(self, topic: str, log_time: int, msg: Any) -> None:
        """Keep a subsample of a probed pose topic, and the joint states around each sample
        (read the probe topics after the static ones and before the main pass)."""
        header = getattr(msg, "header", None)
        t = stamp_ns(header.stamp) if header is not None else 0
        t = t if self._plausible(t) else int(log_time)
        if topic == self._joint_topic:
            names, pos = list(msg.name), _floats(msg.position)
            if pos.size != len(names):
                return
            self._probe_last = (t, names, pos)
            if self._probe_want_next:
                self._probe_joints[t] = (names, pos)
                self._probe_want_next = False
            return
        pr = self._probe.get(topic)
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
        if self._probe_last is not None:  # the joint states on both sides of the pose
            self._probe_joints[self._probe_last[0]] = self._probe_last[1:]
        self._probe_want_next = True

    def _decide_probed(self) -> None:
        """Pose topics that track a robot link become ``ee_pose:<link>`` (see ``ee_track``)."""
        if not self._probe:
            return
        from .ee_track import link_fits, tracked_link

        chain = self._robot_chain()
        joints = self._probe_joint_arrays(chain)
        for topic, pr in sorted(self._probe.items()):
            if chain is None or joints is None or pr.frame not in chain.link_names:
                if chain is not None and pr.frame is not None and joints is not None:
                    self.reasons[topic] += f"; frame {pr.frame!r} is not a robot link"
                continue
            fits = link_fits(chain, pr.frame, *joints, np.array(pr.t), np.array(pr.xyz))
            hit = tracked_link(fits)
            if hit is None:
                if fits:
                    best = min(fits, key=lambda f: f.rms_m)
                    self.reasons[topic] += (
                        f"; tracks no robot link (best {best.link}: rms "
                        f"{best.rms_m * 1e3:.1f} mm over {best.spread_m * 1e3:.0f} mm of motion)"
                    )
                continue
            fit = (
                f"path tracks link {hit.link} (rms {hit.rms_m * 1e3:.2f} mm, offset "
                f"{hit.offset_m * 1e3:.1f} mm, {hit.samples} samples)"
            )
            if hit.offset_m <= _MAX_EE_OFFSET_M:
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
            self.roles[topic] = role
            self.reasons[topic] = why
            rec = self.prov.topic(topic)
            rec.role, rec.reason = str(role), why

    def _robot_chain(self) -> Any:
        """The robot's :class:`~robogs.format.kinematics.Chain`, or None (with a note)."""
        import tempfile
        from pathlib import Path

        from robogs.format.errors import RobogsError
        from robogs.format.kinematics import Chain
        from robogs.format.urdf import load_urdf

        try:
            if self.opts.urdf is not None:
                return Chain.from_urdf(load_urdf(self.opts.urdf, load_meshes=False))
            if self.ctx.robot_description:
                with tempfile.TemporaryDirectory(prefix="robogs-urdf-") as tmp:
                    path = Path(tmp) / "robot_description.urdf"
                    path.write_text(self.ctx.robot_description, encoding="utf-8")
                    return Chain.from_urdf(load_urdf(path, load_meshes=False))
        except RobogsError as exc:
            self.prov.note(f"pose roles not compared with the robot ({exc.message})")
        return None

    def _probe_joint_arrays(self, chain: Any) -> tuple[np.ndarray, np.ndarray] | None:
        """Kept joint samples as sorted ``([M] t_ns, [M, J] q)`` in the chain's joint order."""
        if chain is None:
            return None
        rows = [(t, n, p) for t, (n, p) in self._probe_joints.items()]
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

    # ------------------------------------------------------------------ dispatch
    def handle(self, topic: str, log_time: int, msg: Any) -> None:
        """Process one decoded message of a planned topic."""
        self.read[topic] = self.read.get(topic, 0) + 1
        role = self.roles.get(topic)
        if role is None or role.kind == "ignore":
            return
        if topic not in self._static_topics:
            self._begin_main()
            self.tf.emit_until(int(log_time), self._add_tf_pose)
        kind = role.kind
        if kind == "tf_static":
            self.tf.add_static(topic, msg)
            self.prov.topic(topic).written += 1
            return
        if kind == "tf":
            self.tf.add_dynamic(topic, log_time, msg)
            return
        if kind == "robot_description":
            if self.ctx.robot_description is None:
                self.ctx.robot_description = str(msg.data)
                self.prov.topic(topic).written += 1
            else:
                self.prov.drop(topic, "only the first robot_description is used")
            return
        if kind == "camera_info":
            self._camera_info(topic, role, log_time, msg)
            return
        if kind == "generic" and not hasattr(getattr(msg, "header", None), "stamp"):
            t: int | None = self._log_stamp(topic, log_time)
        else:
            t = self._stamp(topic, msg, log_time)
        if t is None:
            return
        if kind == "joint_states":
            self._joint_state(topic, t, msg)
        elif kind == "camera_image":
            self._image(topic, role, t, msg)
        elif kind == "camera_labels":
            self._labels(topic, role, t, msg)
        elif kind in ("object_pose", "ee_pose"):
            self._pose(topic, role, t, msg)
        elif kind == "wrench":
            self._wrench(topic, role, t, msg)
        elif kind == "generic":
            self._generic_row(topic, t, msg)

    def note_undecodable(self, topic: str, log_time: int, error: str) -> None:
        """Record a message that the reader could not decode."""
        self.read[topic] = self.read.get(topic, 0) + 1
        self.prov.issue(topic, f"message could not be decoded ({error[:120]})", log_time)

    # ------------------------------------------------------------------ joint states
    def _joint_state(self, topic: str, t: int, msg: Any) -> None:
        if topic != self._joint_topic:
            self.prov.drop(topic, "not the joint_states topic")
            return
        names = list(msg.name)
        pos = _floats(msg.position)
        lay = self._joint_layout
        if lay is None:
            if not names or len(set(names)) != len(names) or pos.size != len(names):
                self.prov.issue(
                    topic, "JointState without unique names matching its positions (dropped)", t
                )
                return
            vel, eff = _floats(msg.velocity), _floats(msg.effort)
            lay = self._joint_layout = _JointLayout(
                names,
                {n: i for i, n in enumerate(names)},
                vel.size == len(names),
                eff.size == len(names),
            )
            cols = [f"position.{n}" for n in names]
            cols += [f"velocity.{n}" for n in names] if lay.has_vel else []
            cols += [f"effort.{n}" for n in names] if lay.has_eff else []
            self._joint_sink = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/joint_states.parquet"),
                "joint_states",
                cols,
                **self._sink_kwargs(),
            )
        n = len(lay.names)
        if names == lay.names and pos.size == n:
            parts = [pos]
            if lay.has_vel:
                parts.append(self._optional(topic, t, msg.velocity, n, "velocity"))
            if lay.has_eff:
                parts.append(self._optional(topic, t, msg.effort, n, "effort"))
        else:
            if pos.size != len(names):
                self.prov.issue(topic, "JointState with fewer positions than names (dropped)", t)
                return
            unknown = [x for x in names if x not in lay.index]
            if unknown:
                self.prov.issue(
                    topic,
                    f"joints {unknown[:5]} not in the first message (their values dropped)",
                    t,
                    drop=False,
                )
            parts = [self._by_name(names, pos, lay, topic, t, "position")]
            if lay.has_vel:
                parts.append(self._by_name(names, _floats(msg.velocity), lay, topic, t, "velocity"))
            if lay.has_eff:
                parts.append(self._by_name(names, _floats(msg.effort), lay, topic, t, "effort"))
        row = np.concatenate(parts) if len(parts) > 1 else parts[0]
        assert self._joint_sink is not None
        if self._joint_sink.add(topic, t, row.tolist()):
            self.prov.topic(topic).written += 1

    def _optional(self, topic: str, t: int, values: Any, n: int, what: str) -> np.ndarray:
        arr = _floats(values)
        if arr.size == n:
            return arr
        self.prov.issue(topic, f"JointState without {what} (NaN written)", t, drop=False)
        return np.full(n, np.nan)

    def _by_name(
        self, names: list[str], values: np.ndarray, lay: _JointLayout, topic: str, t: int, what: str
    ) -> np.ndarray:
        out = np.full(len(lay.names), np.nan)
        if values.size != len(names):
            self.prov.issue(topic, f"JointState without {what} (NaN written)", t, drop=False)
            return out
        for i, name in enumerate(names):
            j = lay.index.get(name)
            if j is not None:
                out[j] = values[i]
        if np.isnan(out).any():
            self.prov.issue(
                topic, f"JointState missing some joints' {what} (NaN written)", t, drop=False
            )
        return out

    # ------------------------------------------------------------------ cameras
    def _camera(self, name: str) -> _Camera:
        cam = self._cameras.get(name)
        if cam is None:
            cam = self._cameras[name] = _Camera(name)
        return cam

    def _camera_info(self, topic: str, role: Role, log_time: int, msg: Any) -> None:
        name = role.name or camera_name_from_topic(topic)
        cam = self._camera(name)
        if cam.info_topic is not None and cam.info_topic != topic:
            self.prov.drop(topic, f"camera {name} already has camera_info from {cam.info_topic}")
            return
        cam.info_topic = topic
        header = getattr(msg, "header", None)
        t = stamp_ns(header.stamp) if header is not None else int(log_time)
        K = _floats(getattr(msg, "k", getattr(msg, "K", ())))
        key = (
            int(msg.width),
            int(msg.height),
            tuple(K.tolist()),
            tuple(_floats(getattr(msg, "d", getattr(msg, "D", ()))).tolist()),
            str(msg.distortion_model),
        )
        if cam.info_key is None:
            cam.info_key = key
            if K.size != 9 or K[0] == 0.0:
                self.prov.issue(
                    topic, "camera is not calibrated (K[0] == 0); no intrinsics written", t
                )
                return
            cam.model = camera_from_info_msg(msg, name=name, topic=topic, t_ns=t)
            cam.frame_id = str(header.frame_id).lstrip("/") if header is not None else ""
            self.prov.topic(topic).stamp_source = (
                "sensor_header" if header is not None else "log_time"
            )
        elif key != cam.info_key:
            self.prov.issue(
                topic, "calibration differs from the first camera_info (first one kept)", t
            )
            return
        if cam.model is None:
            self.prov.drop(topic, "camera is not calibrated (K[0] == 0)")
            return
        self.prov.topic(topic).written += 1

    def _fps_hint(self, topic: str) -> float:
        n = self.counts.get(topic, 0)
        if self.time_range and n > 1 and self.time_range[1] > self.time_range[0]:
            return max(
                1.0, min(1000.0, (n - 1) / ((self.time_range[1] - self.time_range[0]) / 1e9))
            )
        return 30.0

    def _decode(self, topic: str, t: int, msg: Any) -> tuple[str, np.ndarray] | None:
        if self.types.get(topic) == "sensor_msgs/msg/CompressedImage":
            out = decode_compressed_image(msg, topic=topic, t_ns=t)
            if out is None:
                fmt = str(getattr(msg, "format", ""))[:40]
                self.prov.issue(
                    topic, f"compressed image not decodable as a still image (format {fmt!r})", t
                )
            return out
        return decode_raw_image(msg, topic=topic, t_ns=t)

    def _image(self, topic: str, role: Role, t: int, msg: Any) -> None:
        name = role.name or camera_name_from_topic(topic)
        cam = self._camera(name)
        if cam.image_topic is not None and cam.image_topic != topic:
            self.prov.drop(topic, f"camera {name} already has images from {cam.image_topic}")
            return
        if cam.sink is None:
            ep = self.ctx.episode_dir()
            w = self.ctx.writer
            cam.image_topic = topic
            cam.stamp_source = self._stamp_src.get(topic)
            cam.sink = CameraSink(
                w.path(f"{ep}/cameras/{name}/frames.parquet"),
                w.path(f"{ep}/cameras/{name}/rgb.mp4"),
                topic=topic,
                provenance=self.prov,
                video=self.bag.video,
                fps_hint=self._fps_hint(topic),
            )
            header = getattr(msg, "header", None)
            if header is not None and not cam.frame_id:
                cam.frame_id = str(header.frame_id).lstrip("/")
            cam.frame_of = {}
        if not cam.sink.accepts(t):
            return
        rgb = None
        if self.bag.video:
            out = self._decode(topic, t, msg)
            if out is None:
                return
            kind, rgb = out
            if kind != "rgb":
                self.prov.issue(
                    topic,
                    "16-bit single-channel image on a colour camera topic (map it as "
                    "camera_labels)",
                    t,
                )
                return
        elif self.types.get(topic) == "sensor_msgs/msg/Image":
            decode_raw_image(msg, topic=topic, t_ns=t)  # size checks even without video
        cam.sink.add(t, rgb)
        assert cam.frame_of is not None
        cam.frame_of[t] = cam.sink.count - 1
        self.prov.topic(topic).written += 1
        self._match_labels(cam)

    def _labels(self, topic: str, role: Role, t: int, msg: Any) -> None:
        if role.name:
            name = role.name
        else:  # /camera/<cam>/labels/compressed -> <cam>
            parts = [p for p in topic.split("/") if p]
            while parts and parts[-1] in (
                "compressed",
                "image_raw",
                "image",
                "labels",
                "label",
                "panoptic",
                "segmentation",
            ):
                parts = parts[:-1]
            name = camera_name_from_topic("/" + "/".join(parts) + "/image_raw")
        out = self._decode(topic, t, msg)
        if out is None:
            return
        kind, img = out
        if kind != "mono16":
            if img.ndim == 3 and np.array_equal(img[..., 0], img[..., 1]):
                img = img[..., 0].astype(np.uint16)
            else:
                self.prov.issue(topic, "label image is not single-channel (dropped)", t)
                return
        cam = self._camera(name)
        cam.labels_topic = cam.labels_topic or topic
        pend = self._pending_labels.setdefault(name, [])
        pend.append((t, img))
        self._match_labels(cam)
        if len(pend) > _MAX_PENDING_LABELS:
            t_old, _ = pend.pop(0)
            self.prov.issue(
                topic, "label image without a colour frame of the same stamp (dropped)", t_old
            )

    def _match_labels(self, cam: _Camera) -> None:
        pend = self._pending_labels.get(cam.name)
        if not pend or cam.frame_of is None:
            return
        keep = []
        for t, img in pend:
            idx = cam.frame_of.get(t)
            if idx is None:
                keep.append((t, img))
                continue
            self._write_label(cam, idx, img)
        self._pending_labels[cam.name] = keep

    def _write_label(self, cam: _Camera, frame_index: int, img: np.ndarray) -> None:
        schema = pa.schema([pa.field("frame_index", pa.int64()), pa.field("png", pa.binary())])
        entry = self._labels_writers.get(cam.name)
        if entry is None:
            path = self.ctx.writer.path(
                f"{self.ctx.episode_dir()}/cameras/{cam.name}/labels.parquet"
            )
            entry = (pq.ParquetWriter(path, schema, compression="none"), 0)
        writer, n = entry
        writer.write_table(
            pa.Table.from_arrays(
                [
                    pa.array([frame_index], pa.int64()),
                    pa.array([encode_label_png(img)], pa.binary()),
                ],
                schema=schema,
            )
        )
        self._labels_writers[cam.name] = (writer, n + 1)
        assert cam.labels_topic is not None
        self.prov.topic(cam.labels_topic).written += 1

    # ------------------------------------------------------------------ poses and wrenches
    def world_frame(self) -> str:
        """The TF frame taken as the dataset world."""
        if self._world is None:
            frames = self.tf.buf.frames
            cands = [self.bag.world_frame] if self.bag.world_frame else []
            cands += [self.ctx.robot_root_link] if self.ctx.robot_root_link else []
            cands += list(_WORLD_CANDIDATES)
            self._world = next(
                (c for c in cands if c in frames), cands[0] if self.bag.world_frame else "world"
            )
        return self._world

    def _frame_to_world(self, topic: str, frame: str) -> np.ndarray | list[Hop] | None:
        """``T_world_frame`` (static chain), the chain's hops (moving frame) or ``None``."""
        if topic in self._pose_frames:
            return self._pose_frames[topic]
        world = self.world_frame()
        T: np.ndarray | list[Hop] | None = None
        if frame and frame != world:
            hops = self.tf.buf.chain(world, frame)
            if hops is None:
                self.prov.note(
                    f"{topic}: frame {frame!r} is not connected to {world!r} in /tf or "
                    "/tf_static; poses kept as given"
                )
            elif any(h.dynamic for h in hops):
                T = hops
                self.tf.use(hops)
                self.prov.note(
                    f"{topic}: poses given in the moving frame {frame!r}, composed with the /tf "
                    f"chain to {world!r} at each stamp"
                )
            else:
                T = self.tf.buf.lookup(world, frame)
                self.prov.note(
                    f"{topic}: poses given in {frame!r}, composed with the static chain to {world!r}"
                )
        self._pose_frames[topic] = T
        return T

    # ------------------------------------------------------------------ tf
    def _robot_links(self) -> set[str]:
        """Link names of the robot (``--urdf`` or ``/robot_description``); empty if unknown."""
        from xml.etree.ElementTree import ParseError

        import defusedxml.ElementTree as ET

        try:
            if self.opts.urdf is not None:
                root = ET.parse(str(self.opts.urdf)).getroot()
            elif self.ctx.robot_description:
                root = ET.fromstring(self.ctx.robot_description)
            else:
                return set()
        except (OSError, ParseError, ValueError) as exc:
            self.prov.note(f"robot links unknown for the tf frames ({type(exc).__name__})")
            return set()
        return {str(link.get("name")) for link in root.iter("link") if link.get("name")}

    def _begin_main(self) -> None:
        """Once, after the first pass: sort the transforms and choose the tf objects."""
        if self._main_started:
            return
        self._main_started = True
        self._decide_probed()
        if not self.tf.buf.dynamic_edges:
            self.tf.finalize()
            return
        world = self.world_frame()
        cam_frames = {c.frame_id for c in self._cameras.values() if c.frame_id}
        cam_frames |= {f.lstrip("/") for f in self.bag.tf_cameras.values()}
        taken = {r.name or safe_name(t) for t, r in self.roles.items() if r.kind == "object_pose"}
        self.tf.select_objects(
            world,
            explicit=dict(self.bag.tf_objects),
            auto=self.bag.tf_auto_objects,
            camera_frames=cam_frames,
            robot_links=self._robot_links(),
            taken=taken,
        )
        for obj in self.tf.objects:
            topic = obj.source.rsplit(":", 1)[0]
            self._stamp_src[obj.source] = self.tf.stamp_source.get(topic, "log_time")

    def _pose_sink(self, kind: str) -> TableSink:
        sink = self._pose_sinks.get(kind)
        if sink is None:
            sink = self._pose_sinks[kind] = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/{kind}.parquet"),
                kind,
                _POSE_COLS,
                label_column="link" if kind == "ee_poses" else "object",
                **self._sink_kwargs(),
            )
        return sink

    def _add_tf_pose(self, obj: TfObject, t: int, vals: list[float]) -> None:
        self._pose_sink("object_poses").add(obj.source, t, vals, obj.name)

    def _pose(self, topic: str, role: Role, t: int, msg: Any) -> None:
        if hasattr(msg, "transform"):
            p, q = msg.transform.translation, msg.transform.rotation
        else:
            pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
            p, q = pose.position, pose.orientation
        vals = [float(p.x), float(p.y), float(p.z), float(q.w), float(q.x), float(q.y), float(q.z)]
        qn = math.sqrt(sum(v * v for v in vals[3:]))
        if not all(math.isfinite(v) for v in vals) or qn < 1e-9:
            self.prov.issue(
                topic, "pose with a zero or non-finite quaternion or position (dropped)", t
            )
            return
        T = self._frame_to_world(topic, str(msg.header.frame_id).lstrip("/"))
        if isinstance(T, list):  # moving frame: the chain at this stamp
            Ts, ok = self.tf.poses_at(T, np.array([t], np.int64))
            if not ok[0]:
                self.prov.issue(
                    topic, "no /tf transform of the pose's frame near this stamp (dropped)", t
                )
                return
            T = Ts[0]
        if T is not None:
            M = T @ pose_to_matrix(np.array(vals[:3]), np.array(vals[3:]))
            tr, qq = matrix_to_pose(M)
            vals = [*tr.tolist(), *qq.tolist()]
        kind = "ee_poses" if role.kind == "ee_pose" else "object_poses"
        sink = self._pose_sink(kind)
        label = role.name or safe_name(topic)
        if sink.add(topic, t, vals, label):
            self.prov.topic(topic).written += 1

    def _wrench(self, topic: str, role: Role, t: int, msg: Any) -> None:
        f, tq = msg.wrench.force, msg.wrench.torque
        vals = [float(f.x), float(f.y), float(f.z), float(tq.x), float(tq.y), float(tq.z)]
        if not all(math.isfinite(v) for v in vals):
            self.prov.issue(topic, "non-finite wrench (dropped)", t)
            return
        sink = self._wrench_sinks.get(topic)
        if sink is None:
            _, stem = self._wrench_streams.get(topic, ("wrenches", "wrenches"))
            sink = self._wrench_sinks[topic] = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/{stem}.parquet"),
                "wrenches",
                _WRENCH_COLS,
                label_column="frame",
                **self._sink_kwargs(),
            )
        frame = role.name or str(msg.header.frame_id).lstrip("/") or safe_name(topic)
        if sink.add(topic, t, vals, frame):
            self.prov.topic(topic).written += 1

    def _generic_row(self, topic: str, t: int, msg: Any) -> None:
        table = self._generic.get(topic)
        if table is None:
            table = self._generic[topic] = GenericTable(topic, self.prov)
        table.add(t, msg)
        self.prov.topic(topic).written += 1

    # ------------------------------------------------------------------ finishing
    def _stream_stamp_source(self, topics: list[str]) -> str:
        srcs = sorted({self._stamp_src.get(t, "log_time") for t in topics})
        if len(srcs) > 1:
            self.prov.note(
                f"topics {', '.join(topics)} share one table but use different stamp sources "
                "(see topics/*/stamp_source); the stream records the first"
            )
        return self._stamp_src.get(topics[0], "log_time")

    def finish(self) -> None:
        """Close every sink, write cameras, declare streams, account for unread messages."""
        ctx, ep = self.ctx, self.ctx.episode_dir()
        self._begin_main()
        self.tf.emit_until(None, self._add_tf_pose)
        if self._joint_sink is not None:
            st = self._joint_sink.close()
            if st.rows:
                assert self._joint_topic is not None
                ctx.add_stream(
                    "joint_states",
                    {
                        "kind": "joint_states",
                        "path": f"{ep}/joint_states.parquet",
                        "stamp_source": self._stream_stamp_source([self._joint_topic]),
                        "offset_ns": 0,
                        "nominal_rate_hz": st.rate_hz,
                        "source": self._joint_topic,
                    },
                    start_ns=st.start_ns,
                    end_ns=st.end_ns,
                )
        for kind, sink in sorted(self._pose_sinks.items()):
            st = sink.close()
            if st.rows:
                topics = sorted(sink.written)
                ctx.add_stream(
                    kind,
                    {
                        "kind": kind,
                        "path": f"{ep}/{kind}.parquet",
                        "stamp_source": self._stream_stamp_source(topics),
                        "offset_ns": 0,
                        "nominal_rate_hz": st.rate_hz,
                        "source": ", ".join(topics),
                    },
                    start_ns=st.start_ns,
                    end_ns=st.end_ns,
                )
                if kind == "object_poses":
                    for label in sink._labels:
                        if label:
                            ctx.writer.set_asset(label, kind="object")
        for topic, sink in sorted(self._wrench_sinks.items()):
            st = sink.close()
            if st.rows:
                name, stem = self._wrench_streams.get(topic, ("wrenches", "wrenches"))
                ctx.add_stream(
                    name,
                    {
                        "kind": "wrenches",
                        "path": f"{ep}/{stem}.parquet",
                        "stamp_source": self._stream_stamp_source([topic]),
                        "offset_ns": 0,
                        "nominal_rate_hz": st.rate_hz,
                        "source": topic,
                    },
                    start_ns=st.start_ns,
                    end_ns=st.end_ns,
                )
        self._finish_generic()
        for writer, _ in self._labels_writers.values():
            writer.close()
        self._finish_cameras()
        self.tf.account([t for t, r in self.roles.items() if r.kind == "tf"])
        self.tf.keep_static_frames(ctx.writer.manifest, self._robot_links())
        self.tf.close()
        for topic, n_index in self.counts.items():
            role = self.roles.get(topic)
            if role is None or role.kind == "ignore":
                continue
            got = self.read.get(topic, 0)
            if got < n_index:
                self.prov.drop(
                    topic, "listed in the index but not delivered by the reader", n_index - got
                )
                self.prov.note(
                    f"{topic}: {n_index - got} of {n_index} indexed messages were not delivered"
                )
            elif got > n_index:
                self.prov.topic(topic).messages = got
        for name, pend in self._pending_labels.items():
            for t, _ in pend:
                self.prov.issue(
                    self._cameras[name].labels_topic or name,
                    "label image without a colour frame of the same stamp (dropped)",
                    t,
                )

    def _finish_generic(self) -> None:
        """Write each generic table and declare its ``generic`` stream."""
        ctx, ep = self.ctx, self.ctx.episode_dir()
        used: set[str] = set()
        widen = ctx.start_ns is None  # the role streams set the episode's span when there are any
        for topic, table in sorted(self._generic.items()):
            if not table.rows:
                continue
            base = safe_name(topic)
            name, k = base, 1
            while name in used:
                k += 1
                name = f"{base}_{k}"
            used.add(name)
            tab = table.table()
            rel = f"{ep}/streams/{name}.parquet"
            ctx.writer.write_table(rel, tab, kind="generic")
            t = tab.column("t_ns").to_numpy()
            ctx.add_stream(
                f"streams/{name}",
                {
                    "kind": "generic",
                    "path": rel,
                    "stamp_source": self._stamp_src.get(topic, "log_time"),
                    "offset_ns": 0,
                    "nominal_rate_hz": median_rate_hz(t[:2001]),
                    "source": topic,
                },
                start_ns=int(t[0]) if widen else None,
                end_ns=int(t[-1]) if widen else None,
            )
            if table.lengths_only:
                self.prov.note(
                    f"{topic}: {', '.join(sorted(table.lengths_only)[:4])} kept as lengths only "
                    "(arrays over 256 elements and bytes are not copied into generic tables)"
                )
        self.prov.extra["decoded"] = self._decode_summary()

    def _decode_summary(self) -> dict[str, Any]:
        """Messages decoded and not decoded over every topic not mapped to ``ignore``, and the
        message types outside the standard ROS type stores (custom types)."""
        from rosbags.typesys import Stores, get_typestore

        std = set(get_typestore(Stores.ROS2_HUMBLE).types) | set(
            get_typestore(Stores.ROS1_NOETIC).types
        )
        undecodable = 0
        for i in self.prov.issues:
            if i["problem"].startswith("message could not be decoded"):
                undecodable += int(i["count"])
        undecodable += sum(int(u.get("messages") or 0) for u in self.prov.undecodable)
        listed = [t for t, r in self.roles.items() if r.kind != "ignore"]
        custom = sorted(
            {self.types[t] for t in listed if self.types[t] not in std and "/msg/" in self.types[t]}
        )
        return {
            "topics": len(listed) + len(self.prov.undecodable),
            "messages": sum(self.read.get(t, 0) for t in listed) - undecodable,
            "undecodable": undecodable,
            "ignored_topics": sorted(t for t, r in self.roles.items() if r.kind == "ignore"),
            "custom_types": custom,
        }

    def _camera_extrinsics(
        self, name: str, cam: _Camera, frame: str
    ) -> tuple[np.ndarray | None, str | None]:
        """``(T_world_cam, extrinsics_rel)`` of a camera: a static transform, or ``None`` and the
        path of a ``camera_extrinsics`` table written at the frame stamps (moving frame)."""
        world = self.world_frame()
        hops = self.tf.buf.chain(world, frame) if frame else None
        if hops is None:
            self.prov.note(
                f"camera {name}: no /tf or /tf_static chain from {world!r} to "
                f"{frame or '(no frame_id)'!r}; T_world_cam set to identity"
            )
            return np.eye(4), None
        if frame and "optical" not in frame and frame not in self.bag.tf_cameras.values():
            self.prov.note(
                f"camera {name}: frame {frame!r} is taken as an optical frame (x right, y down, "
                "z forward); pass --tf-camera CAM=FRAME to choose another"
            )
        if not any(h.dynamic for h in hops):
            return self.tf.buf.lookup(world, frame), None
        self.tf.use(hops)
        stamps = np.array(sorted(cam.frame_of or {}), dtype=np.int64)
        T, ok = self.tf.poses_at(hops, stamps)
        for t in stamps[~ok]:
            self.prov.issue(
                cam.image_topic or name,
                "no /tf transform of the camera frame near this frame stamp (no extrinsics row)",
                int(t),
                drop=False,
            )
        if not ok.any():
            t0 = self.tf.buf.times(*self.tf.buf.driver(hops).edge)[:1]  # type: ignore[union-attr]
            T0, _ = self.tf.poses_at(hops, np.asarray(t0, np.int64))
            self.prov.note(
                f"camera {name}: frame {frame!r} moves in /tf but no frame stamp is covered; "
                "static T_world_cam taken from the first transform"
            )
            return T0[0], None
        vals = poses_of(T[ok])
        cols = [pa.array(stamps[ok], pa.int64())] + [pa.array(vals[:, j]) for j in range(7)]
        rel = f"{self.ctx.episode_dir()}/cameras/{name}/extrinsics.parquet"
        table = pa.Table.from_arrays(cols, names=["t_ns", *_POSE_COLS])
        self.ctx.writer.write_table(rel, table, kind="camera_extrinsics")
        self.prov.note(
            f"camera {name}: frame {frame!r} moves in /tf; T_world_cam written per frame "
            f"({int(ok.sum())} rows, extrinsics time_varying)"
        )
        return None, rel

    def _finish_cameras(self) -> None:
        from dataclasses import replace

        ctx, ep = self.ctx, self.ctx.episode_dir()
        unknown = sorted(set(self.bag.tf_cameras) - set(self._cameras))
        if unknown:
            raise InputError(
                f"--tf-camera names camera(s) not in the source: {', '.join(unknown)}",
                where="--tf-camera / tf_cameras",
                hint=f"cameras: {', '.join(sorted(self._cameras)) or 'none'}",
            )
        for name, cam in sorted(self._cameras.items()):
            stats = cam.sink.close() if cam.sink is not None else None
            model = cam.model
            extrinsics_rel = None
            if model is not None:
                frame = self.bag.tf_cameras.get(name, cam.frame_id).lstrip("/")
                T, extrinsics_rel = self._camera_extrinsics(name, cam, frame)
                if stats is not None and cam.sink is not None and cam.sink.size is not None:
                    if cam.sink.size != (model.width, model.height):
                        self.prov.issue(
                            cam.image_topic or name,
                            f"image size {cam.sink.size} differs from camera_info "
                            f"{(model.width, model.height)}",
                            None,
                            drop=False,
                        )
                ext = "time_varying" if extrinsics_rel else "static"
                ctx.writer.set_camera(replace(model, T_world_cam=T, extrinsics=ext))
            elif cam.image_topic is not None:
                self.prov.note(
                    f"camera {name}: images without a usable camera_info; no intrinsics written "
                    "(pass the calibration with --map or record camera_info)"
                )
            if stats is not None and stats.rows:
                entry: dict[str, Any] = {
                    "kind": "camera",
                    "camera": name,
                    "frames": f"{ep}/cameras/{name}/frames.parquet",
                    "stamp_source": cam.stamp_source or "log_time",
                    "offset_ns": 0,
                    "nominal_rate_hz": stats.rate_hz,
                    "source": cam.image_topic or "",
                }
                if self.bag.video:
                    entry["video"] = f"{ep}/cameras/{name}/rgb.mp4"
                if name in self._labels_writers:
                    entry["labels"] = f"{ep}/cameras/{name}/labels.parquet"
                if extrinsics_rel:
                    entry["extrinsics"] = extrinsics_rel
                ctx.add_stream(
                    f"camera/{name}", entry, start_ns=stats.start_ns, end_ns=stats.end_ns
                )

    def abort(self) -> None:
        """Close open files after a failure (the writer discards them)."""
        for sink in [self._joint_sink, *self._wrench_sinks.values(), *self._pose_sinks.values()]:
            if sink is not None:
                sink.abort()
        for cam in self._cameras.values():
            if cam.sink is not None:
                cam.sink.abort()
        for writer, _ in self._labels_writers.values():
            writer.close()
        self.tf.close()

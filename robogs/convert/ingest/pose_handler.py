"""Pose and wrench messages -> ``object_poses``, ``ee_poses`` and ``wrenches`` tables.

A pose given in a frame other than the world is composed with the TF chain to the world:
the static transform, or the moving chain at each stamp. Moving TF frames chosen as objects
(:mod:`.tf_ingest`) join the same ``object_poses`` table. Wrenches stay in their sensor frame
(the ``frame`` column), one stream per topic when there are several.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .context import IngestContext
from .roles import Role, safe_name
from .sinks import TableSink
from .stamps import StampClock
from .tf_buffer import Hop
from .tf_ingest import TfIngest, TfObject
from .tf_tree import matrix_to_pose, pose_to_matrix

__all__ = ["POSE_COLUMNS", "PoseHandler", "WrenchHandler"]

#: value columns of a pose table (m; quaternion w, x, y, z)
POSE_COLUMNS = ["x", "y", "z", "qw", "qx", "qy", "qz"]
_WRENCH_COLUMNS = ["fx", "fy", "fz", "tx", "ty", "tz"]


class PoseHandler:
    """Object and end-effector poses (from pose topics and moving TF frames).

    Args:
        ctx: the conversion context.
        clock: stamp sources and sink thresholds.
        tf: the TF tree.
        world: ``world()`` -> the TF frame that is the dataset world.
    """

    def __init__(
        self, ctx: IngestContext, clock: StampClock, tf: TfIngest, world: Callable[[], str]
    ) -> None:
        self.ctx = ctx
        self.prov = ctx.provenance
        self.clock = clock
        self.tf = tf
        self.world = world
        self._sinks: dict[str, TableSink] = {}
        self._frames: dict[str, np.ndarray | list[Hop] | None] = {}

    def _sink(self, kind: str) -> TableSink:
        sink = self._sinks.get(kind)
        if sink is None:
            sink = self._sinks[kind] = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/{kind}.parquet"),
                kind,
                POSE_COLUMNS,
                label_column="link" if kind == "ee_poses" else "object",
                **self.clock.sink_kwargs(),
            )
        return sink

    def add_tf_object(self, obj: TfObject, t: int, vals: list[float]) -> None:
        """One pose (x, y, z, qw, qx, qy, qz; world frame) of a moving TF frame chosen as object."""
        self._sink("object_poses").add(obj.source, t, vals, obj.name)

    def _to_world(self, topic: str, frame: str) -> np.ndarray | list[Hop] | None:
        """``T_world_frame`` (static chain), the chain's hops (moving frame) or ``None``."""
        if topic in self._frames:
            return self._frames[topic]
        world = self.world()
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
        self._frames[topic] = T
        return T

    def add(self, topic: str, role: Role, t: int, msg: Any) -> None:
        """A pose message (PoseStamped, PoseWithCovarianceStamped, TransformStamped) at ``t``."""
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
        T = self._to_world(topic, str(msg.header.frame_id).lstrip("/"))
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
        sink = self._sink(kind)
        label = role.name or safe_name(topic)
        if sink.add(topic, t, vals, label):
            self.prov.topic(topic).written += 1

    def close(self) -> None:
        """Close the pose tables, declare their streams and the objects as assets."""
        ctx, ep = self.ctx, self.ctx.episode_dir()
        for kind, sink in sorted(self._sinks.items()):
            st = sink.close()
            if not st.rows:
                continue
            topics = sorted(sink.written)
            ctx.add_stream(
                kind,
                {
                    "kind": kind,
                    "path": f"{ep}/{kind}.parquet",
                    "stamp_source": self.clock.stream_source(topics),
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

    def abort(self) -> None:
        """Close the open tables after a failure."""
        for sink in self._sinks.values():
            sink.abort()


class WrenchHandler:
    """``WrenchStamped`` messages, one table per topic.

    Args:
        ctx: the conversion context.
        clock: stamp sources and sink thresholds.
        streams: wrench topic -> (stream name, file stem), from the plan.
    """

    def __init__(
        self, ctx: IngestContext, clock: StampClock, streams: dict[str, tuple[str, str]]
    ) -> None:
        self.ctx = ctx
        self.prov = ctx.provenance
        self.clock = clock
        self.streams = streams
        self._sinks: dict[str, TableSink] = {}

    def add(self, topic: str, role: Role, t: int, msg: Any) -> None:
        """One wrench (N, N m; in the sensor frame) at stamp ``t`` (ns)."""
        f, tq = msg.wrench.force, msg.wrench.torque
        vals = [float(f.x), float(f.y), float(f.z), float(tq.x), float(tq.y), float(tq.z)]
        if not all(math.isfinite(v) for v in vals):
            self.prov.issue(topic, "non-finite wrench (dropped)", t)
            return
        sink = self._sinks.get(topic)
        if sink is None:
            _, stem = self.streams.get(topic, ("wrenches", "wrenches"))
            sink = self._sinks[topic] = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/{stem}.parquet"),
                "wrenches",
                _WRENCH_COLUMNS,
                label_column="frame",
                **self.clock.sink_kwargs(),
            )
        frame = role.name or str(msg.header.frame_id).lstrip("/") or safe_name(topic)
        if sink.add(topic, t, vals, frame):
            self.prov.topic(topic).written += 1

    def close(self) -> None:
        """Close the wrench tables and declare their streams."""
        ep = self.ctx.episode_dir()
        for topic, sink in sorted(self._sinks.items()):
            st = sink.close()
            if not st.rows:
                continue
            name, stem = self.streams.get(topic, ("wrenches", "wrenches"))
            self.ctx.add_stream(
                name,
                {
                    "kind": "wrenches",
                    "path": f"{ep}/{stem}.parquet",
                    "stamp_source": self.clock.stream_source([topic]),
                    "offset_ns": 0,
                    "nominal_rate_hz": st.rate_hz,
                    "source": topic,
                },
                start_ns=st.start_ns,
                end_ns=st.end_ns,
            )

    def abort(self) -> None:
        """Close the open tables after a failure."""
        for sink in self._sinks.values():
            sink.abort()

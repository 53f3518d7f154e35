"""``sensor_msgs/JointState`` messages -> the episode's ``joint_states`` table.

The first message fixes the joint order and whether velocity and effort columns exist; later
messages are matched by name (a joint missing from a message is NaN, recorded; a joint not in
the first message is recorded and its values dropped).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .context import IngestContext
from .msg_fields import floats
from .sinks import TableSink
from .stamps import StampClock

__all__ = ["JointStateHandler"]


@dataclass
class _Layout:
    names: list[str]
    index: dict[str, int]
    has_vel: bool
    has_eff: bool


class JointStateHandler:
    """Writes the one ``joint_states`` topic of the plan.

    Args:
        ctx: the conversion context (writer, provenance, episode).
        clock: stamp sources and sink thresholds.
        topic: the joint topic (others with this role are dropped and recorded).
    """

    def __init__(self, ctx: IngestContext, clock: StampClock, topic: str | None) -> None:
        self.ctx = ctx
        self.prov = ctx.provenance
        self.clock = clock
        self.topic = topic
        self._layout: _Layout | None = None
        self._sink: TableSink | None = None

    def add(self, topic: str, t: int, msg: Any) -> None:
        """One JointState at stamp ``t`` (ns)."""
        if topic != self.topic:
            self.prov.drop(topic, "not the joint_states topic")
            return
        names = list(msg.name)
        pos = floats(msg.position)
        lay = self._layout
        if lay is None:
            if not names or len(set(names)) != len(names) or pos.size != len(names):
                self.prov.issue(
                    topic, "JointState without unique names matching its positions (dropped)", t
                )
                return
            vel, eff = floats(msg.velocity), floats(msg.effort)
            lay = self._layout = _Layout(
                names,
                {n: i for i, n in enumerate(names)},
                vel.size == len(names),
                eff.size == len(names),
            )
            cols = [f"position.{n}" for n in names]
            cols += [f"velocity.{n}" for n in names] if lay.has_vel else []
            cols += [f"effort.{n}" for n in names] if lay.has_eff else []
            self._sink = TableSink(
                self.ctx.writer.path(f"{self.ctx.episode_dir()}/joint_states.parquet"),
                "joint_states",
                cols,
                **self.clock.sink_kwargs(),
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
                parts.append(self._by_name(names, floats(msg.velocity), lay, topic, t, "velocity"))
            if lay.has_eff:
                parts.append(self._by_name(names, floats(msg.effort), lay, topic, t, "effort"))
        row = np.concatenate(parts) if len(parts) > 1 else parts[0]
        assert self._sink is not None
        if self._sink.add(topic, t, row.tolist()):
            self.prov.topic(topic).written += 1

    def _optional(self, topic: str, t: int, values: Any, n: int, what: str) -> np.ndarray:
        arr = floats(values)
        if arr.size == n:
            return arr
        self.prov.issue(topic, f"JointState without {what} (NaN written)", t, drop=False)
        return np.full(n, np.nan)

    def _by_name(
        self, names: list[str], values: np.ndarray, lay: _Layout, topic: str, t: int, what: str
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

    def close(self) -> None:
        """Close the table and declare the ``joint_states`` stream (when rows were written)."""
        if self._sink is None:
            return
        st = self._sink.close()
        if st.rows:
            assert self.topic is not None
            self.ctx.add_stream(
                "joint_states",
                {
                    "kind": "joint_states",
                    "path": f"{self.ctx.episode_dir()}/joint_states.parquet",
                    "stamp_source": self.clock.stream_source([self.topic]),
                    "offset_ns": 0,
                    "nominal_rate_hz": st.rate_hz,
                    "source": self.topic,
                },
                start_ns=st.start_ns,
                end_ns=st.end_ns,
            )

    def abort(self) -> None:
        """Close the open table after a failure."""
        if self._sink is not None:
            self._sink.abort()

"""Stamps of bag and MCAP messages: header stamp or log time, plausibility, clock jumps.

Per topic, ``header.stamp`` is used when the first message's stamp is plausible (non-zero and
within the recording's time range +- the tolerance); otherwise the log time. Later messages of
a header-stamped topic whose stamp is implausible are dropped and recorded with topic and
stamp. The chosen source is recorded per topic (``stamp_source``). Clock jumps (a stamp going
back or far forward) are handled by the table sinks with the thresholds given here.
"""

from __future__ import annotations

from typing import Any

from .bag_options import BagOptions
from .provenance import Provenance
from .tf_ingest import stamp_ns

__all__ = ["StampClock"]


class StampClock:
    """The stamp of every message of a recording.

    Args:
        prov: where implausible stamps and the chosen sources are recorded.
        time_range: ``(start_ns, end_ns)`` of the recording's log times (``None``: any
            non-zero stamp is plausible).
        options: the tolerance and jump thresholds (ns).
    """

    def __init__(
        self, prov: Provenance, time_range: tuple[int, int] | None, options: BagOptions
    ) -> None:
        self.prov = prov
        self.time_range = time_range
        self.opts = options
        #: topic (or TF object source) -> ``sensor_header`` | ``log_time``
        self.source: dict[str, str] = {}

    def plausible(self, t: int) -> bool:
        """True when ``t`` (ns) is non-zero and inside the recording +- the tolerance."""
        if t <= 0:
            return False
        if self.time_range is None:
            return True
        tol = self.opts.stamp_tolerance_ns
        return self.time_range[0] - tol <= t <= self.time_range[1] + tol

    def stamp(self, topic: str, msg: Any, log_time: int) -> int | None:
        """The stamp (ns) of one message; None when its header stamp is implausible (dropped
        and recorded). The first message decides the topic's source."""
        header = getattr(msg, "header", None)
        src = self.source.get(topic)
        if src is None:
            t_hdr = stamp_ns(header.stamp) if header is not None else 0
            src = "sensor_header" if header is not None and self.plausible(t_hdr) else "log_time"
            if header is not None and src == "log_time":
                self.prov.note(
                    f"{topic}: header.stamp {t_hdr} is zero or outside the recording's time range; "
                    "log time used for this topic"
                )
            self.source[topic] = src
            self.prov.topic(topic).stamp_source = src
        if src == "log_time":
            return int(log_time)
        t = stamp_ns(header.stamp)
        if not self.plausible(t):
            self.prov.issue(
                topic, "header stamp zero or outside the recording's time range (sample dropped)", t
            )
            return None
        return t

    def log_stamp(self, topic: str, log_time: int) -> int:
        """Log time as the stamp of a topic whose messages have no header stamp."""
        if topic not in self.source:
            self.source[topic] = "log_time"
            self.prov.topic(topic).stamp_source = "log_time"
        return int(log_time)

    def probe_stamp(self, msg: Any, log_time: int) -> int:
        """The header stamp when plausible, else the log time (no record: probing only)."""
        header = getattr(msg, "header", None)
        t = stamp_ns(header.stamp) if header is not None else 0
        return t if self.plausible(t) else int(log_time)

    def stream_source(self, topics: list[str]) -> str:
        """The ``stamp_source`` of a stream written from ``topics`` (the first topic's; a note
        when they differ)."""
        srcs = sorted({self.source.get(t, "log_time") for t in topics})
        if len(srcs) > 1:
            self.prov.note(
                f"topics {', '.join(topics)} share one table but use different stamp sources "
                "(see topics/*/stamp_source); the stream records the first"
            )
        return self.source.get(topics[0], "log_time")

    def sink_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of a :class:`~.sinks.TableSink`: provenance and jump thresholds."""
        return {
            "provenance": self.prov,
            "jump_back_ns": self.opts.jump_back_ns,
            "jump_forward_ns": self.opts.jump_forward_ns,
        }

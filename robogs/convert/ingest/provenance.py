"""The provenance record of a conversion: what came in, what went out, what was left behind.

Nothing read from a source is lost silently: every topic (or file) is listed with its
message count, the role it was given, how many samples were written, and — when some
were not — the reason, grouped with a count and the first stamps concerned. The record
is stored as ``manifest["provenance"]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["Provenance", "TopicRecord"]

_MAX_EXAMPLES = 5


@dataclass
class TopicRecord:
    """Counts for one source topic (or file).

    Attributes:
        type: message type (``pkg/msg/Name``) or file kind.
        role: the role the topic was given (``ignore`` when dropped).
        messages: messages read.
        written: samples written to the dataset.
        stamp_source: ``sensor_header`` | ``log_time`` | ... once decided.
        dropped: reason -> count of messages not written.
        reason: why the topic got its role (the guess, or the user's override).
    """

    type: str
    role: str = "ignore"
    messages: int = 0
    written: int = 0
    stamp_source: str | None = None
    dropped: dict[str, int] = field(default_factory=dict)
    reason: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "type": self.type,
            "role": self.role,
            "messages": self.messages,
            "written": self.written,
        }
        if self.stamp_source is not None:
            out["stamp_source"] = self.stamp_source
        if self.reason:
            out["reason"] = self.reason
        if self.dropped:
            out["dropped"] = dict(sorted(self.dropped.items()))
        return out


class Provenance:
    """Collects the provenance block while a conversion runs.

    Issues are grouped by ``(topic, problem)``: each group keeps a count and the first
    few stamps, so a million bad samples cost a few bytes.
    """

    def __init__(self, converter: str, source: str) -> None:
        self.converter = converter
        self.source = source
        self.topics: dict[str, TopicRecord] = {}
        self.notes: list[str] = []
        self.undecodable: list[dict[str, Any]] = []
        self._issues: dict[tuple[str, str], dict[str, Any]] = {}
        self.extra: dict[str, Any] = {}

    def topic(self, name: str, type_: str = "", role: str = "ignore") -> TopicRecord:
        """The record of ``name``, created on first use."""
        rec = self.topics.get(name)
        if rec is None:
            rec = self.topics[name] = TopicRecord(type=type_, role=role)
        return rec

    def drop(self, topic: str, reason: str, n: int = 1) -> None:
        """Count ``n`` messages of ``topic`` not written, for ``reason``."""
        rec = self.topic(topic)
        rec.dropped[reason] = rec.dropped.get(reason, 0) + n

    def issue(
        self, topic: str, problem: str, t_ns: int | None = None, *, drop: bool = True
    ) -> None:
        """Record a problem with one sample of ``topic`` at stamp ``t_ns`` (ns).

        Args:
            topic: source topic or file.
            problem: short fixed text (used as the group key; put numbers in ``t_ns``).
            t_ns: the stamp concerned.
            drop: also count the sample as dropped for this reason.
        """
        key = (topic, problem)
        entry = self._issues.get(key)
        if entry is None:
            entry = self._issues[key] = {
                "topic": topic,
                "problem": problem,
                "count": 0,
                "stamps_ns": [],
            }
        entry["count"] += 1
        if t_ns is not None and len(entry["stamps_ns"]) < _MAX_EXAMPLES:
            entry["stamps_ns"].append(int(t_ns))
        if drop:
            self.drop(topic, problem)

    @property
    def issues(self) -> list[dict[str, Any]]:
        return list(self._issues.values())

    def note(self, text: str) -> None:
        """A free-text remark (conventions applied, fallbacks taken)."""
        if text not in self.notes:
            self.notes.append(text)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready provenance block."""
        out: dict[str, Any] = {"converter": self.converter, "source": self.source}
        out.update(self.extra)
        out["topics"] = {k: v.to_dict() for k, v in sorted(self.topics.items())}
        dropped = [
            {
                "topic": k,
                "type": v.type,
                "messages": v.messages - v.written,
                "reasons": dict(v.dropped),
            }
            for k, v in sorted(self.topics.items())
            if v.messages > v.written
        ]
        if dropped:
            out["dropped"] = dropped
        if self.undecodable:
            out["undecodable"] = self.undecodable
        if self._issues:
            out["issues"] = self.issues
        if self.notes:
            out["notes"] = list(self.notes)
        return out

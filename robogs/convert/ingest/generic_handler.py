"""Topics with the ``generic`` role -> one decoded table each (``streams/<topic>``).

Every numeric or string field of a message becomes a column (:class:`~.generic.GenericTable`);
the table is written when the recording ends.
"""

from __future__ import annotations

from typing import Any

from .context import IngestContext
from .generic import GenericTable
from .roles import safe_name
from .sinks import median_rate_hz
from .stamps import StampClock

__all__ = ["GenericHandler"]


class GenericHandler:
    """The generic tables of a recording.

    Args:
        ctx: the conversion context.
        clock: stamp sources.
    """

    def __init__(self, ctx: IngestContext, clock: StampClock) -> None:
        self.ctx = ctx
        self.prov = ctx.provenance
        self.clock = clock
        self._tables: dict[str, GenericTable] = {}

    def add(self, topic: str, t: int, msg: Any) -> None:
        """One message at stamp ``t`` (ns)."""
        table = self._tables.get(topic)
        if table is None:
            table = self._tables[topic] = GenericTable(topic, self.prov)
        table.add(t, msg)
        self.prov.topic(topic).written += 1

    def close(self) -> None:
        """Write each table and declare its ``generic`` stream; generic streams widen the
        episode's span only when no role stream set it."""
        ctx, ep = self.ctx, self.ctx.episode_dir()
        used: set[str] = set()
        widen = ctx.start_ns is None
        for topic, table in sorted(self._tables.items()):
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
                    "stamp_source": self.clock.source.get(topic, "log_time"),
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

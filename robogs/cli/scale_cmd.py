"""The ``--ray`` paths of ``robogs validate`` and ``robogs convert`` (Ray is imported only here,
through :class:`robogs.format.distributed.RayExecutor`, and only when ``--ray`` is given).

``--ray`` alone starts a local cluster on this machine's cores; ``--ray auto`` joins the cluster
that ``ray start`` runs; ``--ray ADDRESS`` joins that one. The dataset (or the bags) must be at
the same path on every node. A summary across the cluster goes to stderr: tasks, worker
processes, the peak resident memory of the largest worker, the task seconds and the wall time.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["executor_for", "validate_ray", "summary_line", "LOCAL_OBJECT_STORE_BYTES"]

#: object store of a local cluster: tasks exchange small records only
LOCAL_OBJECT_STORE_BYTES = 200 * 1024**2


def executor_for(address: str, *, num_cpus: int | None = None) -> Any:
    """A :class:`~robogs.format.distributed.RayExecutor` for ``--ray [ADDRESS|auto]``."""
    from robogs.format.distributed import RayExecutor

    if address == "local":
        return RayExecutor(
            None,
            num_cpus=num_cpus,
            init_kwargs={"object_store_memory": LOCAL_OBJECT_STORE_BYTES},
        )
    return RayExecutor(address)


def summary_line(stats: Any, workers: int) -> str:
    """One line: tasks, workers, the largest worker's peak RSS, seconds."""
    peak = max(stats.peak_rss.values(), default=0)
    how = f"; split refused: {stats.reason}" if stats.reason else ""
    own = getattr(stats, "chunk_units", 0)
    chunks = f" ({own} reading their chunk index)" if own else ""
    return (
        f"ray: {stats.units} tasks{chunks} on {len(stats.peak_rss)} worker processes "
        f"({workers} CPUs), peak worker RSS {peak / 2**20:.0f} MiB, "
        f"{stats.task_seconds:.1f} task-s in {stats.wall_seconds:.1f} s{how}"
    )


def validate_ray(
    args: argparse.Namespace,
    *,
    progress: bool | Callable[[str, float, float], None],
    options: dict[str, Any],
) -> Any:
    """``robogs validate DATASET --ray [ADDRESS]``: the report (and a summary on stderr)."""
    from robogs.cli.validate_cmd import _threads
    from robogs.format.distributed import DEFAULT_EPISODES_PER_TASK, Stats, validate_distributed

    ex = executor_for(args.ray)
    stats = Stats()
    try:
        report = validate_distributed(
            args.dataset,
            executor=ex,
            episodes_per_task=args.episodes_per_task or DEFAULT_EPISODES_PER_TASK,
            select=args.select,
            ignore=args.ignore,
            quick=args.quick,
            budgets=dict(args.budget),
            progress=progress,
            options=options,
            label_threads=_threads(args),
            stats=stats,
        )
    finally:
        ex.shutdown()
    line = summary_line(stats, ex.workers)
    if ex.init_seconds:
        line += f" (of which {ex.init_seconds:.1f} s starting Ray)"
    print(line, file=sys.stderr)
    return report

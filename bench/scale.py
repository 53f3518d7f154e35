"""Split validation throughput: one process vs Ray with 1, 2, ... workers, in the same run.

    OMP_NUM_THREADS=1 .venv/bin/python bench/scale.py --episodes 400 --workers 1 2

Generates ``--episodes`` short episodes (robogs.synth.bulk, 1 s at 500 Hz), validates them in
one process (the baseline), then with a local Ray cluster of each worker count (a fresh
``ray.init(num_cpus=W)`` each), checks the findings are identical, and prints wall seconds, the
speed-up over 1 worker and over one process, and the largest worker's peak RSS.
Not yet: the multi-node ``ray.cluster_utils.Cluster`` run and the 200-bag convert figure.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

os.environ.setdefault("RAY_DISABLE_IMPORT_WARNING", "1")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=400)
    ap.add_argument("--seconds", type=float, default=1.0, help="length of each episode, s")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--episodes-per-task", type=int, default=25)
    a = ap.parse_args()

    import ray

    from robogs.format.distributed import RayExecutor, Stats, validate_distributed
    from robogs.format.validate import validate
    from robogs.synth.bulk import write_bulk_dataset

    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, ray {ray.__version__}"
    )
    with tempfile.TemporaryDirectory(prefix="robogs-scale-") as tmp:
        ds = Path(tmp) / "ds"
        t = time.perf_counter()
        write_bulk_dataset(ds, n_episodes=a.episodes, duration_s=a.seconds)
        print(
            f"generated {a.episodes} episodes of {a.seconds:g} s in {time.perf_counter() - t:.1f} s"
        )
        t = time.perf_counter()
        one = validate(ds, label_threads=1)
        base = time.perf_counter() - t
        print(f"one process: {base:.1f} s ({a.episodes / base:.1f} episodes/s)")
        facts = [f.to_dict() for f in one.findings]
        first = None
        for w in a.workers:
            ray.init(
                num_cpus=w,
                include_dashboard=False,
                log_to_driver=False,
                object_store_memory=200 * 1024**2,
                logging_level="ERROR",
            )
            try:
                ex = RayExecutor()
                ex.connect()
                ray.get([ray.remote(lambda: 0).remote() for _ in range(2 * w)])  # warm workers
                st = Stats()
                t = time.perf_counter()
                rep = validate_distributed(
                    ds, executor=ex, stats=st, episodes_per_task=a.episodes_per_task
                )
                wall = time.perf_counter() - t
            finally:
                ray.shutdown()
            same = [f.to_dict() for f in rep.findings] == facts
            first = first or wall
            peak = max(st.peak_rss.values(), default=0) / 2**20
            print(
                f"ray {w} workers: {wall:.1f} s, x{first / wall:.2f} vs 1 worker, "
                f"x{base / wall:.2f} vs one process, {st.units} tasks, peak worker RSS "
                f"{peak:.0f} MiB, findings identical: {same}"
            )


if __name__ == "__main__":
    main()

"""Scale benchmark (issue 22): many episodes, many bags, one process against Ray, in one run.

    OMP_NUM_THREADS=1 .venv/bin/python bench/scale.py            # every phase, defaults below
    OMP_NUM_THREADS=1 .venv/bin/python bench/scale.py --phases open throughput --episodes 2000

Phases (``--phases``, all by default):

* ``open``: writes ``--big`` (10^4) short episodes in the sharded layout (chunks of 1000), then
  times ``Dataset.open`` in a fresh interpreter (imports excluded and included), the lookup of
  the last episode, the merge of every chunk index, and ``validate --quick`` in one process.
* ``throughput``: writes ``--episodes`` (2000) episodes (sharded), validates them in one process
  (the baseline), then on a fresh local Ray cluster of each ``--workers`` count; checks the
  findings are identical; prints the speed-up over 1 worker and over one process, and each
  worker's peak RSS.
* ``nodes``: the same dataset on a simulated multi-node cluster (``ray.cluster_utils.Cluster``,
  ``--nodes`` raylets of one CPU each); findings identical, tasks per node.
* ``bags``: writes ``--bags`` (200) MCAP bags (one cut short, so unreadable) and converts them
  into one dataset in one process and with each worker count; the corrupt bag must be the
  only one reported, and the result must validate (``--quick``) without errors.

Every figure is printed with the 1-minute load average before and after it: the machine is
shared, so a figure taken at load L on C cores had about C / max(C, L + 1) of them.
``--json-out`` writes the figures as JSON too.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("RAY_DISABLE_IMPORT_WARNING", "1")
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one numerics thread per process: the workers are the cores

RESULTS: dict[str, Any] = {}


def load() -> float:
    return round(os.getloadavg()[0], 2)


def say(key: str, text: str, **values: Any) -> None:
    """Print one figure with the load average, and keep it for ``--json-out``."""
    values["load_1min"] = load()
    RESULTS[key] = values
    print(f"{text}  [load {values['load_1min']:.2f}]", flush=True)


def _facts(report) -> list[dict]:
    return [f.to_dict() for f in report.findings]


def _ray_init(ray, **kw: Any) -> None:
    ray.init(
        include_dashboard=False,
        log_to_driver=False,
        object_store_memory=200 * 1024**2,
        logging_level="ERROR",
        **kw,
    )


def phase_open(tmp: Path, a: argparse.Namespace) -> None:
    from robogs.format.validate import validate
    from robogs.synth.bulk import write_bulk_dataset

    ds = tmp / "big"
    t = time.perf_counter()
    m = write_bulk_dataset(ds, n_episodes=a.big, duration_s=a.seconds, chunk_size=1000)
    say(
        "generate_big",
        f"generated {a.big} episodes ({len(m['shards']['chunks'])} chunks) in "
        f"{time.perf_counter() - t:.1f} s; manifest.json {(ds / 'manifest.json').stat().st_size} B",
        episodes=a.big,
        seconds=time.perf_counter() - t,
    )
    last = m["shards"]["chunks"][-1]
    last_id = json.loads((ds / last["index"]).read_text())["episodes"][-1]["id"]
    probe = (
        "import time; t0 = time.perf_counter()\n"
        "from robogs.format.dataset import Dataset\n"
        f"t1 = time.perf_counter(); ds = Dataset.open({str(ds)!r}); n = ds.num_episodes\n"
        f"t2 = time.perf_counter(); ds.episode({last_id!r}); t3 = time.perf_counter()\n"
        "m = ds.full_manifest(); t4 = time.perf_counter()\n"
        "print(t2 - t1, t2 - t0, t3 - t2, t4 - t3, n, len(m['files']))\n"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    o, with_imports, lookup, merge, n, nfiles = out.stdout.split()
    say(
        "open_big",
        f"open: {float(o) * 1e3:.1f} ms ({float(with_imports):.2f} s with imports, fresh "
        f"interpreter), {n} episodes from the manifest alone; last episode found in "
        f"{float(lookup):.2f} s (every chunk read); all {nfiles} files merged in {float(merge):.2f} s",
        open_s=float(o),
        open_with_imports_s=float(with_imports),
        lookup_last_s=float(lookup),
        merge_s=float(merge),
    )
    c0, t = time.process_time(), time.perf_counter()
    rep = validate(ds, quick=True, label_threads=1)
    wall, cpu = time.perf_counter() - t, time.process_time() - c0
    say(
        "quick_big",
        f"validate --quick, one process: {wall:.1f} s wall, {cpu:.1f} s CPU, "
        f"{len(rep.findings)} findings",
        wall_s=wall,
        cpu_s=cpu,
        findings=len(rep.findings),
    )


def _throughput_data(tmp: Path, a: argparse.Namespace) -> Path:
    from robogs.synth.bulk import write_bulk_dataset

    ds = tmp / "many"
    if not ds.exists():
        t = time.perf_counter()
        write_bulk_dataset(ds, n_episodes=a.episodes, duration_s=a.seconds, chunk_size=1000)
        say(
            "generate_many",
            f"generated {a.episodes} episodes of {a.seconds:g} s in {time.perf_counter() - t:.1f} s",
            seconds=time.perf_counter() - t,
        )
    return ds


def _baseline(ds: Path) -> tuple[list[dict], float]:
    from robogs.format.validate import validate

    if "baseline" not in RESULTS:
        t, c = time.perf_counter(), time.process_time()
        one = validate(ds, label_threads=1)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        say(
            "baseline",
            f"one process: {wall:.1f} s ({cpu:.1f} s CPU), {len(one.findings)} findings",
            wall_s=wall,
            cpu_s=cpu,
            facts=_facts(one),
        )
    return RESULTS["baseline"]["facts"], RESULTS["baseline"]["wall_s"]


def phase_throughput(tmp: Path, a: argparse.Namespace) -> None:
    import ray

    from robogs.format.distributed import RayExecutor, Stats, validate_distributed

    ds = _throughput_data(tmp, a)
    facts, base = _baseline(ds)
    first = first_cpu = None
    for w in a.workers:
        t_init = time.perf_counter()
        _ray_init(ray, num_cpus=w)
        try:
            ex = RayExecutor()
            ex.connect()
            ray.get([ray.remote(lambda: 0).remote() for _ in range(2 * w)])  # start the workers
            init_s = time.perf_counter() - t_init  # counted apart from the validation
            st = Stats()
            t, c = time.perf_counter(), time.process_time()
            rep = validate_distributed(
                ds, executor=ex, stats=st, episodes_per_task=a.episodes_per_task
            )
            wall, driver_cpu = time.perf_counter() - t, time.process_time() - c
        finally:
            ray.shutdown()
        first = first or wall
        rss = sorted(v / 2**20 for v in st.peak_rss.values())
        cpu = sorted(st.cpu_seconds.values())
        # load-independent: the task CPU per worker; on W idle cores the tasks need at least
        # max(cpu) seconds, so sum / max bounds the speed-up the split allows
        first_cpu = first_cpu or sum(cpu)
        say(
            f"ray_{w}",
            f"ray {w} workers: {wall:.1f} s (ray.init + worker start {init_s:.1f} s apart), "
            f"x{first / wall:.2f} vs 1 worker, x{base / wall:.2f} "
            f"vs one process, {st.units} tasks ({st.chunk_units} reading their chunk index), "
            f"peak RSS per worker {', '.join(f'{r:.0f}' for r in rss)} "
            f"MiB, findings identical: {_facts(rep) == facts}; CPU: driver {driver_cpu:.1f} s, "
            f"tasks {' + '.join(f'{x:.1f}' for x in cpu)} = {sum(cpu):.1f} s (sum / max "
            f"{sum(cpu) / max(max(cpu, default=1), 1e-9):.2f}; 1-worker task CPU / max here "
            f"x{first_cpu / max(max(cpu, default=1), 1e-9):.2f})",
            init_s=init_s,
            chunk_units=st.chunk_units,
            driver_cpu_s=driver_cpu,
            task_cpu_s=cpu,
            wall_s=wall,
            speedup_vs_1=first / wall,
            speedup_vs_process=base / wall,
            tasks=st.units,
            peak_rss_mib=rss,
            identical=_facts(rep) == facts,
        )


def phase_nodes(tmp: Path, a: argparse.Namespace) -> None:
    import ray
    from ray.cluster_utils import Cluster

    from robogs.format.distributed import RayExecutor, Stats, ray_unit, validate_distributed

    ds = _throughput_data(tmp, a)
    facts, base = _baseline(ds)
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    for _ in range(a.nodes - 1):
        cluster.add_node(num_cpus=1)
    try:
        ray.init(address=cluster.address, log_to_driver=False, logging_level="ERROR")

        seen = tmp / "nodes"
        seen.mkdir(exist_ok=True)

        def on_node(root, base_m, unit, settings):  # the task body, noting its raylet
            node = ray.get_runtime_context().get_node_id()
            (seen / f"{unit.index}").write_text(node, encoding="utf-8")
            return ray_unit(root, base_m, unit, settings)

        ex = RayExecutor(body=on_node)
        st = Stats()
        t = time.perf_counter()
        rep = validate_distributed(ds, executor=ex, stats=st, episodes_per_task=a.episodes_per_task)
        wall = time.perf_counter() - t
        nodes = len([n for n in ray.nodes() if n.get("Alive")])
        per_node: dict[str, int] = {}
        for f in seen.iterdir():
            node = f.read_text(encoding="utf-8")
            per_node[node] = per_node.get(node, 0) + 1
    finally:
        ray.shutdown()
        cluster.shutdown()
    say(
        "nodes",
        f"{nodes} local raylets x 1 CPU: {wall:.1f} s, x{base / wall:.2f} vs one process, "
        f"{st.units} tasks, per node {sorted(per_node.values())}, findings identical: "
        f"{_facts(rep) == facts}",
        nodes=nodes,
        wall_s=wall,
        tasks_per_node=sorted(per_node.values()),
        identical=_facts(rep) == facts,
    )


def phase_bags(tmp: Path, a: argparse.Namespace) -> None:
    from robogs.convert.distributed import convert_many
    from robogs.convert.ingest.context import ConvertOptions
    from robogs.format.distributed import RayExecutor
    from robogs.format.validate import validate
    from robogs.synth.bulk import planar_urdf, write_bulk_bags

    bags = tmp / "bags"
    t = time.perf_counter()
    srcs = write_bulk_bags(bags, n_bags=a.bags, duration_s=a.bag_seconds, corrupt=(a.bags // 2,))
    say("generate_bags", f"generated {a.bags} bags in {time.perf_counter() - t:.1f} s")
    urdf = tmp / "planar.urdf"
    urdf.write_text(planar_urdf(), encoding="utf-8")
    opts = ConvertOptions(urdf=urdf, progress=False)
    base = None
    for w in [0, *a.workers]:
        out = tmp / f"bags_out_{w}"
        if w:
            import ray

            _ray_init(ray, num_cpus=w)
        try:
            t = time.perf_counter()
            res = convert_many(srcs, out, opts, executor=RayExecutor() if w else None)
            wall = time.perf_counter() - t
        finally:
            if w:
                ray.shutdown()
        base = base or wall
        rep = validate(out, quick=True, label_threads=1)
        errors = sum(f.severity == "error" for f in rep.findings)
        failed = [Path(f["source"]).name for f in res.failed]
        say(
            f"bags_{w}",
            f"convert {a.bags} bags, {'one process' if not w else f'ray {w} workers'}: "
            f"{wall:.1f} s (x{base / wall:.2f} vs one process), {len(res.episodes)} episodes, "
            f"failed {failed}, validate --quick errors {errors}, peak RSS "
            f"{max(res.peak_rss.values(), default=0) / 2**20:.0f} MiB",
            wall_s=wall,
            episodes=len(res.episodes),
            failed=failed,
            errors=errors,
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--phases", nargs="+", default=["open", "throughput", "nodes", "bags"])
    ap.add_argument("--big", type=int, default=10_000, help="episodes of the open phase")
    ap.add_argument("--episodes", type=int, default=2000, help="episodes of the throughput phase")
    ap.add_argument("--seconds", type=float, default=0.2, help="length of each episode, s")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2, os.cpu_count() or 2])
    ap.add_argument("--episodes-per-task", type=int, default=25)
    ap.add_argument("--nodes", type=int, default=3)
    ap.add_argument("--bags", type=int, default=200)
    ap.add_argument("--bag-seconds", type=float, default=0.5)
    ap.add_argument("--json-out", type=Path)
    a = ap.parse_args()
    a.workers = sorted(set(a.workers))

    import ray

    print(
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {platform.machine()}, "
        f"{os.cpu_count()} cores, load {load():.2f}, OMP_NUM_THREADS="
        f"{os.environ.get('OMP_NUM_THREADS')}, ray {ray.__version__}, python "
        f"{platform.python_version()}",
        flush=True,
    )
    phases = {"open": phase_open, "throughput": phase_throughput, "nodes": phase_nodes}
    phases["bags"] = phase_bags
    with tempfile.TemporaryDirectory(prefix="robogs-scale-") as tmp:
        for name in a.phases:
            phases[name](Path(tmp), a)
    if a.json_out:
        RESULTS.get("baseline", {}).pop("facts", None)
        a.json_out.write_text(json.dumps(RESULTS, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()

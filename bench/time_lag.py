"""Cost of the inter-stream lag check (T013) within the time group, on a long episode.

Builds, in a temp folder, a dataset whose joint states (500 Hz) and end-effector poses
(500 Hz) are the synthetic scene's (``robogs.synth.scene``, small, seed 0) played forward and
backward until the episode lasts ``--seconds`` (continuous motion, stamps advancing), with the
poses delayed by ``--delay-ms`` against the joints. Every stream except those two is dropped.
Then times, in this process after a warm-up, ``validate(select=["time"])`` against the in-run
baseline ``validate(select=["time"], ignore=["T013"])`` (best of ``--repeat``), and prints the
ratio, the lag T013 reports, the machine and the threads.

Usage::

    PYTHONPATH=. .venv/bin/python -W ignore bench/time_lag.py [--seconds 280] [--threads 1]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

KEEP = ("joint_states", "ee_poses")


def _pingpong(table: pa.Table, t0: int, period_ns: int, n_out: int) -> pa.Table:
    """Rows 0..N-1, N-2..1, 1..N-1, ... restamped every ``period_ns`` from ``t0``."""
    n = table.num_rows
    cycle = np.concatenate([np.arange(n), np.arange(n - 2, 0, -1)])
    idx = np.resize(cycle, n_out)
    out = table.take(pa.array(idx))
    t = t0 + np.arange(n_out, dtype=np.int64) * period_ns
    return out.set_column(out.schema.get_field_index("t_ns"), "t_ns", pa.array(t, pa.int64()))


def _delay(table: pa.Table, ms: float) -> pa.Table:
    """Pose values at stamp t become the pose at t - ms (linear interpolation, held at start)."""
    t = table.column("t_ns").to_numpy().astype(np.float64)
    for c in ("x", "y", "z", "qw", "qx", "qy", "qz"):
        v = np.interp(t - ms * 1e6, t, table.column(c).to_numpy())
        table = table.set_column(table.schema.get_field_index(c), c, pa.array(v))
    return table


def build(root: Path, seconds: float, delay_ms: float) -> Path:
    """Write the long dataset at ``root`` (see the module docstring)."""
    from robogs.synth.scene import synthesize

    synthesize(root, seed=0, size="small")
    m = json.loads((root / "manifest.json").read_text())
    ep = m["episodes"][0]
    ep["streams"] = {k: v for k, v in ep["streams"].items() if k in KEEP}
    n_out = int(seconds * 500)
    for name, st in ep["streams"].items():
        tab = pq.read_table(root / st["path"])
        tab = _pingpong(tab, ep["start_ns"], 2_000_000, n_out)
        if name == "ee_poses" and delay_ms:
            tab = _delay(tab, delay_ms)
        pq.write_table(tab, root / st["path"])
    ep["end_ns"] = ep["start_ns"] + n_out * 2_000_000
    m["episodes"] = [ep]
    for rel in list(m["files"]):
        p = root / rel
        if rel.endswith(".parquet") and "/ep" in rel:
            if not any(rel == st["path"] for st in ep["streams"].values()):
                del m["files"][rel]
                continue
        entry = {"sha256": hashlib.sha256(p.read_bytes()).hexdigest(), "size": p.stat().st_size}
        if rel.endswith(".parquet"):
            entry["rows"] = pq.ParquetFile(p).metadata.num_rows
        m["files"][rel] = entry
    (root / "manifest.json").write_text(json.dumps(m, indent=2, sort_keys=True) + "\n")
    return root


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=280.0)
    ap.add_argument("--delay-ms", type=float, default=12.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    import torch

    torch.set_num_threads(args.threads)
    from robogs.format.validate import validate

    with tempfile.TemporaryDirectory() as tmp:
        root = build(Path(tmp) / "ds", args.seconds, args.delay_ms)
        validate(root, select=["time"])  # warm-up: imports, URDF parse
        base, _ = _best(lambda: validate(root, select=["time"], ignore=["T013"]), args.repeat)
        full, rep = _best(lambda: validate(root, select=["time"]), args.repeat)
    lags = [f"{f.value:.3f}" for f in rep.findings if f.code == "T013"]
    print(
        f"time group on a {args.seconds:g} s episode (joints + EE poses at 500 Hz, poses "
        f"{args.delay_ms:g} ms late): {full:.3f} s with T013, {base:.3f} s without "
        f"(ratio {full / base:.2f}); T013 lag(s) {', '.join(lags) or 'none'} ms"
    )
    print(
        f"machine: {platform.node()} {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; threads {args.threads}; "
        f"best of {args.repeat}"
    )


if __name__ == "__main__":
    main()

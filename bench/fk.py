"""Forward-kinematics throughput: batched torch Chain vs yourdfpy's per-configuration loop.

Workload: the UR5 URDF of the real-data fixtures (11 links, 6 joints), 10,000 random joint
vectors, the pose of every link. Baseline: ``yourdfpy.URDF.update_cfg`` + ``get_transform`` for
every link, one configuration at a time (timed on a subset and reported per configuration).

Usage: ``.venv/bin/python bench/fk.py [--batch 10000] [--threads 2] [--baseline 300]``
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from robogs.format.kinematics import Chain, ur5_mdh
from robogs.format.urdf import load_urdf

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "fixtures" / "real"
UR5 = REAL / "ur5" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"


def best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=10_000)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--baseline", type=int, default=300, help="configurations timed for yourdfpy")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()

    if not UR5.is_file():
        print(f"real-data fixture folder is missing: {REAL}", file=sys.stderr)
        return 2
    torch.set_num_threads(args.threads)
    urdf = load_urdf(UR5, load_meshes=False)
    chain = Chain.from_urdf(urdf)
    mdh = ur5_mdh()
    rng = np.random.default_rng(0)
    q64 = torch.from_numpy(rng.uniform(-np.pi, np.pi, size=(args.batch, chain.num_joints)))
    q32 = q64.float()

    chain.forward(q64[:10])
    chain.forward(q32[:10])
    t64 = best_of(lambda: chain.forward(q64), args.repeats)
    t32 = best_of(lambda: chain.forward(q32), args.repeats)
    tmdh = best_of(lambda: mdh.forward(q64), args.repeats)

    qs = q64[: args.baseline].numpy()

    def baseline() -> None:
        for q in qs:
            urdf.update_cfg(q)
            for link in chain.link_names:
                urdf.get_transform(link, chain.link_names[0])

    tb = best_of(baseline, 1)
    per_base = tb / len(qs)

    # correctness guard: the figures compare equal outputs
    urdf.update_cfg(qs[-1])
    ref = urdf.get_transform("tool0", chain.link_names[0])
    got = chain.forward(q64[len(qs) - 1])[chain.link_index("tool0")].numpy()
    err = float(np.abs(ref - got).max())

    n = args.batch
    print(f"machine: {platform.processor() or platform.machine()}, cpu_count={os.cpu_count()}, "
          f"torch {torch.__version__}, torch threads={torch.get_num_threads()}")  # fmt: skip
    print(f"workload: UR5 URDF, {chain.num_links} links x {n} configurations (all link poses)")
    print(f"torch Chain.forward float64: {t64 * 1e3:.2f} ms  ({n / t64:,.0f} configs/s)")
    print(f"torch Chain.forward float32: {t32 * 1e3:.2f} ms  ({n / t32:,.0f} configs/s)")
    print(
        f"torch MDHTable.forward float64 (7 frames): {tmdh * 1e3:.2f} ms  ({n / tmdh:,.0f} configs/s)"
    )
    print(f"baseline yourdfpy loop: {per_base * 1e6:.1f} us/config ({1 / per_base:,.0f} configs/s; "
          f"timed on {len(qs)} configs) -> {per_base * n:.2f} s for {n}")  # fmt: skip
    print(f"speed-up float64: {per_base * n / t64:,.0f}x ; float32: {per_base * n / t32:,.0f}x")
    print(f"max |T_chain - T_yourdfpy| (tool0): {err:.1e}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

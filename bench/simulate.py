"""Rollout throughput: a batch of 64 parameter sets in one rollout vs 64 single rollouts.

The fitter's finite-difference Jacobians and the diagnosis run many parameter sets at once;
this measures what the leading batch dimension buys. Scenario: 9 pushes (robogs.synth.scenarios),
dt = 1 ms, full effect catalogue in the parameter space.

    .venv/bin/python bench/simulate.py
"""

from __future__ import annotations

import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> None:
    torch.set_num_threads(1)  # small tensors: one thread is fastest (and fair on a shared machine)
    from robogs.physics.effects import available_effects, get_effect
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    eng = Engine(make_scenario("none", seed=0, kinds=("push",)))
    space = eng.space([get_effect(n) for n in available_effects(model="rigid")])
    m = 64
    rng = np.random.default_rng(0)
    th = np.stack([eng.start(space)] * m)
    th[:, 0] *= 1.0 + 0.05 * rng.standard_normal(m)
    loc = np.zeros((m, eng.prep.n_traj, 3))
    steps = eng.prep.drive.n_steps * eng.prep.n_traj
    eng.evaluate(space, th[:2], loc[:2])  # warm-up
    t0 = time.perf_counter()
    eng.evaluate(space, th, loc)
    batched = time.perf_counter() - t0
    t0 = time.perf_counter()
    for i in range(m):
        eng.evaluate(space, th[i : i + 1], loc[i : i + 1])
    single = time.perf_counter() - t0
    lines = [
        "### rollout throughput (bench/simulate.py)",
        "",
        "Command: `.venv/bin/python bench/simulate.py`  ",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"torch {torch.__version__}, threads {torch.get_num_threads()}",
        "",
        f"- batch of {m} rollouts ({eng.prep.n_traj} trajectories x {eng.prep.drive.n_steps} steps each, "
        f"dt 1 ms): {batched:.2f} s = {m * steps / batched:,.0f} trajectory-steps/s",
        f"- {m} single rollouts (baseline): {single:.2f} s = {m * steps / single:,.0f} trajectory-steps/s",
        f"- ratio batched / single throughput: {single / batched:.1f}x",
        "- (rollouts stop early once every box rests and the end effector no longer moves; "
        "steps counted on the full grid)",
    ]
    print("\n".join(lines))
    if "--no-write" not in sys.argv:
        with (ROOT / "bench" / "RESULTS.md").open("a") as fh:
            fh.write("## 2026-11-22\n\n" + "\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main()

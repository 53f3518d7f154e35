#!/usr/bin/env python
"""Issue 16's timing target: the full catalogue diagnosed on a 9-push scene, planar vs MuJoCo.

The scene is ``make_scenario("none", seed=0, kinds=("push",))`` (9 pushes, nothing hidden), so
every candidate is fitted and scored and nothing is selected. Each engine runs in the same
process on a fresh cache folder; torch uses 1 thread, MuJoCo's batch runner ``--threads``.
Prints wall and CPU seconds per engine, the MuJoCo / planar wall and CPU ratios (the in-run
baseline), MuJoCo's simulate calls, parameter sets, distinct rollouts and steps taken, the
fitted base friction and residual RMS of both (the results the speed-ups must keep), the
machine, the threads and the load. Run it on an otherwise idle machine::

    OMP_NUM_THREADS=1 .venv/bin/python bench/diagnose_engines.py --threads 2
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time


def _one(backend: str, threads: int) -> dict:
    from robogs.physics.diagnose import diagnose_recording
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",))
    load0 = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    eng = Engine(rec, backend=backend, threads=threads)
    count = {"calls": 0, "sets": 0, "rollouts": 0, "steps": 0}
    if eng._mujoco is not None:  # count what MuJoCo runs (the instance's simulate, wrapped)
        sim, plain = eng._mujoco, eng._mujoco.simulate

        def counted(theta, *args, **kw):
            out = plain(theta, *args, **kw)
            count["calls"] += 1
            count["sets"] += int(theta.shape[0])
            count["rollouts"] += sim.last_rollouts
            count["steps"] += getattr(sim, "last_steps", 0)
            return out

        sim.simulate = counted
    res = diagnose_recording(rec, engine=eng)
    return {
        "backend": backend,
        "threads": threads,
        "wall_s": round(time.perf_counter() - t0, 1),
        "cpu_s": round(time.process_time() - c0, 1),
        "load": [round(load0, 2), round(os.getloadavg()[0], 2)],
        "candidates": len(res.rows),
        "reported": [r.name for r in res.rows if r.reported],
        "base": {
            p.name: [round(p.value, 5), round(p.low, 5), round(p.high, 5)] for p in res.base_params
        },
        "rms_base_mm": round(res.rms_base, 4),
        "params": {r.name: {p.name: round(p.value, 5) for p in r.params} for r in res.rows},
        **({"mujoco": count} if eng._mujoco is not None else {}),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=2, help="MuJoCo rollout threads (default 2)")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(1)
    os.environ["ROBOGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="robogs-bench-engines-")
    print(
        f"machine: {platform.machine()}, cpu_count={os.cpu_count()}, torch threads 1, "
        f"mujoco threads {args.threads}"
    )
    planar = _one("planar", 1)
    print(json.dumps(planar))
    mj = _one("mujoco", args.threads)
    print(json.dumps(mj))
    print(
        f"mujoco / planar wall: {mj['wall_s'] / planar['wall_s']:.1f}x, "
        f"CPU: {mj['cpu_s'] / planar['cpu_s']:.1f}x; "
        f"target: mujoco <= 60 s on 2 cores, idle ({mj['wall_s']:.0f} s)"
    )


if __name__ == "__main__":
    main()

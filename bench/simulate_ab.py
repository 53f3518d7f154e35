"""CPU time of the planar rollout (``robogs.physics.model.simulate``) against the frozen copy
of the code before the h26 speed-ups (``tests/physics/_reference_simulate.py``), in one run.

Design-A scenarios (``robogs.synth.scenarios.make_scenario``): 6 pushes, and the full design
(pushes, off-centre pushes, release slides, grasp-and-place: 17 trajectories); M = 1, 8, 64
parameter sets (the fitter's columns, the diagnosis's candidates), table tilt in the space.
Each figure is the best of ``--repeat`` process CPU times, one torch thread; the largest
difference between the two is printed beside it (tests/physics/test_simulate_equiv.py holds
it to 1e-12).

    OMP_NUM_THREADS=1 .venv/bin/python bench/simulate_ab.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "physics"))

from _reference_simulate import simulate_reference  # noqa: E402

from robogs.physics.engine import Engine  # noqa: E402
from robogs.physics.model import simulate  # noqa: E402
from robogs.synth.scenarios import make_scenario  # noqa: E402

DESIGNS = {
    "6 pushes": ("push",),
    "full design": ("push", "offset_push", "release_slide", "grasp_place"),
}


def _best(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__}")
    print(f"load average before: {os.getloadavg()[0]:.1f}")
    print("| scenario | T x S | M | before [s CPU] | after [s CPU] | ratio | max diff |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for label, kinds in DESIGNS.items():
        rec = make_scenario("table_tilt", seed=0, kinds=kinds, n_speeds=2, n_dirs=3, check=False)
        eng = Engine(rec)
        space = eng.space(eng.check_effects(["table_tilt"]))
        drive, scene = eng.prep.drive, eng.prep.scene
        for m in (1, 8, 64):
            th = torch.as_tensor(np.stack([eng.start(space)] * m))
            th[:, 0] += torch.linspace(0.0, 0.1, m, dtype=th.dtype)
            t_ref, a = _best(partial(simulate_reference, th, space, drive, scene), args.repeat)
            t_new, b = _best(partial(simulate, th, space, drive, scene), args.repeat)
            diff = max(
                float((a.pos - b.pos).abs().max()), float((a.dense_pos - b.dense_pos).abs().max())
            )
            print(
                f"| {label} | {drive.n_traj} x {drive.n_steps} | {m} | {t_ref:.3f} | {t_new:.3f} "
                f"| {t_ref / t_new:.2f}x | {diff:.1e} |",
                flush=True,
            )
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()

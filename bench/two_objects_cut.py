"""CPU time of the two-object fit on MuJoCo with and without the rest cut (issue 16).

The two-box generator (:mod:`robogs.synth.scenarios.two_objects`, seed 0, pose noise 0.5 mm)
written as a dataset without a force sensor, loaded as ``robogs fit`` loads it; the base fit of
both table frictions (``Engine.fit`` from the nominal 0.35 / 0.35, 10 % FD steps) and
``robogs.physics.api.fit`` (baseline, held-out folds, the written document's baseline), each
with the cut on and then off (``MujocoFit._cut_ok`` patched to False: every step taken), the
process CPU time of each, MuJoCo steps, and the fitted frictions (equal to the digits shown
when the cut is right). MuJoCo and torch run on one thread.

    OMP_NUM_THREADS=1 .venv/bin/python bench/two_objects_cut.py [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import torch

from robogs.physics import baseline as baseline_mod
from robogs.physics.api import fit
from robogs.physics.engine import Engine
from robogs.physics.engines.mujoco_fit import MujocoFit
from robogs.physics.fit import Problem
from robogs.physics.recording import load_recording
from robogs.synth.scenarios.two_objects import make_two_objects, write_two_objects


def _steps_counter() -> tuple[list[int], object]:
    """Count MuJoCo steps of every ``MujocoFit.simulate`` call (``last_steps``)."""
    total = [0]
    orig = MujocoFit.simulate

    def counted(self, *a, **k):
        out = orig(self, *a, **k)
        total[0] += self.last_steps
        return out

    MujocoFit.simulate = counted
    return total, orig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="on/off pairs (alternating)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    os.environ["ROBOGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="h36-cut-")
    ds = Path(tempfile.mkdtemp(prefix="h36-two-")) / "two_boxes"
    write_two_objects(make_two_objects(seed=0, noise=True), ds)
    rec = load_recording(ds)
    total, _ = _steps_counter()
    orig_ok = MujocoFit._cut_ok
    print(f"load average {os.getloadavg()[0]:.2f}")
    for rep in range(args.repeat):
        for cut in (True, False):
            MujocoFit._cut_ok = orig_ok if cut else (lambda self: False)
            total[0] = 0
            c0, w0 = time.process_time(), time.perf_counter()
            eng = Engine(rec, backend="mujoco", threads=1)
            space = eng.space([])
            (out,) = eng.fit(
                space, [Problem(free=eng.base_columns(space), theta0=eng.start(space))]
            )
            c1, w1 = time.process_time(), time.perf_counter()
            s_fit = total[0]
            baseline_mod._CACHE.clear()
            os.environ["ROBOGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="h36-cut-")
            res = fit(ds, write=False, engine="mujoco")
            c2, w2 = time.process_time(), time.perf_counter()
            mu = ", ".join(f"{p.value:.6f}" for p in res.params)
            print(
                f"rep {rep} cut {'on ' if cut else 'off'}: base fit {c1 - c0:6.2f} CPU s "
                f"({w1 - w0:6.2f} wall, {s_fit / 1e6:.2f} M steps, mu {out.theta[0]:.6f} "
                f"{out.theta[1]:.6f}); api.fit {c2 - c1:6.2f} CPU s ({w2 - w1:6.2f} wall, "
                f"{(total[0] - s_fit) / 1e6:.2f} M steps, mu {mu}); load "
                f"{os.getloadavg()[0]:.2f}",
                flush=True,
            )
    MujocoFit._cut_ok = orig_ok


if __name__ == "__main__":
    main()

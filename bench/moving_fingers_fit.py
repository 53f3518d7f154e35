"""CPU time of the MuJoCo base fit with moving gripper fingers (servo DOFs, rest cut off) against
the same pushes with the fingers held still (rest cut on), issue 16 (h89).

The datasets of ``tests/physics/test_moving_fingers_dataset.py``: the scenario generator's 4
pushes (seed 0) with the gripper URDF (the generator's capsule on ``ee``, two fingers that never
touch the box), the fingers opening and closing 50-70 mm at 1.5 Hz (``moving``: DOFs ``j_l``,
``j_r``, which switch the rest cut off, ``MujocoFit._cut_ok``) or held at 60 mm (``still``: the
fingers are fixed frames on the pusher body, the cut on). Each is fitted as ``robogs fit`` does
(``Engine.fit`` of the base columns from the stored values; then ``robogs.physics.api.fit``
with baselines and held-out folds, write=False); ``still`` once more with the cut patched off,
which separates the cut's share from the DOF bodies' own cost. Process CPU time, MuJoCo steps
and the fitted friction of each; MuJoCo and torch on one thread. Ratios are against ``still``
(cut on) in the same run, the minimum over ``--repeat`` rounds.

    OMP_NUM_THREADS=1 .venv/bin/python bench/moving_fingers_fit.py [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "physics"))
from test_moving_fingers_dataset import build_gripper_dataset, moving, still  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="rounds of the three cases")
    args = ap.parse_args()
    torch.set_num_threads(1)
    tmp = Path(tempfile.mkdtemp(prefix="h89-fingers-"))
    roots = {}
    for name, fn in (("moving", moving), ("still", still)):
        build_gripper_dataset(tmp / name, fn)
        roots[name] = tmp / name
    steps = [0]
    orig_sim, orig_ok = MujocoFit.simulate, MujocoFit._cut_ok

    def counted(self, *a, **k):
        out = orig_sim(self, *a, **k)
        steps[0] += self.last_steps
        return out

    MujocoFit.simulate = counted
    cases = (("still", True), ("still", False), ("moving", True))
    best: dict[str, list[float]] = {}
    print(f"{platform.machine()}, {os.cpu_count()} CPUs, threads 1, load {os.getloadavg()[0]:.2f}")
    for rep in range(args.repeat):
        for name, cut in cases:
            label = f"{name}{'' if cut else ' (cut patched off)'}"
            MujocoFit._cut_ok = orig_ok if cut else (lambda self: False)
            rec = load_recording(roots[name])
            steps[0] = 0
            c0 = time.process_time()
            eng = Engine(rec, backend="mujoco", threads=1)
            space = eng.space([])
            (out,) = eng.fit(
                space, [Problem(free=eng.base_columns(space), theta0=eng.start(space))]
            )
            c1 = time.process_time()
            s_fit = steps[0]
            baseline_mod._CACHE.clear()
            os.environ["ROBOGS_CACHE_DIR"] = tempfile.mkdtemp(prefix="h89-cache-")
            res = fit(roots[name], write=False, engine="mujoco")
            c2 = time.process_time()
            b = best.setdefault(label, [float("inf")] * 2)
            b[0], b[1] = min(b[0], c1 - c0), min(b[1], c2 - c1)
            print(
                f"rep {rep} {label:26s} base fit {c1 - c0:6.2f} CPU s ({s_fit / 1e6:.3f} M steps, "
                f"mu {out.theta[0]:.7f}); api.fit {c2 - c1:6.2f} CPU s "
                f"({(steps[0] - s_fit) / 1e6:.3f} M steps, mu {res.params[0].value:.7f}); "
                f"load {os.getloadavg()[0]:.2f}",
                flush=True,
            )
    MujocoFit._cut_ok, MujocoFit.simulate = orig_ok, orig_sim
    ref = best["still"]
    for label, (a, b) in best.items():
        print(
            f"min {label:26s} base fit {a:6.2f} s ({a / ref[0]:.2f}x), api.fit {b:6.2f} s "
            f"({b / ref[1]:.2f}x)"
        )


if __name__ == "__main__":
    main()

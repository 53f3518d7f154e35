"""Pusher-drive smoothing: parameter bias from encoder noise alone, tricube vs Savitzky-Golay.

Scenarios of the hidden-effect suite with the pose tracker made almost exact (0.1 mm, 1e-4 rad,
no stamp jitter) and the encoders at their nominal 1e-4 rad, so that what is left of the
parameter error comes from the drive. Each case is fitted (friction + the hidden effect) with
the EE smoothed by the library's degree-4 tricube local polynomial (80 ms positions, 60 ms
velocities) and, as the baseline, by the quadratic Savitzky-Golay filter it replaced (40 ms
positions, 24 ms velocities); then again with noiseless encoders, to separate the noise from
the rounding of the drive.

    .venv/bin/python bench/drive_smoothing.py [--seeds 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _savgol(t: np.ndarray, x: np.ndarray, window: float, *, deriv: int = 0, **_: object):
    from scipy.signal import savgol_filter

    period = float(np.median(np.diff(t)))
    n = int(round((0.04 if deriv == 0 else 0.024) / period)) | 1
    return savgol_filter(x, n, 2, deriv=deriv, delta=period, axis=0, mode="interp")


def _fit(effect: str, seed: int, level: str) -> dict[str, float]:
    from robogs.physics.effects import get_effect
    from robogs.physics.engine import Engine
    from robogs.physics.fit import Problem
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario(effect, seed=seed, noise=level, check=False)
    eng = Engine(rec)
    space = eng.space([get_effect(effect)])
    free = eng.base_columns(space) + space.owner_columns(effect)
    out = eng.fit(space, [Problem(free=free)])[0]
    return {
        k: float(out.theta[space.index(effect, k)] / v - 1.0)
        for k, v in rec.meta["true_params"].items()
    }


def main() -> None:
    import torch

    import robogs.physics.prepare as prep
    import robogs.synth.scenarios.generate as gen

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=3)
    a = ap.parse_args()
    torch.set_num_threads(1)
    gen.NOISE_LEVELS["encoders_only"] = {"pos": 1e-4, "rot": 1e-4, "jitter": 0.0, "encoder": 1e-4}
    gen.NOISE_LEVELS["noiseless"] = {"pos": 1e-4, "rot": 1e-4, "jitter": 0.0, "encoder": 0.0}
    ours = prep.local_polynomial
    print(
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; torch threads 1"
    )
    print(
        "| effect | encoders | tricube mean abs err | Savitzky-Golay mean abs err | ratio | mean signed (tricube / SG) |"
    )
    print("|---|---|---|---|---|---|")
    t0 = time.perf_counter()
    for effect in ("quadratic_drag", "viscous_damping", "stribeck"):
        for level in ("encoders_only", "noiseless"):
            errs = {}
            for name, fn in (("tricube", ours), ("sg", _savgol)):
                prep.local_polynomial = fn
                errs[name] = np.array(
                    [list(_fit(effect, s, level).values()) for s in range(a.seeds)]
                )
            prep.local_polynomial = ours
            m_t, m_s = np.mean(np.abs(errs["tricube"])), np.mean(np.abs(errs["sg"]))
            print(
                f"| {effect} | {'1e-4 rad' if level == 'encoders_only' else 'none'} | "
                f"{100 * m_t:.1f} % | {100 * m_s:.1f} % | {m_t / m_s:.2f} | "
                f"{100 * errs['tricube'].mean():+.1f} % / {100 * errs['sg'].mean():+.1f} % |",
                flush=True,
            )
    print(f"{a.seeds} seeds per row; wall {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

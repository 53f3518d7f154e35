"""MuJoCo's friction bias on the noise-free 9-push scene when the encoder stamps fall between
the 1 ms steps: servo targets smoothed over the drive's own sample interval (``Drive.sample_dt``,
h75) against the spacing read from the path's second differences (h67; reads 1 off the grid).

The scene is ``make_scenario("none", seed=0, kinds=("push",), noise="zero")`` (h42 / h55 / h67's
``bias.py``): chi^2 of the base model over table friction 0.33 ... 0.37, best friction from a
quadratic, bias against the generator's 0.35. Clocks:

* ``grid``: the generator's own 500 Hz stamps, on the grid;
* ``jit500``: the same stamps (except the first, the grid's origin) moved by U(-0.2, 0.2) ms,
  with the EE pose resampled from the generator's fine truth at the new stamps;
* ``hzN``: the generator's encoder at N Hz (``generate.ENCODER_HZ``; 333 Hz: 3.003 steps).

For each clock the same prepared recording is evaluated twice in one run: with the interval
(the default) and with ``drive.sample_dt = None`` (the engine then reads the spacing from the
path, as before h75). ``--backend planar`` gives the rigid reference (no servo).

    OMP_NUM_THREADS=1 .venv/bin/python bench/drive_clock_bias.py [--ballast 99] \
        [--clocks grid jit500 hz333 hz120] [--backend mujoco]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time

import numpy as np
import torch

import robogs.format.mjcf as mjcf
import robogs.physics.engines.mujoco_engine as me
import robogs.synth.scenarios.generate as gen
from robogs.physics.engine import Engine

MUS = np.array([0.33, 0.34, 0.35, 0.36, 0.37])


def recording(clock: str):
    """The 9-push recording with its encoder on ``clock``."""
    hz = gen.ENCODER_HZ
    if clock.startswith("hz"):
        gen.ENCODER_HZ = float(clock[2:])
    try:
        rec = gen.make_scenario("none", seed=0, kinds=("push",), noise="zero")
    finally:
        gen.ENCODER_HZ = hz
    if clock == "jit500":
        _, _, path, _, _ = gen._truth("none", ("push",), 3, 3, None)
        rng = np.random.default_rng(0)
        for i, tr in enumerate(rec.trajectories):
            t0 = int(tr.ee_t_ns[0])
            te = (tr.ee_t_ns - t0) * 1e-9
            te[1:] = te[1:] + rng.uniform(-2e-4, 2e-4, len(te) - 1)
            tr.ee_t_ns = t0 + np.round(te * 1e9).astype(np.int64)
            tr.ee_pos = gen._sample(path.pos[i], te)
            tr.ee_quat = gen._quat_yaw(gen._sample(path.yaw[i], te))
    elif clock != "grid" and not clock.startswith("hz"):
        raise SystemExit(f"unknown clock {clock!r}: grid, jit500 or hzN")
    return rec


def best_friction(eng: Engine) -> float:
    space = eng.space([])
    names = [sl.param.name for sl in space.slots]
    th = np.repeat(eng.start(space)[None], len(MUS), 0)
    th[:, [k for k, n in enumerate(names) if "friction" in n][0]] = MUS
    r = eng.evaluate(space, th, np.zeros((len(MUS), eng.prep.n_traj, 3)))
    p = np.polyfit(MUS, (r**2).reshape(len(MUS), -1).sum(1), 2)
    return float(-p[1] / (2 * p[0]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ballast", type=float, default=9.0, help="z ballast B (default 9)")
    ap.add_argument("--clocks", nargs="+", default=["grid", "jit500", "hz333", "hz120"])
    ap.add_argument("--backend", default="mujoco")
    a = ap.parse_args()
    torch.set_num_threads(1)
    s = dataclasses.replace(mjcf.PLANAR_SETTINGS, z_ballast=a.ballast)
    mjcf.PLANAR_SETTINGS = me.PLANAR_SETTINGS = s
    print(
        f"# {platform.machine()}, {os.cpu_count()} CPUs, torch threads {torch.get_num_threads()}, "
        f"OMP {os.environ.get('OMP_NUM_THREADS')}, backend {a.backend}, z ballast {a.ballast:g}"
    )
    print("| clock | median EE dt | spacing read from path | carried | bias read | bias carried |")
    print("|---|---|---|---|---|---|")
    for clock in a.clocks:
        t = time.perf_counter()
        rec = recording(clock)
        eng = Engine(rec, backend=a.backend)
        drive = eng.prep.drive
        steps = me.sample_steps(drive)
        carried = best_friction(eng)
        every, drive.sample_dt = drive.sample_dt, None
        read = best_friction(eng)
        drive.sample_dt = every
        dt = float(np.median(np.diff(rec.trajectories[0].ee_t_ns))) * 1e-9
        print(
            f"| {clock} | {dt * 1e3:.4f} ms | {me.drive_knot_steps(drive.pusher.numpy())} | "
            f"{np.median(steps):.4f} ({steps.min():.3f}-{steps.max():.3f}) | "
            f"{100 * (read / 0.35 - 1):+.2f} % | {100 * (carried / 0.35 - 1):+.2f} % |"
            f"  ({time.perf_counter() - t:.1f} s)",
            flush=True,
        )


if __name__ == "__main__":
    main()

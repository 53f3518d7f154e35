"""The two-object fit with the force bin derived from the data against the fixed 100 ms bin.

The two-box generator (:mod:`robogs.synth.scenarios.two_objects`: a rigid chain, its force does
not ring) and the same recording with a ring added to its force sensor from the moment the
pusher drives both boxes (a real chain of contacts rings; ``--ring-hz``, 0.3 N decaying over
two periods); each fitted on MuJoCo from poses and force (``Engine.fit`` of both table
frictions from the nominal 0.35 / 0.35) with the bin :func:`robogs.physics.prepare.
chain_force_bin` derives and with ``CHAIN_FORCE_BIN_S`` = 0.1 s; errors of mu_a, mu_b against the
generator's 0.45 / 0.25 and the force residual RMS.

    OMP_NUM_THREADS=1 .venv/bin/python bench/chain_force_bin.py [--seeds 0 1 2] [--ring-hz 25]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

import robogs.physics.prepare as prepare_mod
from robogs.physics.engine import Engine
from robogs.physics.fit import Problem
from robogs.physics.prepare import force_rms
from robogs.synth.scenarios.two_objects import TwoBoxTruth, make_two_objects


def add_ring(rec, hz: float, amp: float = 0.3, periods: float = 2.0) -> None:
    """Add a ring of ``hz`` [Hz], ``amp`` [N], decaying by e over ``periods`` periods, along the
    push to the force sensor of every trajectory, from its first sample pushing both boxes."""
    for tr in rec.trajectories:
        f = tr.wrench_force[:, :2] - np.median(tr.wrench_force[:50, :2], axis=0)
        k = int(np.argmax(np.linalg.norm(f, axis=1) > 2.2))  # both boxes pushed: 2.77 N
        s = (tr.wrench_t_ns[k:] - tr.wrench_t_ns[k]) * 1e-9
        ring = amp * np.exp(-s * hz / periods) * np.sin(2 * np.pi * hz * s)
        tr.wrench_force = tr.wrench_force.copy()
        tr.wrench_force[k:, :2] += ring[:, None] * f[k] / np.linalg.norm(f[k])


def fit_once(rec) -> tuple[float, float, dict, str, float]:
    eng = Engine(rec, backend="mujoco", threads=1)
    space = eng.space([])
    c0 = time.process_time()
    (out,) = eng.fit(space, [Problem(free=eng.base_columns(space), theta0=eng.start(space))])
    note = eng.prep.wrench_note
    bins = note.split(" bins of ")[1].split(" ms")[0]
    return *out.theta[:2], force_rms(eng.prep, out.resid), bins, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--ring-hz", type=float, default=25.0)
    args = ap.parse_args()
    torch.set_num_threads(1)
    truth = TwoBoxTruth()
    derived = prepare_mod.chain_force_bin
    print(f"load average {os.getloadavg()[0]:.2f}")
    for seed in args.seeds:
        for ring in (0.0, args.ring_hz):
            for how in ("derived", "fixed 0.1 s"):
                rec = make_two_objects(seed=seed, noise=True)
                if ring:
                    add_ring(rec, ring)
                prepare_mod.chain_force_bin = (
                    derived if how == "derived" else (lambda *a, **k: (0.1, "fixed"))
                )
                mu_a, mu_b, f, bins, cpu = fit_once(rec)
                print(
                    f"seed {seed} ring {ring:4.0f} Hz, {how:11s}: bins {bins} ms, mu_a {mu_a:.4f} "
                    f"({100 * (mu_a / truth.mu_a - 1):+.1f} %), mu_b {mu_b:.4f} "
                    f"({100 * (mu_b / truth.mu_b - 1):+.1f} %), force {f['rms_n']:.3f} N "
                    f"(floor {f['noise_floor_n']:.3f} N), {cpu:.1f} CPU s",
                    flush=True,
                )
    prepare_mod.chain_force_bin = derived


if __name__ == "__main__":
    main()

"""Rollout throughput of the two engines on the 9-push scene, and of a 64-candidate batch.

The fitter's finite-difference Jacobians and the diagnosis run many parameter sets at once.
Scenario: 9 pushes (robogs.synth.scenarios), dt = 1 ms. Measured in one run:

* planar (torch): a batch of 64 parameter sets in one rollout vs 64 single rollouts, full
  effect catalogue in the parameter space (its rollouts stop once every box rests and the end
  effector no longer moves; steps are counted on the full grid);
* mujoco: steps per second of one rollout of the scene (9 trajectories), and a 64-candidate
  finite-difference batch (64 friction values x 9 trajectories = 576 MuJoCo rollouts) on
  ``mujoco.rollout`` with 1 and 2 threads;
* the fitting path (``Engine.evaluate`` on each backend): 64 parameter sets over the full
  catalogue, with no effect, a model-parameter effect (viscous damping: MuJoCo DOF damping) and
  a per-step force effect (Stribeck: one ``mujoco.rollout`` call per step);
* the ratio of the two engines' 64-candidate times.

    .venv/bin/python bench/simulate.py [--no-write]
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _planar(m: int) -> tuple[dict[str, float], object]:
    from robogs.physics.effects import available_effects, get_effect
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",))
    eng = Engine(rec)
    space = eng.space([get_effect(n) for n in available_effects(model="rigid")])
    rng = np.random.default_rng(0)
    th = np.stack([eng.start(space)] * m)
    th[:, 0] *= 1.0 + 0.05 * rng.standard_normal(m)
    loc = np.zeros((m, eng.prep.n_traj, 3))
    eng.evaluate(space, th[:2], loc[:2])  # warm-up
    t0 = time.perf_counter()
    eng.evaluate(space, th, loc)
    batched = time.perf_counter() - t0
    t0 = time.perf_counter()
    for i in range(m):
        eng.evaluate(space, th[i : i + 1], loc[i : i + 1])
    single = time.perf_counter() - t0
    return {"batched": batched, "single": single}, (rec, eng.prep)


def _mujoco(rec, prep, m: int, threads: int) -> dict[str, float]:
    from robogs.physics.engines import get_engine

    eng = get_engine("mujoco")(rec.physics, threads=threads)
    eng.rollout(prep.drive.subset([0]))  # warm-up (pool start)
    t0 = time.perf_counter()
    eng.rollout(prep.drive)
    one = time.perf_counter() - t0
    mu = rec.physics["objects"]["box"]["friction_dynamic"] * (1 + 1e-3 * np.arange(m))
    t0 = time.perf_counter()
    eng.rollout(prep.drive, params={"objects.box.friction_dynamic": mu})
    batch = time.perf_counter() - t0
    eng.close()
    return {"one": one, "batch": batch}


def _fit_path(rec, backend: str, threads: int, m: int, active: str | None) -> float:
    """Seconds of one ``Engine.evaluate`` of ``m`` parameter sets over the full catalogue
    space on ``backend`` (``active``: that effect at its nominal value in every set, so the
    MuJoCo path applies per-step forces when it is a force effect)."""
    from robogs.physics.effects import available_effects, get_effect
    from robogs.physics.engine import Engine

    eng = Engine(rec, backend=backend, threads=threads)
    space = eng.space([get_effect(n) for n in available_effects(model="rigid")])
    th = np.stack([eng.start(space)] * m)
    th[:, 0] *= 1.0 + 1e-3 * np.arange(m)
    if active is not None:
        for c in space.owner_columns(active):
            th[:, c] = space.slots[c].param.nominal
    loc = np.zeros((m, eng.prep.n_traj, 3))
    eng.evaluate(space, th[:1], loc[:1])  # warm-up
    t0 = time.perf_counter()
    eng.evaluate(space, th, loc)
    return time.perf_counter() - t0


def main() -> None:
    torch.set_num_threads(1)  # small tensors: one thread is fastest (and fair on a shared machine)
    import mujoco

    m = 64
    planar, (rec, prep) = _planar(m)
    n_t, n_s = prep.drive.n_traj, prep.drive.n_steps
    steps = n_t * n_s
    mj = {k: _mujoco(rec, prep, m, k) for k in (1, 2)}
    lines = [
        "### rollout throughput, planar and mujoco engines (bench/simulate.py)",
        "",
        "Command: `.venv/bin/python bench/simulate.py`  ",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs (shared "
        f"with other jobs during the run), torch {torch.__version__} with 1 thread, "
        f"mujoco {mujoco.__version__}",
        f"Scene: 9 pushes, {n_t} trajectories x {n_s} steps of 1 ms = {steps:,} trajectory-steps "
        "per parameter set",
        "",
        f"- planar, batch of {m} sets in one rollout: {planar['batched']:.2f} s = "
        f"{m * steps / planar['batched']:,.0f} trajectory-steps/s "
        f"({m / planar['batched']:.1f} candidate rollouts/s)",
        f"- planar, {m} single rollouts (baseline): {planar['single']:.2f} s = "
        f"{m * steps / planar['single']:,.0f} trajectory-steps/s; batched / single "
        f"{planar['single'] / planar['batched']:.1f}x",
    ]
    for k, r in mj.items():
        lines += [
            f"- mujoco, {k} thread(s), one set: {r['one']:.3f} s = {steps / r['one']:,.0f} steps/s",
            f"- mujoco, {k} thread(s), {m} sets ({m * n_t} MuJoCo rollouts): {r['batch']:.2f} s = "
            f"{m * steps / r['batch']:,.0f} steps/s ({m / r['batch']:.1f} candidate rollouts/s)",
        ]
    best = min(r["batch"] for r in mj.values())
    lines += [
        f"- ratio, {m}-candidate batch: planar {planar['batched']:.2f} s / best mujoco "
        f"{best:.2f} s = {planar['batched'] / best:.2f}x (above 1: mujoco faster)",
        f"- mujoco 2 threads / 1 thread speed-up: {mj[1]['batch'] / mj[2]['batch']:.2f}x",
        "- the planar rollouts stop early once every box rests; mujoco integrates every step",
        "",
        f"Fitting path (`Engine.evaluate`, {m} parameter sets over the full catalogue space, "
        "effects at zero unless named; residuals included):",
        "",
    ]
    fit_rows = {}
    for active in (None, "viscous_damping", "stribeck"):
        fit_rows[(active, "planar", 1)] = _fit_path(rec, "planar", 1, m, active)
        for k in (1, 2):
            fit_rows[(active, "mujoco", k)] = _fit_path(rec, "mujoco", k, m, active)
    for (active, backend, k), sec in fit_rows.items():
        ref = fit_rows[(active, "planar", 1)]
        what = active or "no effect"
        how = {None: "", "viscous_damping": " (model parameter)", "stribeck": " (per-step force)"}
        lines.append(
            f"- {backend}, {k} thread(s), {what}{how[active] if backend == 'mujoco' else ''}: "
            f"{sec:.2f} s = {m * steps / sec:,.0f} steps/s, {m / sec:.1f} candidate rollouts/s "
            f"(planar / this = {ref / sec:.2f}x)"
        )
    print("\n".join(lines))
    if "--no-write" not in sys.argv:
        with (ROOT / "bench" / "RESULTS.md").open("a") as fh:
            fh.write(f"## {datetime.date.today().isoformat()}\n\n" + "\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main()

"""Rollout throughput of the two engines on the 9-push scene, and of a 64-candidate batch.

The fitter's finite-difference Jacobians and the diagnosis run many parameter sets at once.
Scenario: 9 pushes (robogs.synth.scenarios), dt = 1 ms. Measured in one run, each figure with
its wall time, the process's CPU time (all its threads) and the 1-minute load average around it
(on a shared machine the CPU time is the idle-machine estimate of a one-thread figure):

* planar (torch): a batch of 64 parameter sets in one rollout vs 64 single rollouts
  (``--no-single`` skips the singles), full effect catalogue in the parameter space (its rollouts
  stop once every box rests and the end effector no longer moves; steps are counted on the full
  grid);
* mujoco engine interface (``MujocoEngine.rollout``): steps per second of one rollout of the
  scene (9 trajectories) and of 64 friction values x 9 trajectories = 576 MuJoCo rollouts on
  ``mujoco.rollout``, 1 and 2 threads;
* the fitting path (``Engine.evaluate``): 64 parameter sets over the full catalogue, with no
  effect, a model-parameter effect (viscous damping: MuJoCo DOF damping), a per-step force
  effect in every set (Stribeck) and in 16 of the 64 (the diagnosis's joint fits: the other
  candidates' sets beside them), on the previous runner (``stepper="rollout"``: one
  ``mujoco.rollout`` call per chunk, and per step for every set once any set applies a force)
  and on ``mujoco.batch`` (``stepper="batch"``) with 1 and 2 threads;
* the share of the grid's steps the batch runner takes (its rest cut repeats the rest pose
  before the pusher comes within reach and after the box rests for good);
* one forward-difference Jacobian over the full catalogue (``robogs.physics.fit.jacobian_fd``:
  base point, one row per column, three local-offset rows), both runners (the batch runs each
  distinct rollout once: the sensor columns' rows repeat the base point's motion).

    .venv/bin/python bench/simulate.py [--no-write] [--no-single]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

M = 64


def _timed(fn: Callable[[], object]) -> dict[str, float]:
    """Wall and process CPU seconds of ``fn()``, with the load average before and after."""
    l0 = os.getloadavg()[0]
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return {
        "wall": time.perf_counter() - t0,
        "cpu": time.process_time() - c0,
        "load": (l0 + os.getloadavg()[0]) / 2,
    }


def _fmt(r: dict[str, float], work: float, unit: str = "steps/s") -> str:
    return (
        f"{r['wall']:.2f} s wall ({work / r['wall']:,.0f} {unit}), {r['cpu']:.2f} s CPU "
        f"({work / r['cpu']:,.0f} {unit} per CPU second), load {r['load']:.1f}"
    )


def _catalogue_engine(rec, backend: str, threads: int = 1, stepper: str | None = None):
    from robogs.physics.effects import available_effects, get_effect
    from robogs.physics.engine import Engine

    eng = Engine(rec, backend=backend, threads=threads)
    if stepper is not None:
        eng._mujoco.stepper = stepper
    return eng, eng.space([get_effect(n) for n in available_effects(model="rigid")])


def _sets(eng, space, active: str | None, n_active: int) -> tuple[np.ndarray, np.ndarray]:
    """``M`` sets: friction 0.1 % apart, ``active`` at its nominal value in the first
    ``n_active``; zero local offsets."""
    th = np.stack([eng.start(space)] * M)
    th[:, 0] *= 1.0 + 1e-3 * np.arange(M)
    if active is not None:
        for c in space.owner_columns(active):
            th[:n_active, c] = space.slots[c].param.nominal
    return th, np.zeros((M, eng.prep.n_traj, 3))


def _planar(rec, single: bool) -> dict[str, dict[str, float]]:
    eng, space = _catalogue_engine(rec, "planar")
    rng = np.random.default_rng(0)
    th = np.stack([eng.start(space)] * M)
    th[:, 0] *= 1.0 + 0.05 * rng.standard_normal(M)
    loc = np.zeros((M, eng.prep.n_traj, 3))
    eng.evaluate(space, th[:2], loc[:2])  # warm-up
    out = {"batched": _timed(lambda: eng.evaluate(space, th, loc))}
    if single:
        out["single"] = _timed(
            lambda: [eng.evaluate(space, th[i : i + 1], loc[i : i + 1]) for i in range(M)]
        )
    return out


def _interface(rec, prep, threads: int) -> dict[str, dict[str, float]]:
    from robogs.physics.engines import get_engine

    eng = get_engine("mujoco")(rec.physics, threads=threads)
    eng.rollout(prep.drive.subset([0]))  # warm-up (pool start)
    one = _timed(lambda: eng.rollout(prep.drive))
    mu = rec.physics["objects"]["box"]["friction_dynamic"] * (1 + 1e-3 * np.arange(M))
    batch = _timed(lambda: eng.rollout(prep.drive, params={"objects.box.friction_dynamic": mu}))
    eng.close()
    return {"one": one, "batch": batch}


def _fit_path(rec, backend, threads, stepper, active, n_active) -> dict[str, float]:
    """One ``Engine.evaluate`` of ``M`` sets over the full catalogue space."""
    eng, space = _catalogue_engine(rec, backend, threads, stepper)
    th, loc = _sets(eng, space, active, n_active)
    eng.evaluate(space, th[:1], loc[:1])  # warm-up
    r = _timed(lambda: eng.evaluate(space, th, loc))
    if eng._mujoco is not None and eng._mujoco.stepper == "batch":
        r["steps"] = eng._mujoco.last_steps  # taken (the rest cut leaves out the rest poses)
    return r


def _jacobian(rec, stepper: str) -> tuple[dict[str, float], int, int]:
    """One FD Jacobian over every column of the full catalogue space (effects at zero); the
    previous runner runs every row (no search for repeated rollouts, as before)."""
    from robogs.physics.fit import jacobian_fd

    eng, space = _catalogue_engine(rec, "mujoco", 1, stepper)
    eng._mujoco.distinct = stepper == "batch"
    th = eng.start(space)
    loc = np.zeros((eng.prep.n_traj, 3))
    fn = eng.residual_fn(space)
    cols = list(range(len(space.slots)))
    r = _timed(lambda: jacobian_fd(fn, space, th, loc, cols))
    return r, len(cols) + 4, eng._mujoco.last_rollouts


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-write", action="store_true", help="print only, no bench/RESULTS.md")
    ap.add_argument("--no-single", action="store_true", help="skip the 64 single planar rollouts")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)  # small tensors: one thread is fastest (and fair on a shared machine)
    import mujoco

    from robogs.physics.prepare import prepare
    from robogs.synth.scenarios import make_scenario

    rec = make_scenario("none", seed=0, kinds=("push",))
    prep = prepare(rec, dt=1e-3)
    n_t, n_s = prep.drive.n_traj, prep.drive.n_steps
    steps = n_t * n_s
    load0 = os.getloadavg()
    planar = _planar(rec, not args.no_single)
    mj = {k: _interface(rec, prep, k) for k in (1, 2)}
    lines = [
        "### rollout throughput, planar and mujoco engines (bench/simulate.py)",
        "",
        f"Command: `.venv/bin/python bench/simulate.py {' '.join(sys.argv[1:])}`  ",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load "
        f"average {load0[0]:.1f} / {load0[1]:.1f} / {load0[2]:.1f} at the start (shared with "
        f"other jobs unless ~0); torch {torch.__version__} with 1 thread, mujoco "
        f"{mujoco.__version__}. Wall times scale with the load; CPU times are the process's "
        "(all its threads): with one thread, the idle-machine estimate.",
        f"Scene: 9 pushes, {n_t} trajectories x {n_s} steps of 1 ms = {steps:,} trajectory-steps "
        "per parameter set",
        "",
        f"- planar, batch of {M} sets in one rollout: {_fmt(planar['batched'], M * steps)}",
    ]
    if "single" in planar:
        lines.append(
            f"- planar, {M} single rollouts (baseline): {_fmt(planar['single'], M * steps)}; "
            f"batched / single {planar['single']['wall'] / planar['batched']['wall']:.1f}x wall"
        )
    for k, r in mj.items():
        lines += [
            f"- mujoco interface (`MujocoEngine.rollout`), {k} thread(s), one set: "
            f"{_fmt(r['one'], steps)}",
            f"- mujoco interface, {k} thread(s), {M} sets ({M * n_t} rollouts): "
            f"{_fmt(r['batch'], M * steps)}; {M / r['batch']['wall']:.1f} candidate rollouts/s",
        ]
    lines += [
        "",
        f"Fitting path (`Engine.evaluate`, {M} parameter sets over the full catalogue space, "
        "effects at zero unless named; residuals included). Runners: `rollout` = the previous "
        "one (`mujoco.rollout`), `batch` = `mujoco.batch`:",
        "",
        "| effect | engine, runner, threads | wall | CPU | candidate rollouts/s (wall) "
        "| planar / this (wall) | rollout runner / this (CPU) | MuJoCo steps taken / grid "
        "| load |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    cases = [
        (None, M, "no effect"),
        ("viscous_damping", M, "viscous damping (model parameter), all sets"),
        ("stribeck", M, "Stribeck (per-step force), all sets"),
        ("stribeck", M // 4, f"Stribeck in {M // 4} of {M} sets"),
    ]
    for active, n_active, what in cases:
        ref = _fit_path(rec, "planar", 1, None, active, n_active)
        rows = [("planar, 1", ref)]
        old = _fit_path(rec, "mujoco", 1, "rollout", active, n_active)  # no repeats in these
        rows.append(("mujoco, rollout, 1", old))
        for k in (1, 2):
            r = _fit_path(rec, "mujoco", k, "batch", active, n_active)
            rows.append((f"mujoco, batch, {k}", r))
        for name, r in rows:
            lines.append(
                f"| {what} | {name} | {r['wall']:.2f} s | {r['cpu']:.2f} s | "
                f"{M / r['wall']:.1f} | {ref['wall'] / r['wall']:.2f}x | "
                f"{old['cpu'] / r['cpu']:.2f}x | "
                + (f"{r['steps'] / (M * steps):.1%}" if "steps" in r else "-")
                + f" | {r['load']:.1f} |"
            )
    jac = {s: _jacobian(rec, s) for s in ("rollout", "batch")}
    (jr, rows_j, _), (jb, _, distinct) = jac["rollout"], jac["batch"]
    lines += [
        "",
        f"FD Jacobian over the full catalogue ({rows_j} parameter sets x {n_t} trajectories; "
        f"the batch ran {distinct} distinct rollouts of {rows_j * n_t}): rollout runner "
        f"{jr['wall']:.2f} s wall / {jr['cpu']:.2f} s CPU, batch {jb['wall']:.2f} s / "
        f"{jb['cpu']:.2f} s CPU = {jr['cpu'] / jb['cpu']:.2f}x (CPU), load {jb['load']:.1f}",
    ]
    print("\n".join(lines))
    if not args.no_write:
        with (ROOT / "bench" / "RESULTS.md").open("a") as fh:
            fh.write(
                f"## simulate.py: engine throughput ({datetime.date.today().isoformat()})\n\n"
                + "\n".join(lines)
                + "\n\n"
            )


if __name__ == "__main__":
    main()

"""The planar model's compiled steps (robogs.physics.step_kernels) against its numpy reference.

In one run, each figure with the numpy reference as its in-run baseline (same process, same
inputs, results checked equal to the bit before any time is reported):

* ``Engine.evaluate`` of 8 and 64 parameter sets (the fitter's Jacobian batches) over the full
  catalogue on design A (20 trajectories, capsule pusher) and design B (9, sphere): best of
  ``--repeat`` runs;
* with ``--diagnose``: one diagnosis of design A hiding a centre-of-mass offset and Stribeck
  friction (two candidates, the parametric null; the slowest diagnosis of the test suite) with
  the kernels and without (about 4 minutes).

Threads: torch, OpenMP and BLAS 1 (set below, before numpy and torch load); the kernels are
serial loops.

    .venv/bin/python bench/planar_steps.py [--diagnose] [--repeat N] [--no-write]
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import datetime  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from contextlib import nullcontext  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import robogs.physics.step_kernels as SK  # noqa: E402

CATALOGUE = [
    "table_tilt",
    "anisotropic_friction",
    "viscous_damping",
    "quadratic_drag",
    "stribeck",
    "com_offset",
    "restitution",
]


class _Switch:
    """Turns the compiled kernels off inside ``with`` (the model then runs its reference)."""

    def __enter__(self) -> None:
        self._k = SK.kernels
        SK.kernels = lambda: None  # type: ignore[assignment]

    def __exit__(self, *exc: object) -> None:
        SK.kernels = self._k  # type: ignore[assignment]


def _recording(design: str):
    if design == "A":
        from robogs.synth.scenarios import make_scenario

        return make_scenario("com_offset+stribeck", seed=1, noise="nominal")
    from robogs.synth.scenarios.design_b import make_design_b

    return make_design_b("restitution", seed=3, with_detectability=False)


def _evaluate_rows(repeat: int) -> list[str]:
    from robogs.physics.engine import Engine

    rows = []
    for design in ("A", "B"):
        rec = _recording(design)
        eng = Engine(rec, backend="planar")
        space = eng.space(eng.check_effects(CATALOGUE))
        for m in (8, 64):
            r = np.random.default_rng(m)
            th = np.repeat(eng.start(space)[None], m, 0)
            th[1:] += r.normal(0.0, 0.01, th[1:].shape)
            loc = r.normal(0.0, 1e-3, (m, eng.prep.n_traj, 3))
            fast = eng.evaluate(space, th, loc)  # compiles on a cold cache
            with _Switch():
                ref = eng.evaluate(space, th, loc)
            if not np.array_equal(fast, ref, equal_nan=True):
                raise SystemExit(f"design {design}, {m} sets: kernels differ from the reference")
            t_fast, t_ref = [], []
            for _ in range(repeat):
                t0 = time.perf_counter()
                eng.evaluate(space, th, loc)
                t_fast.append(time.perf_counter() - t0)
                with _Switch():
                    t0 = time.perf_counter()
                    eng.evaluate(space, th, loc)
                    t_ref.append(time.perf_counter() - t0)
            a, b = min(t_ref), min(t_fast)
            rows.append(
                f"| {design} ({eng.prep.n_traj} trajectories) | {m} | {a:.3f} | {b:.3f} | "
                f"**{a / b:.2f}x** |"
            )
            print(rows[-1], flush=True)
    return rows


def _diagnose_row() -> str:
    from robogs.physics.diagnose import diagnose_recording
    from robogs.physics.engine import Engine

    rec = _recording("A")
    out = {}
    for label in ("numpy", "numba"):
        with (
            tempfile.TemporaryDirectory() as cache,
            _Switch() if label == "numpy" else nullcontext(),
        ):
            os.environ["ROBOGS_CACHE_DIR"] = cache
            os.environ["ROBOGS_GATE_METHOD"] = "parametric"
            t0 = time.perf_counter()
            res = diagnose_recording(rec, effects=["com_offset", "stribeck"], engine=Engine(rec))
            out[label] = (time.perf_counter() - t0, [(r.name, r.delta_bic) for r in res.rows])
        print(label, f"{out[label][0]:.1f} s", flush=True)
    if out["numpy"][1] != out["numba"][1]:
        raise SystemExit(f"the diagnoses differ: {out['numpy'][1]} vs {out['numba'][1]}")
    a, b = out["numpy"][0], out["numba"][0]
    name = "diagnose, design A, 2 candidates (same rows and ΔBIC)"
    return f"| {name} | - | {a:.1f} | {b:.1f} | **{a / b:.2f}x** |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--diagnose", action="store_true", help="also time a design A diagnosis")
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure (best is kept)")
    ap.add_argument("--no-write", action="store_true", help="do not append to bench/RESULTS.md")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if SK.kernels() is None:
        raise SystemExit(f"no compiled kernels: {SK.unavailable_reason()}")
    load0 = os.getloadavg()[0]
    rows = _evaluate_rows(args.repeat)
    if args.diagnose:
        rows.append(_diagnose_row())
    load1 = os.getloadavg()[0]
    import numba

    head = (
        f"Machine {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}; torch/OpenMP/BLAS threads 1, kernels "
        f"serial; 1-min load {load0:.1f} before, {load1:.1f} after. Best of {args.repeat} runs."
    )
    table = [
        "| scene | parameter sets | numpy reference [s] | numba kernels [s] | speed-up (in-run) |",
        "|---|---|---|---|---|",
        *rows,
    ]
    print(head)
    print("\n".join(table))
    if not args.no_write:
        now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        cmd = "bench/planar_steps.py" + (" --diagnose" if args.diagnose else "")
        with open(ROOT / "bench" / "RESULTS.md", "a", encoding="utf-8") as fh:
            fh.write(
                f"\n## planar model: compiled steps against the numpy reference ({now})\n\n"
                f"Command: `.venv/bin/python {cmd}`. {head} Every figure's results were checked "
                "equal to the bit before timing.\n\n" + "\n".join(table) + "\n"
            )


if __name__ == "__main__":
    main()

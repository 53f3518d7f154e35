"""Long fuzz campaign over every reader: the targets of ``tests/hardening`` with many examples.

Runs each Hypothesis target of ``tests/hardening/targets.py`` (structure-aware and byte-level
mutations of valid seeds) for its share of a time budget, in rounds of fresh random examples,
and checks every run against the hardening contract (exit 0/1/2, no traceback, no check crash,
under 10 CPU s, under 2 GB). Failures are not shrunk; their input is saved under ``--out`` so
that it can be replayed. Prints, per target, the runs, the exit-code counts, the slowest run and
the distinct failures, then a JSON summary.

``--atheris TARGET`` instead runs coverage-guided atheris/libFuzzer
(https://github.com/google/atheris) on the raw bytes of one target's seed file, in a child
process (``pip install robogs[fuzz]``).

Examples::

    nice -n 10 python bench/fuzz_campaign.py --minutes 10
    python bench/fuzz_campaign.py --minutes 2 --targets mcap,ros1
    python bench/fuzz_campaign.py --atheris splats --seconds 120
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO))

#: raw-bytes targets for atheris: target -> (case variant, seed file relative to the seed folder)
ATHERIS_FILES = {
    "manifest": ("manifest.json", "ds/manifest.json"),
    "sidecar": ("cameras/cam0.json", "ds/cameras/cam0.json"),
    "splats": ("assets/box/splats.ply", "ds/assets/box/splats.ply"),
    "urdf": ("robot/robot.urdf", "ds/robot/robot.urdf"),
    "meshes": ("assets/box/mesh.ply", "ds/assets/box/mesh.ply"),
    "mcap": ("nocrc_zstd.mcap", "nocrc_zstd.mcap"),
    "ros1": ("a_bz2.bag", "a_bz2.bag"),
    "video": ("v.avi", "v.avi"),
    "calibration": ("cam_ros.yaml", "cam_ros.yaml"),
    "stamps": ("stamps.csv", "stamps.csv"),
    "tabular_csv": ("log.csv", "log.csv"),
    "robot_urdf": ("robot.urdf", "robot/robot.urdf"),
}


def _run_target(tgt, seeds, seconds: float, chunk: int, out: Path, start_seed: int) -> dict:
    from hardening.targets import run_case
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed

    strategy = tgt.strategy(seeds)
    rcs: collections.Counter = collections.Counter()
    errors: collections.Counter = collections.Counter()
    failures: dict[str, dict] = {}
    runs, slowest, slowest_argv = 0, 0.0, ""
    t_end = time.perf_counter() + seconds
    rnd = start_seed
    while time.perf_counter() < t_end:
        rnd += 1

        @hseed(rnd)
        @settings(
            max_examples=chunk,
            deadline=None,
            database=None,
            phases=[Phase.generate],
            suppress_health_check=list(HealthCheck),
        )
        @given(case=strategy)
        def one(case) -> None:
            nonlocal runs, slowest, slowest_argv
            if time.perf_counter() > t_end:
                return
            v = run_case(seeds, tgt, case)
            runs += 1
            rcs[str(v.rc)] += 1
            if v.cpu_s > slowest:
                slowest, slowest_argv = v.cpu_s, " ".join(v.argv[:2])
            if not v.ok:
                last = (v.detail.strip().splitlines() or [""])[-1][:160]
                key = f"{v.problem}: {last}"
                f = failures.setdefault(key, {"count": 0, "saved": []})
                f["count"] += 1
                if len(f["saved"]) < 3:
                    name = f"{tgt.name}-{len(failures)}-{f['count']}"
                    data = case.data if isinstance(case.data, bytes) else repr(case.data).encode()
                    (out / f"{name}.input").write_bytes(data)
                    (out / f"{name}.txt").write_text(f"variant {case.variant}\n{v.describe()}\n")
                    f["saved"].append(name)

        try:
            one()
        except Exception as exc:  # noqa: BLE001 - a mutator bug must not end the campaign
            errors[f"{type(exc).__name__}: {str(exc).splitlines()[0][:120]}"] += 1
    return {
        "target": tgt.name,
        "family": tgt.family,
        "runs": runs,
        "exit_codes": dict(rcs),
        "slowest_cpu_s": round(slowest, 2),
        "slowest": slowest_argv,
        "failures": failures,
        "mutator_errors": dict(errors),
    }


def campaign(args: argparse.Namespace) -> int:
    from hardening.seeds import build_seeds
    from hardening.targets import TARGETS

    names = [t for t in args.targets.split(",") if t] if args.targets else [t.name for t in TARGETS]
    targets = [t for t in TARGETS if t.name in names]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="robogs-fuzz-seeds-") as tmp:
        seeds = build_seeds(Path(tmp) / "seeds")
        budget = args.minutes * 60 - (time.perf_counter() - t0)
        share = max(budget / len(targets), 1.0)
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
              f"python {platform.python_version()}; {len(targets)} targets, {share:.0f} s each")  # fmt: skip
        results = []
        for k, tgt in enumerate(targets):
            r = _run_target(tgt, seeds, share, args.chunk, out, args.seed + 1000 * k)
            results.append(r)
            fails = sum(f["count"] for f in r["failures"].values())
            print(f"{r['target']:16s} {r['family']:24s} runs {r['runs']:6d}  exit {r['exit_codes']}  "
                  f"slowest {r['slowest_cpu_s']:.2f} CPU s  failures {fails}", flush=True)  # fmt: skip
            for key, f in r["failures"].items():
                print(f"    {f['count']:4d} x {key}  (saved: {', '.join(f['saved'])})")
            for key, n in r["mutator_errors"].items():
                print(f"    mutator error (harness bug, not robogs) x{n}: {key}")
    total = sum(r["runs"] for r in results)
    crashes = sum(f["count"] for r in results for f in r["failures"].values())
    summary = {
        "minutes": round((time.perf_counter() - t0) / 60, 2),
        "runs": total,
        "failures": crashes,
        "peak_rss_mb": round(__import__("resource").getrusage(0).ru_maxrss / 1024),
        "targets": results,
    }
    print(f"total: {total} runs, {crashes} contract failures, {summary['minutes']} min")
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return 1 if crashes else 0


def _atheris_worker(name: str, libfuzzer_args: list[str]) -> None:  # pragma: no cover - child
    import atheris

    with atheris.instrument_imports():
        import robogs.cli.main  # noqa: F401
        import robogs.convert.ingest  # noqa: F401
        import robogs.format.validate  # noqa: F401
    from hardening.seeds import build_seeds
    from hardening.targets import Case, run_case, target

    tmp = Path(tempfile.mkdtemp(prefix="robogs-atheris-"))
    seeds = build_seeds(tmp / "seeds")
    tgt = target(name)
    variant, seed_rel = ATHERIS_FILES[name]
    corpus = tmp / "corpus"
    corpus.mkdir()
    (corpus / "seed").write_bytes((seeds.root / seed_rel).read_bytes())

    def one(data: bytes) -> None:
        v = run_case(seeds, tgt, Case(variant, data))
        if not v.ok:
            raise RuntimeError(v.describe())

    atheris.Setup([sys.argv[0], *libfuzzer_args, str(corpus)], one)
    atheris.Fuzz()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=10.0, help="total time budget (default 10)")
    p.add_argument("--targets", default="", help="comma-separated target names (default: all)")
    p.add_argument("--chunk", type=int, default=50, help="examples per Hypothesis round")
    p.add_argument("--seed", type=int, default=0, help="first Hypothesis seed")
    p.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "robogs-fuzz-campaign"),
                   help="folder for failing inputs and summary.json")  # fmt: skip
    p.add_argument(
        "--atheris", metavar="TARGET", help=f"run atheris on one of {sorted(ATHERIS_FILES)}"
    )
    p.add_argument("--seconds", type=int, default=60, help="atheris run time (s)")
    p.add_argument("--atheris-worker", help=argparse.SUPPRESS)
    args, rest = p.parse_known_args(argv)
    if args.atheris_worker:
        _atheris_worker(args.atheris_worker, rest)
        return 0
    if args.atheris:
        if args.atheris not in ATHERIS_FILES:
            p.error(f"--atheris takes one of {sorted(ATHERIS_FILES)}")
        cmd = [sys.executable, __file__, "--atheris-worker", args.atheris,
               f"-max_total_time={args.seconds}", "-rss_limit_mb=2048", "-timeout=10",
               f"-artifact_prefix={args.out}/"]  # fmt: skip
        Path(args.out).mkdir(parents=True, exist_ok=True)
        return subprocess.call(cmd)
    return campaign(args)


if __name__ == "__main__":
    sys.exit(main())

"""kill -9 campaign: SIGKILL convert, reconstruct and fit at many seeded points; count outcomes.

For each command a reference run (uninterrupted, on a copy) gives its duration T. Then
``--runs`` killed runs follow on one dataset; each kill point is drawn (seeded) from one of:

* ``time``: uniform in [0, 1.05 T] after start (most land in start-up and computation);
* ``tmp``: uniform in [0, 0.5 s] after the writer's temp folder appears (the write phase);
* ``manifest``: uniform in [0, 5 ms] after the manifest lands in the temp folder (the swap).

After each kill the dataset is hashed (every file, manifest included, with hashlib) and
classified as ``previous`` (byte-identical), ``new`` (a complete committed version: files match
the manifest's sizes and sha256) or ``broken``. Every ``--finish-every`` kills, and at the end,
an uninterrupted run must exit 0 and leave no temp folders. Failures: broken states, failed
finishing runs, leftovers after a finishing run.

Usage: ``nice -n 10 .venv/bin/python bench/kill_campaign.py --command convert --runs 50 --seed 0``
(``--command all`` runs the three in turn; ``--append`` adds the table to bench/RESULTS.md).
"""

from __future__ import annotations

import argparse
import collections
import datetime as _dt
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robogs.synth.killrun import (  # noqa: E402
    after_start,
    is_complete_version,
    leftovers,
    manifest_in_tmp,
    run_and_kill,
    run_to_end,
    tmp_appeared,
    tree_digest,
)

COMMANDS = ("convert", "fit", "reconstruct")


def _inputs(root: Path, command: str) -> tuple[Path, list[str]]:
    """Build the input of ``command`` under ``root``; returns (dataset to write, robogs argv)."""
    from robogs.cli.main import main
    from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf

    if command == "convert":
        urdf = root / "ur5.urdf"
        urdf.write_text(ur5_urdf())
        for name, seed in (("logA", 1), ("logB", 2)):
            generate_armlog(root / name, urdf, ArmLogSpec(segments=3, duration_s=6.0, seed=seed))
        target = root / "out"
        assert main(["convert", str(root / "logA"), str(target), "--urdf", str(urdf)]) == 0
        return target, ["convert", str(root / "logB"), str(target), "--urdf", str(urdf), "--force"]
    if command == "fit":
        from robogs.synth.scenarios import make_scenario
        from robogs.synth.scenarios.write import write_scenario

        rec = make_scenario(
            "table_tilt", seed=0, kinds=("push",), n_speeds=2, n_dirs=3, check=False
        )
        target = root / "tilt"
        write_scenario(rec, target)
        return target, ["fit", str(target), "--add", "table_tilt"]
    from robogs.synth.multiview import synthesize_multiview

    target = root / "mv"
    synthesize_multiview(target, n_views=8, width=48, height=36, supersample=2)
    argv = [
        "reconstruct", str(target), "--iterations", "24", "--checkpoint-every", "8",
        "--tsdf-resolution", "40", "--heldout-every", "4", "--threads", "1", "--no-progress",
        "--work-dir", str(root / "work"), "--force",
    ]  # fmt: skip
    return target, argv


def _campaign(command: str, runs: int, seed: int, finish_every: int, budget_s: float) -> dict:
    rng = np.random.default_rng([seed, COMMANDS.index(command)])
    with tempfile.TemporaryDirectory(prefix=f"robogs-kill-{command}-") as tmp:
        root = Path(tmp)
        target, argv = _inputs(root, command)
        log = root / "log.txt"
        ref = root / "ref"
        shutil.copytree(target, ref)
        ref_argv = [str(ref) if a == str(target) else a for a in argv]
        if command == "reconstruct":
            ref_argv[ref_argv.index("--work-dir") + 1] = str(root / "work-ref")
        rc, t_ref = run_to_end(ref_argv, log=log)
        if rc != 0:
            raise SystemExit(f"reference {command} run failed:\n{log.read_text()[-3000:]}")
        t_start = time.perf_counter()
        states: collections.Counter[tuple[str, str]] = collections.Counter()
        failures: list[str] = []
        finished = finish_ok = 0
        left_after_kill = 0
        done = 0
        for k in range(runs):
            if time.perf_counter() - t_start > budget_s:
                break
            kind = rng.choice(["time", "time", "time", "tmp", "manifest"])
            if kind == "time":
                trig = after_start(float(rng.uniform(0.0, 1.05 * t_ref)))
            elif kind == "tmp":
                trig = tmp_appeared(target, float(rng.uniform(0.0, 0.5)))
            else:
                trig = manifest_in_tmp(target, float(rng.uniform(0.0, 0.005)))
            before, left_before = tree_digest(target), set(leftovers(target))
            res = run_and_kill(argv, target, trig, before=before, log=log)
            outcome = res.state if res.killed else f"{res.state} (ended, rc {res.returncode})"
            states[(str(kind), outcome)] += 1
            left_after_kill += bool(set(res.leftovers) - left_before)
            if res.state == "broken" or (not res.killed and res.returncode != 0):
                failures.append(f"run {k}: {res}")
            done += 1
            if (k + 1) % finish_every == 0 or k == runs - 1:
                rc, _ = run_to_end(argv, log=log)
                finished += 1
                ok = rc == 0 and is_complete_version(target) and not leftovers(target)
                finish_ok += ok
                if not ok:
                    failures.append(
                        f"finishing run after kill {k}: rc {rc}, left {leftovers(target)}"
                    )
        if done and done % finish_every:
            rc, _ = run_to_end(argv, log=log)
            finished += 1
            ok = rc == 0 and is_complete_version(target) and not leftovers(target)
            finish_ok += ok
            if not ok:
                failures.append(f"final run: rc {rc}, left {leftovers(target)}")
        return {
            "command": command,
            "argv": " ".join(["robogs", *[Path(a).name if a.startswith(tmp) else a for a in argv]]),
            "reference_s": round(t_ref, 2),
            "kills": done,
            "states": {f"{a}: {b}": n for (a, b), n in sorted(states.items())},
            "kills_leaving_temp_folders": left_after_kill,
            "finishing_runs": finished,
            "finishing_runs_ok": finish_ok,
            "failures": failures,
            "seconds": round(time.perf_counter() - t_start, 1),
        }


def _machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{platform.machine()} {platform.system()}, cpu_count={os.cpu_count()}, load average {load:.1f}"


def _table(results: list[dict]) -> str:
    lines = [
        "| command | reference run s | kills | outcomes (trigger: state) | kills leaving new temp folders | "
        "finishing runs ok | broken / failures |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        outcomes = "; ".join(f"{k} {v}" for k, v in r["states"].items())
        lines.append(
            f"| `{r['argv']}` | {r['reference_s']} | {r['kills']} | {outcomes} | "
            f"{r['kills_leaving_temp_folders']} | {r['finishing_runs_ok']}/{r['finishing_runs']} | "
            f"{len(r['failures'])} |"
        )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--command", choices=(*COMMANDS, "all"), default="all")
    ap.add_argument("--runs", type=int, default=50, help="killed runs per command")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--finish-every", type=int, default=5, help="an uninterrupted run every N kills"
    )
    ap.add_argument(
        "--budget-s", type=float, default=540.0, help="stop killing a command after this"
    )
    ap.add_argument("--append", action="store_true", help="append the table to bench/RESULTS.md")
    ap.add_argument("--json", type=Path, help="also write the results as JSON")
    args = ap.parse_args()
    commands = COMMANDS if args.command == "all" else (args.command,)
    print(f"machine: {_machine()}; commands run single-threaded where they take --threads")
    results = []
    for c in commands:
        r = _campaign(c, args.runs, args.seed, args.finish_every, args.budget_s)
        results.append(r)
        print(json.dumps(r, indent=1))
    table = _table(results)
    print(table)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    failed = sum(len(r["failures"]) for r in results)
    if args.append:
        date = _dt.date.today().isoformat()
        cmd = " ".join(["nice -n 10 .venv/bin/python bench/kill_campaign.py", *sys.argv[1:]])
        cmd = cmd.replace(" --append", "")
        with open(Path(__file__).with_name("RESULTS.md"), "a", encoding="utf-8") as fh:
            fh.write(
                f"\n## kill_campaign — SIGKILL during convert / fit / reconstruct ({date})\n\n"
                f"Command: `{cmd}`\n\nmachine: {_machine()}\n\n{table}\n\n"
                f"Failures: {failed}.\n"
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

"""Validation under load: 1,000 small episodes, and one long episode validated by streaming.

Datasets are written by ``robogs.synth.bulk`` (pyarrow and hashlib directly, independent of the
writer under test) into a temp folder outside the repository: a planar 3R arm whose
``joint_states`` and ``ee_poses`` are sampled at 500 Hz with a closed-form end-effector pose,
so a correct validation reports no errors. Each validation runs in a fresh interpreter
(``torch.set_num_threads(--threads)``); its peak RSS comes from ``os.wait4`` and its time from
the validation report.

Figures:

* (a) ``--episodes`` episodes of ``--episode-s`` seconds: peak RSS (target <= 1 GB) and time;
  baseline: the same validation of 10 episodes (RSS ratio).
* (b) one episode of ``--long-min`` minutes: peak RSS and time; baseline: one episode of
  ``--short-min`` minutes (RSS ratio; 1.0 means memory does not grow with length). The long
  dataset is then damaged near its end (a gap in the last row group, a joint past its limit,
  an end-effector pose 5 mm off) and must be reported with the right rows: the stream is read
  to its end, not sampled.

* (c) ``--diagnose``: two ``robogs diagnose`` processes at once on the same 2 cores (two copies
  of a 6-push hidden-effect scenario), each against its solo time on the same cores. Cases:
  the CLI's default threads (``--threads`` unset: the cores this process may use, passive
  OpenMP wait), ``--threads 1`` each, and "without the setting": the same diagnosis through
  the Python API in an interpreter with no thread variables (library defaults: OpenBLAS and
  OpenMP pools of every core, spinning waits), which is what the CLI did before ``--threads``.

Usage: ``nice -n 10 .venv/bin/python bench/load.py [--episodes 1000] [--long-min 30] [--threads 1] [--append]``;
``.venv/bin/python bench/load.py --diagnose [--append]``
"""

from __future__ import annotations

import argparse
import datetime as _dt
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robogs.synth.bulk import JOINTS, LINKS_M, write_bulk_dataset  # noqa: E402

_CHILD = """
import json, sys, time, torch
torch.set_num_threads(int(sys.argv[2]))
from robogs.format.validate import validate
t = time.perf_counter()
r = validate(sys.argv[1])
print(json.dumps({"seconds": time.perf_counter() - t, "counts": r.counts(),
                  "findings": [f.to_dict() for f in r.findings]}))
"""


def measure(root: Path, threads: int, env: dict[str, str] | None = None) -> dict:
    """Validate ``root`` in a fresh interpreter; returns seconds, peak RSS (MB) and findings."""
    proc = subprocess.Popen(
        [sys.executable, "-W", "ignore", "-c", _CHILD, str(root), str(threads)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, **(env or {})},
    )
    out = proc.stdout.read()  # type: ignore[union-attr]
    err = proc.stderr.read()  # type: ignore[union-attr]
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"validation of {root} failed:\n{err.decode()[-3000:]}")
    doc = json.loads(out)
    doc["rss_mb"] = usage.ru_maxrss / 1024.0
    return doc


def _rehash(root: Path, rel: str) -> None:
    man = json.loads((root / "manifest.json").read_text())
    p = root / rel
    man["files"][rel] = {
        "sha256": hashlib.sha256(p.read_bytes()).hexdigest(),
        "size": p.stat().st_size,
        "rows": pq.ParquetFile(p).metadata.num_rows,
    }
    (root / "manifest.json").write_text(json.dumps(man, indent=1))


def damage_near_end(root: Path) -> dict[str, int]:
    """Put three defects into the last 5 % of episode ``ep000``; returns their rows.

    A 10-period gap (every later stamp moves), ``joint2`` at 3.3 rad (limit 3.1) for one
    sample, and ``tool0`` 5 mm off along x for one sample.
    """
    rel_js, rel_ee = "episodes/ep000/joint_states.parquet", "episodes/ep000/ee_poses.parquet"
    js = pq.read_table(root / rel_js)
    n = js.num_rows
    gap_row, limit_row, ee_row = n - n // 40, n - n // 30, n - n // 25
    t = js.column("t_ns").to_numpy().copy()
    period = int(t[1] - t[0])
    t[gap_row + 1 :] += 9 * period
    q = js.column("position.joint2").to_numpy().copy()
    q[limit_row] = 3.3
    js = js.set_column(0, "t_ns", pa.array(t))
    js = js.set_column(js.schema.get_field_index("position.joint2"), "position.joint2", pa.array(q))
    pq.write_table(js, root / rel_js, compression="zstd", row_group_size=1 << 16)
    ee = pq.read_table(root / rel_ee)
    cols = {c: ee.column(c).to_numpy().copy() for c in ("x", "y", "qw", "qz")}
    qr = np.array([js.column(f"position.{j}")[limit_row].as_py() for j in JOINTS])
    cum = np.cumsum(qr)  # the recorded pose follows the joint past its limit (closed form)
    cols["x"][limit_row] = sum(L * np.cos(cum[i]) for i, L in enumerate(LINKS_M))
    cols["y"][limit_row] = sum(L * np.sin(cum[i]) for i, L in enumerate(LINKS_M))
    cols["qw"][limit_row], cols["qz"][limit_row] = np.cos(cum[2] / 2), np.sin(cum[2] / 2)
    cols["x"][ee_row] += 0.005
    ee = ee.set_column(0, "t_ns", pa.array(t))
    for c, v in cols.items():
        ee = ee.set_column(ee.schema.get_field_index(c), c, pa.array(v))
    pq.write_table(ee, root / rel_ee, compression="zstd", row_group_size=1 << 16)
    for rel in (rel_js, rel_ee):
        _rehash(root, rel)
    return {"T003": gap_row, "G007": limit_row, "G008": ee_row}


_THREAD_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMBA_NUM_THREADS",
    "OMP_WAIT_POLICY",
)
_CLI = "import sys; from robogs.cli.main import main; sys.exit(main(sys.argv[1:]))"
_API = "import sys; from robogs.physics.api import diagnose; diagnose(sys.argv[1], mask_frames=0)"


def _diagnose_cmds(root: Path, case: str) -> list[str]:
    if case == "without":
        return [sys.executable, "-W", "ignore", "-c", _API, str(root)]
    extra = ["--threads", "1"] if case == "threads1" else []
    return [sys.executable, "-W", "ignore", "-c", _CLI, *extra, "diagnose", str(root)]


def timed_together(cmds: list[list[str]], cores: set[int]) -> list[float]:
    """Start ``cmds`` at once pinned to ``cores``, with no thread variables set; wall [s] each."""
    env = {k: v for k, v in os.environ.items() if k not in _THREAD_VARS}
    t0 = time.perf_counter()
    procs = [
        subprocess.Popen(
            c,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            preexec_fn=lambda: os.sched_setaffinity(0, cores),
        )
        for c in cmds
    ]
    walls = [0.0] * len(procs)
    left = set(range(len(procs)))
    while left:
        for i in list(left):
            if procs[i].poll() is not None:
                walls[i] = time.perf_counter() - t0
                left.discard(i)
        time.sleep(0.05)
    for p, c in zip(procs, cmds, strict=True):
        if p.returncode != 0:
            raise SystemExit(f"{c} failed:\n{p.stderr.read().decode()[-2000:]}")  # type: ignore[union-attr]
    return walls


def diagnose_figure(say) -> None:
    """(c): solo and paired diagnoses on the same 2 cores, per thread setting."""
    from robogs.synth.scenarios import make_scenario, write_scenario

    cores = set(sorted(os.sched_getaffinity(0))[:2])
    rec = make_scenario(
        "table_tilt", seed=0, noise="nominal", kinds=("push",), n_speeds=2, n_dirs=3, check=False
    )
    with tempfile.TemporaryDirectory(prefix="robogs-load-") as tmp:
        roots = [Path(tmp) / "a", Path(tmp) / "b"]
        for r in roots:
            write_scenario(rec, r)
        for case, what in (
            ("default", "robogs diagnose (default --threads: 2, passive OpenMP wait)"),
            ("threads1", "robogs diagnose --threads 1"),
            ("without", "without the setting (API, library-default pools)"),
        ):
            (solo,) = timed_together([_diagnose_cmds(roots[0], case)], cores)
            pair = timed_together([_diagnose_cmds(r, case) for r in roots], cores)
            say(
                f"(c) {what} on cores {sorted(cores)}: solo {solo:.1f} s; two at once "
                f"{pair[0]:.1f} s and {pair[1]:.1f} s = {pair[0] / solo:.2f}x and "
                f"{pair[1] / solo:.2f}x solo (target <= 2.5x)"
            )


def _machine(threads: int) -> str:
    import torch

    load = os.getloadavg()[0]
    return (
        f"{platform.machine()} {platform.system()}, cpu_count={os.cpu_count()}, load average "
        f"{load:.1f}, python {platform.python_version()}, pyarrow {pa.__version__}, torch "
        f"{torch.__version__}, torch threads={threads} (validator process), arrow pool "
        f"{os.environ.get('ARROW_DEFAULT_MEMORY_POOL', pa.default_memory_pool().backend_name)}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--episode-s", type=float, default=2.0, help="length of each small episode")
    ap.add_argument("--long-min", type=float, default=30.0)
    ap.add_argument("--short-min", type=float, default=3.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--skip-many", action="store_true", help="only the long-episode figure")
    ap.add_argument("--append", action="store_true", help="append to bench/RESULTS.md")
    ap.add_argument(
        "--diagnose", action="store_true", help="only figure (c): two diagnoses at once"
    )
    args = ap.parse_args()
    lines = [f"machine: {_machine(args.threads)}"]

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    if args.diagnose:
        lines[0] = lines[0].split(", torch threads=")[0] + ", threads as each case says"
        diagnose_figure(say)
        if args.append:
            _append(
                "load — two `robogs diagnose` at once on 2 cores, with and without the thread "
                "setting",
                ".venv/bin/python bench/load.py --diagnose",
                lines,
            )
        return 0

    with tempfile.TemporaryDirectory(prefix="robogs-load-") as tmp:
        tmp = Path(tmp)
        if not args.skip_many:
            for n in (10, args.episodes):
                t0 = time.perf_counter()
                write_bulk_dataset(tmp / f"many{n}", n_episodes=n, duration_s=args.episode_s)
                made = time.perf_counter() - t0
                m = measure(tmp / f"many{n}", args.threads)
                say(
                    f"(a) {n} episodes x {args.episode_s:g} s ({n * 2} tables, written in "
                    f"{made:.1f} s): validate {m['seconds']:.1f} s, peak RSS {m['rss_mb']:.0f} MB, "
                    f"findings {m['counts']}"
                )
                if n == 10:
                    base = m["rss_mb"]
            say(
                f"(a) RSS {args.episodes} episodes / 10 episodes = {m['rss_mb'] / base:.2f}x; "
                f"target <= 1024 MB: {'met' if m['rss_mb'] <= 1024 else 'NOT met'}"
            )
        rss = {}
        for minutes in (args.short_min, args.long_min):
            root = tmp / f"long{minutes:g}"
            t0 = time.perf_counter()
            write_bulk_dataset(root, n_episodes=1, duration_s=60.0 * minutes)
            made = time.perf_counter() - t0
            rows = int(round(60.0 * minutes * 500))
            m = measure(root, args.threads)
            rss[minutes] = m["rss_mb"]
            say(
                f"(b) 1 episode of {minutes:g} min ({rows} rows per table, "
                f"{sum(p.stat().st_size for p in root.rglob('*')) / 2**20:.0f} MiB, written in "
                f"{made:.1f} s): validate {m['seconds']:.1f} s, peak RSS {m['rss_mb']:.0f} MB, "
                f"findings {m['counts']}"
            )
        say(
            f"(b) RSS {args.long_min:g} min / {args.short_min:g} min = "
            f"{rss[args.long_min] / rss[args.short_min]:.3f}x (length ratio "
            f"{args.long_min / args.short_min:g}x)"
        )
        jem = {
            minutes: measure(
                tmp / f"long{minutes:g}",
                args.threads,
                env={"ARROW_DEFAULT_MEMORY_POOL": "jemalloc"},
            )["rss_mb"]
            for minutes in (args.short_min, args.long_min)
        }
        say(
            f"(b) with ARROW_DEFAULT_MEMORY_POOL=jemalloc: peak RSS {jem[args.short_min]:.0f} MB "
            f"({args.short_min:g} min), {jem[args.long_min]:.0f} MB ({args.long_min:g} min), "
            f"ratio {jem[args.long_min] / jem[args.short_min]:.3f}x"
        )
        long_root = tmp / f"long{args.long_min:g}"
        rows = damage_near_end(long_root)
        m = measure(long_root, args.threads)
        found = {
            code: sorted(f["location"].get("where", "") for f in m["findings"] if f["code"] == code)
            for code in rows
        }
        ok = all(f"row {rows[c]}" in found[c] for c in rows)
        say(
            f"(b) damaged near the end (rows {rows}): reported {found} -> "
            f"{'all found' if ok else 'MISSED'}; validate {m['seconds']:.1f} s, peak RSS "
            f"{m['rss_mb']:.0f} MB"
        )
    if args.append:
        cmd = " ".join(["nice -n 10 .venv/bin/python bench/load.py", *sys.argv[1:]])
        _append(
            "load — many episodes and a long episode, validated by streaming",
            cmd.replace(" --append", ""),
            lines,
        )
    return 0 if ok else 1


def _append(title: str, cmd: str, lines: list[str]) -> None:
    date = _dt.date.today().isoformat()
    body = "\n".join(lines)
    with open(Path(__file__).with_name("RESULTS.md"), "a", encoding="utf-8") as fh:
        fh.write(f"\n## {title} ({date})\n\nCommand: `{cmd}`\n\n```\n{body}\n```\n")


if __name__ == "__main__":
    sys.exit(main())

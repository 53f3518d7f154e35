"""Validation speed: the synthetic scenes (small, medium, large) and a 10-minute episode.

**Scenes** (default): for each ``--sizes`` entry, ``robogs synth OUT --size SIZE`` in a temp
folder, then ``robogs-validate OUT --json`` as a child process (the user's command: imports,
torch, every check, the binding re-render within its default time budget), timed for wall
time, child CPU time and peak RSS, against the in-run baseline: a plain pyarrow
``read_table`` of every parquet table of the same dataset (and the manifest). ``--full-sizes``
also times ``--full`` (every frame re-rendered) for those sizes. The machine's load average
is recorded before and after each run: the bench machine may be shared.

**Long episode** (``--long-episode``): builds, in a temp folder outside the repository, a
dataset with one 10-minute episode: joint states at 500 Hz (6 joints, positions and velocities), a 30 fps
frame index, 640x480 panoptic label images (a pool of simple moving-rectangle
images, repeated), 2D boxes derived from them, segments and a 6-joint URDF. Then
it times, in this process after a warm-up import:

* ``validate(quick=True)`` (target <= 3 s) against a baseline that reads the
  manifest and every parquet footer with plain pyarrow;
* ``validate()`` (target <= 30 s) against a baseline that reads every parquet
  file with ``pyarrow.parquet.read_table`` (bodies, no PNG decoding).

Usage::

    PYTHONPATH=. .venv/bin/python -W ignore bench/validate.py --sizes small,medium [--full-sizes small] [--threads 2] [--append]
    PYTHONPATH=. .venv/bin/python -W ignore bench/validate.py --long-episode [--minutes 10] [--threads 2] [--append]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

T0 = 1_700_000_000_000_000_000
W, H = 640, 480
JOINTS = [f"j{i}" for i in range(1, 7)]


def _urdf() -> str:
    links = [
        '<link name="base"><inertial><mass value="2"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" '
        'iyz="0" izz="0.01"/></inertial><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>'
    ]
    joints = []
    parent = "base"
    for k, j in enumerate(JOINTS, 1):
        links.append(
            f'<link name="l{k}"><inertial><origin xyz="0.05 0 0"/><mass value="1"/><inertia ixx="0.001" '
            'ixy="0" ixz="0" iyy="0.004" iyz="0" izz="0.004"/></inertial><collision><origin xyz="0.05 0 0"/>'
            '<geometry><box size="0.1 0.03 0.03"/></geometry></collision></link>'
        )
        axis = "0 0 1" if k % 2 else "0 1 0"
        joints.append(
            f'<joint name="{j}" type="revolute"><parent link="{parent}"/><child link="l{k}"/>'
            f'<origin xyz="0.1 0 0"/><axis xyz="{axis}"/><limit lower="-3" upper="3" effort="10" '
            'velocity="3"/></joint>'
        )
        parent = f"l{k}"
    return '<?xml version="1.0"?>\n<robot name="bench6">' + "".join(links + joints) + "</robot>\n"


def _label_pool(n: int) -> tuple[list[bytes], list[list[tuple[int, int, int, int, int]]]]:
    """``n`` label images (PNG) of rectangles and their exact boxes (label, x0, y0, x1, y1)."""
    from robogs.format.images import encode_label_png

    blobs, boxes = [], []
    for i in range(n):
        img = np.zeros((H, W), np.uint16)
        rects = []
        for label, (x, y, w, h) in (
            (200, (0, 300, W, 180)),
            (1, (100 + 5 * i, 120, 80, 200)),
            (2, (180 + 5 * i, 100, 120, 40)),
            (100, (400 - 3 * i, 260, 60, 50)),
        ):
            img[y : y + h, x : x + w] = label
        for label in (200, 1, 2, 100):
            ys, xs = np.nonzero(img == label)
            rects.append(
                (label, int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
            )
        blobs.append(encode_label_png(img))
        boxes.append(rects)
    return blobs, boxes


def build(root: Path, minutes: float) -> Path:
    """Write the benchmark dataset to ``root``."""
    import pyarrow as pa

    from robogs.format import Dataset

    dur_ns = int(minutes * 60e9)
    rng = np.random.default_rng(0)
    tj = (
        T0
        + np.arange(0, dur_ns + 1, 2_000_000, dtype=np.int64)
        + rng.integers(-20_000, 20_000, dur_ns // 2_000_000 + 1)
    )
    tj[0], tj[-1] = T0, T0 + dur_ns
    s = (tj - T0) / 1e9
    cols = {"t_ns": tj}
    for k, j in enumerate(JOINTS):
        cols[f"position.{j}"] = 1.2 * np.sin(2 * np.pi * (0.05 + 0.01 * k) * s + k)
        cols[f"velocity.{j}"] = np.gradient(cols[f"position.{j}"], s)
    tc = T0 + np.rint(np.arange(0, minutes * 60 * 30 + 1) * (1e9 / 30)).astype(np.int64)
    n = tc.size
    blobs, boxes = _label_pool(30)
    ep = "episodes/ep000"
    with Dataset.create(root) as w:
        w.write_text("robot/robot.urdf", _urdf())
        w.set_robot("robot/robot.urdf", base_link="base")
        w.write_table(f"{ep}/joint_states.parquet", pa.table(cols), kind="joint_states")
        w.write_table(
            f"{ep}/cameras/cam0/frames.parquet",
            pa.table({"t_ns": tc, "frame_index": np.arange(n, dtype=np.int64)}),
            kind="camera_frames",
        )
        pool = np.arange(n) % len(blobs)
        # labels are written in chunks so the builder never holds 18000 images either
        import pyarrow.parquet as pq

        path = w.path(f"{ep}/cameras/cam0/labels.parquet")
        schema = pa.schema([("frame_index", pa.int64()), ("png", pa.binary())])
        with pq.ParquetWriter(path, schema, compression="zstd") as pw:
            for s0 in range(0, n, 2000):
                idx = np.arange(s0, min(n, s0 + 2000))
                pw.write_table(
                    pa.table(
                        {"frame_index": idx, "png": [blobs[p] for p in pool[idx]]}, schema=schema
                    )
                )
        rows = [(int(tc[i]), i, *b) for i in range(n) for b in boxes[pool[i]]]
        arr = np.array(rows, dtype=np.int64)
        w.write_table(
            f"{ep}/boxes2d.parquet",
            pa.table(
                {
                    "t_ns": arr[:, 0],
                    "camera": ["cam0"] * len(rows),
                    "frame_index": arr[:, 1],
                    "label_id": arr[:, 2].astype(np.int32),
                    **{
                        c: arr[:, 3 + k].astype(float)
                        for k, c in enumerate(("x_min", "y_min", "x_max", "y_max"))
                    },
                }
            ),
            kind="boxes2d",
        )
        w.write_table(
            f"{ep}/segments.parquet",
            pa.table(
                {
                    "label_id": pa.array([1, 2, 100, 200], pa.int32()),
                    "category": ["robot", "robot", "box", "table"],
                    "instance": pa.array([1, 2, 1, 1], pa.int32()),
                    "kind": ["robot_link", "robot_link", "object", "background"],
                    "target": ["l1", "l2", "box", "table"],
                }
            ),
            kind="segments",
        )
        from robogs.format.cameras import CameraModel

        w.set_camera(CameraModel("cam0", W, H, 500.0, 500.0, W / 2, H / 2, T_world_cam=np.eye(4)))
        w.set_asset("box", kind="object")
        w.set_asset("table", kind="table")
        w.add_episode(
            "ep000",
            start_ns=T0,
            end_ns=T0 + dur_ns,
            streams={
                "joint_states": {
                    "kind": "joint_states",
                    "path": f"{ep}/joint_states.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                    "nominal_rate_hz": 500.0,
                },
                "boxes2d": {
                    "kind": "boxes2d",
                    "path": f"{ep}/boxes2d.parquet",
                    "stamp_source": "derived",
                    "offset_ns": 0,
                    "nominal_rate_hz": None,
                },
                "segments": {
                    "kind": "segments",
                    "path": f"{ep}/segments.parquet",
                    "stamp_source": "none",
                    "offset_ns": 0,
                },
                "camera/cam0": {
                    "kind": "camera",
                    "camera": "cam0",
                    "frames": f"{ep}/cameras/cam0/frames.parquet",
                    "labels": f"{ep}/cameras/cam0/labels.parquet",
                    "stamp_source": "synthetic",
                    "offset_ns": 0,
                    "nominal_rate_hz": 30.0,
                },
            },
        )
        w.commit()
    return root


def _baseline_quick(root: Path) -> float:
    import pyarrow.parquet as pq

    t = time.perf_counter()
    json.loads((root / "manifest.json").read_text())
    for p in root.rglob("*.parquet"):
        _ = pq.ParquetFile(p).metadata.num_rows
    return time.perf_counter() - t


def _baseline_full(root: Path) -> float:
    import pyarrow.parquet as pq

    t = time.perf_counter()
    json.loads((root / "manifest.json").read_text())
    for p in root.rglob("*.parquet"):
        pq.read_table(p)
    return time.perf_counter() - t


def _decode_floor(root: Path, sample: int = 1000) -> float:
    """OpenCV PNG decode time of every label image (1 thread), extrapolated from a sample."""
    import cv2
    import pyarrow.parquet as pq

    path = next(root.rglob("labels.parquet"))
    pf = pq.ParquetFile(path)
    blobs = next(pf.iter_batches(batch_size=sample, columns=["png"])).column(0).to_pylist()
    t = time.perf_counter()
    for b in blobs:
        cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED)
    return (time.perf_counter() - t) / len(blobs) * pf.metadata.num_rows


REPO = Path(__file__).resolve().parents[1]
#: what ``robogs synth --size`` makes (its help text)
SIZES = {"small": "4 s 160x120", "medium": "20 s 320x240", "large": "60 s 640x480"}


def _child(cmd: list[str]) -> tuple[float, float, int, int, str]:
    """Run ``cmd``: wall s, its own CPU s (user + sys), peak RSS (kB), exit code, stderr tail.

    ``os.wait4`` gives the resource usage of this one child (not of every child so far).
    """
    with tempfile.TemporaryFile() as err:
        t = time.perf_counter()
        proc = subprocess.Popen(
            cmd,
            stdout=subprocess.DEVNULL,
            stderr=err,
            env={**os.environ, "PYTHONPATH": str(REPO), "PYTHONWARNINGS": "ignore"},
            cwd=REPO,
        )
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        proc.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        tail = err.read().decode("utf-8", "replace").strip()[-300:]
    return wall, usage.ru_utime + usage.ru_stime, int(usage.ru_maxrss), proc.returncode, tail


def _robogs(*args: str) -> list[str]:
    return [
        sys.executable,
        "-c",
        "import sys; from robogs.cli.main import main; sys.exit(main())",
        *args,
    ]


def _camera_frames(root: Path) -> str:
    m = json.loads((root / "manifest.json").read_text())
    out = []
    for ep in m["episodes"]:
        for st in ep["streams"].values():
            if st.get("kind") == "camera":
                import pyarrow.parquet as pq

                out.append(str(pq.read_metadata(root / st["frames"]).num_rows))
    return "+".join(out) or "0"


def bench_scenes(args: argparse.Namespace) -> list[str]:
    """Synthesise and validate each size; one line per run."""
    sizes = [s.strip() for s in args.sizes.split(",") if s.strip()]
    full = {s.strip() for s in args.full_sizes.split(",") if s.strip()}
    for s in [*sizes, *full]:
        if s not in SIZES:
            raise SystemExit(f"unknown size {s!r}; choose from {', '.join(SIZES)}")
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        cores = os.cpu_count() or 1
    lines = [
        f"machine: {platform.machine()} {platform.processor() or ''}".rstrip()
        + f", cpu_count={os.cpu_count()}, usable cores={cores}, python {platform.python_version()}; "
        f"robogs-validate --threads {args.threads} (torch, OpenMP, BLAS, label decoder)"
    ]
    tmp = Path(tempfile.mkdtemp(prefix="robogs-bench-validate-"))
    try:
        for size in sizes:
            root = tmp / size
            wall, _cpu, _rss, rc, err = _child(
                _robogs(
                    "--threads", str(args.threads), "synth", str(root), "--size", size, "--quiet"
                )
            )
            if rc != 0:
                lines.append(f"{size}: synth failed ({rc}): {err}")
                continue
            mb = sum(p.stat().st_size for p in root.rglob("*") if p.is_file()) / 1e6
            lines.append(
                f"{size} ({SIZES[size]}, {_camera_frames(root)} camera frames, {mb:.1f} MB): "
                f"synthesised in {wall:.1f} s"
            )
            _baseline_full(root)  # warm the page cache for both sides
            base = min(_baseline_full(root) for _ in range(3))
            modes = [("default", [])] + ([("--full", ["--full"])] if size in full else [])
            for label, extra in modes:
                load0 = os.getloadavg()[0]
                out = tmp / f"{size}{label.strip('-')}.json"
                cmd = _robogs(
                    "--threads",
                    str(args.threads),
                    "validate",
                    str(root),
                    "--no-progress",
                    "--json-out",
                    str(out),
                    *extra,
                )
                wall, cpu, rss, rc, err = _child(cmd)
                load1 = os.getloadavg()[0]
                if rc not in (0, 1) or not out.exists():
                    lines.append(f"  {label}: validate failed ({rc}): {err}")
                    continue
                summary = json.loads(out.read_text())["summary"]
                counts = summary["counts"]
                lines.append(
                    f"  validate {label}: {wall:.2f} s wall, {cpu:.2f} s CPU, peak RSS "
                    f"{rss / 1024:.0f} MB; in-run baseline pyarrow read_table of "
                    f"every table {base * 1e3:.1f} ms; ratio {wall / base:.0f}x; "
                    f"{summary['checks_run']} checks, {counts['error']} errors, {counts['warning']} warnings; "
                    f"load average {load0:.1f} -> {load1:.1f}"
                )
                for note in summary.get("notes", []):
                    lines.append(f"    note: {note}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="small,medium,large", help="synthetic scenes to validate")
    ap.add_argument("--full-sizes", default="", help="sizes also validated with --full")
    ap.add_argument("--long-episode", action="store_true", help="the 10-minute episode bench")
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--append", action="store_true", help="append the result to bench/RESULTS.md")
    args = ap.parse_args(argv)
    if not args.long_episode:
        lines = bench_scenes(args)
        print("\n".join(lines))
        if args.append:
            _append(
                "validate — robogs-validate on the synthetic scenes, default time budget",
                argv,
                lines,
            )
        return 0
    return long_episode(args, argv)


def _append(title: str, argv: list[str] | None, lines: list[str]) -> None:
    import datetime

    cmd = "PYTHONPATH=. .venv/bin/python -W ignore bench/validate.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    text = (
        f"\n## {title} ({datetime.date.today().isoformat()})\n\n"
        f"Command: `{cmd.strip()}`\n\n```\n" + "\n".join(lines) + "\n```\n"
    )
    with open(Path(__file__).resolve().parent / "RESULTS.md", "a", encoding="utf-8") as fh:
        fh.write(text)


def long_episode(args: argparse.Namespace, argv: list[str] | None) -> int:
    """The 10-minute episode: ``--quick`` and full validation (no splats: no re-render)."""
    t = time.perf_counter()
    import torch

    from robogs.format.checks import available_checks
    from robogs.format.validate import validate

    available_checks()
    import_s = time.perf_counter() - t
    torch.set_num_threads(args.threads)

    tmp = Path(tempfile.mkdtemp(prefix="robogs-bench-validate-"))
    try:
        t = time.perf_counter()
        root = build(tmp / "ds", args.minutes)
        build_s = time.perf_counter() - t
        size_mb = sum(p.stat().st_size for p in root.rglob("*") if p.is_file()) / 1e6
        base_q = min(_baseline_quick(root) for _ in range(3))
        t = time.perf_counter()
        rq = validate(root, quick=True, label_threads=args.threads)
        quick_s = time.perf_counter() - t
        cli = [
            sys.executable,
            "-W",
            "ignore",
            "-c",
            "import sys; from robogs.cli.main import validate_main; "
            "sys.exit(validate_main(sys.argv[1:]))",
            str(root),
            "--quick",
            "--json",
        ]
        t = time.perf_counter()
        subprocess.run(
            cli,
            check=True,
            capture_output=True,
            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])},
        )
        quick_cli_s = time.perf_counter() - t
        base_f = _baseline_full(root)
        decode_s = _decode_floor(root)
        load_before = os.getloadavg()[0]
        t, c = time.perf_counter(), time.process_time()
        rf = validate(root, label_threads=args.threads)
        full_s, full_cpu = time.perf_counter() - t, time.process_time() - c
        slowest = sorted(rf.runs, key=lambda r: -r.seconds)[:5]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    lines = [
        f"machine: {platform.machine()} {platform.processor() or ''}".rstrip()
        + f", cpu_count={os.cpu_count()}, "
        f"torch {torch.__version__}, torch threads={torch.get_num_threads()}, label decoder threads={args.threads}",
        f"dataset: {args.minutes:g} min episode, 500 Hz joints ({len(JOINTS)} joints), 30 fps frame index, "
        f"{W}x{H} labels, {size_mb:.0f} MB (built in {build_s:.1f} s); import {import_s:.2f} s (not timed below)",
        f"quick: {quick_s:.3f} s (target <= 3 s), {len(rq.runs)} checks, {len(rq.findings)} findings; "
        f"baseline pyarrow footers {base_q:.3f} s; ratio {quick_s / base_q:.1f}x; "
        f"whole CLI process (robogs-validate --quick --json, imports included) {quick_cli_s:.2f} s",
        f"full:  {full_s:.2f} s (target <= 30 s), {len(rf.runs)} checks, {len(rf.findings)} findings; "
        f"baseline pyarrow read_table of every table {base_f:.2f} s; ratio {full_s / base_f:.1f}x; "
        f"process CPU {full_cpu:.1f} s (load average {load_before:.1f} on {os.cpu_count()} cores when started)",
        f"reference: OpenCV decode of every label PNG, 1 thread: {decode_s:.1f} s (the label pass decodes "
        "the writer's Sub-filtered PNGs without unfiltering, on the decoder threads)",
        "slowest checks (full): " + ", ".join(f"{r.code} {r.seconds:.2f} s" for r in slowest),
    ]
    for f in rf.findings[:5]:
        lines.append(f"finding: {f.code} {f.severity} {f.message}")
    print("\n".join(lines))
    if args.append:
        _append(
            f"validate — robogs-validate speed on a {args.minutes:g}-minute episode", argv, lines
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

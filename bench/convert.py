"""Ingest throughput: synthetic ROS 2 MCAP (joints 500 Hz + 30 fps 640x480 JPEG) -> dataset.

Prints, for a file of about ``--size-mb`` MB written in a temp folder:

* bare iteration of every message with ``mcap`` (no decoding): the baseline;
* ingest with ``video=False`` (all messages decoded, tables and frame indexes written, images not
  decoded): MB/s and the ratio baseline_time / ingest_time (target >= 0.5);
* full ingest (JPEG decode + mp4 encode): MB/s, and the video share reported separately;
* peak RSS of each run (``resource.getrusage`` in the child process that ran it; target <= 1 GB).

Usage: ``PYTHONPATH=. .venv/bin/python bench/convert.py [--size-mb 1000] [--append]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

T0 = 1_700_000_000_000_000_000


def _jpeg_pool(n: int, rng: np.random.Generator) -> list[bytes]:
    import cv2

    yy, xx = np.mgrid[0:480, 0:640]
    pool = []
    for i in range(n):
        base = np.sin(xx / (9 + i) + i) * 60 + np.cos(yy / (13 + i)) * 60 + 128
        img = np.stack([base, np.roll(base, 7 * i, 1), np.roll(base, 11 * i, 0)], -1)
        img = np.clip(img + rng.normal(0, 12, img.shape), 0, 255).astype(np.uint8)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
        assert ok
        pool.append(buf.tobytes())
    return pool


def generate(path: Path, size_mb: float) -> dict[str, float]:
    """Write the synthetic MCAP; returns facts (seconds of recording, messages)."""
    from mcap_ros2.writer import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    rng = np.random.default_rng(0)
    pool = _jpeg_pool(48, rng)
    frame_bytes = float(np.mean([len(b) for b in pool]))
    seconds = size_mb * 1e6 / (30 * (frame_bytes + 60) + 500 * 150)
    joints = [f"joint{i}" for i in range(1, 7)]
    n_msgs = 0
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=4 << 20)
        s_js = w.register_msgdef(
            "sensor_msgs/msg/JointState",
            ts.generate_msgdef("sensor_msgs/msg/JointState", ros_version=2)[0],
        )
        s_im = w.register_msgdef(
            "sensor_msgs/msg/CompressedImage",
            ts.generate_msgdef("sensor_msgs/msg/CompressedImage", ros_version=2)[0],
        )
        n_j, n_c = int(seconds * 500), int(seconds * 30)
        j = c = 0
        while j < n_j or c < n_c:
            tj = T0 + j * 2_000_000
            tc = T0 + 1_000_000 + c * 33_333_333
            if j < n_j and (c >= n_c or tj <= tc):
                q = np.sin(j * 0.002 + np.arange(6)).tolist()
                msg = {
                    "header": {
                        "stamp": {"sec": tj // 10**9, "nanosec": tj % 10**9},
                        "frame_id": "",
                    },
                    "name": joints,
                    "position": q,
                    "velocity": q,
                    "effort": [],
                }
                w.write_message("/joint_states", s_js, msg, log_time=tj + 300_000, publish_time=tj)
                j += 1
            else:
                msg = {
                    "header": {
                        "stamp": {"sec": tc // 10**9, "nanosec": tc % 10**9},
                        "frame_id": "cam0_optical",
                    },
                    "format": "jpeg",
                    "data": pool[c % len(pool)],
                }
                w.write_message(
                    "/camera/cam0/image_raw/compressed",
                    s_im,
                    msg,
                    log_time=tc + 5_000_000,
                    publish_time=tc,
                )
                c += 1
            n_msgs += 1
        w.finish()
    return {
        "seconds": seconds,
        "messages": n_msgs,
        "frames": n_c,
        "joint_msgs": n_j,
        "jpeg_bytes": frame_bytes,
    }


def _child(mode: str, src: str, out: str) -> None:
    # imports first (the registry loads every converter module): timed separately
    t_imp = time.perf_counter()
    if mode != "bare":
        import robogs.convert.ingest.mcap_source  # noqa: F401
        from robogs.convert.registry import available_converters

        available_converters()
    t_imp = time.perf_counter() - t_imp
    t = time.perf_counter()
    if mode == "bare":
        from mcap.reader import make_reader

        n = 0
        with open(src, "rb") as fh:
            for _ in make_reader(fh).iter_messages():
                n += 1
    else:
        from robogs.convert.ingest import ConvertOptions, convert_path

        convert_path(src, out, options=ConvertOptions(video=(mode == "video")), force=True)
        n = 0
    dt = time.perf_counter() - t
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB
    print(json.dumps({"seconds": dt, "maxrss": rss, "messages": n, "import_s": t_imp}))


def _run(mode: str, src: Path, out: Path) -> dict[str, float]:
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    res = subprocess.run(
        [sys.executable, __file__, "--child", mode, str(src), str(out)],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if res.returncode != 0:
        raise SystemExit(f"{mode} run failed:\n{res.stderr[-3000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--size-mb", type=float, default=1000.0, help="size of the synthetic MCAP (default 1000)"
    )
    ap.add_argument("--append", action="store_true", help="append the result to bench/RESULTS.md")
    ap.add_argument("--child", nargs=3, metavar=("MODE", "SRC", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(*args.child)
        return
    try:
        import torch

        torch.set_num_threads(1)
        threads = f"torch threads={torch.get_num_threads()} (ingest does not use torch)"
    except ImportError:  # pragma: no cover
        threads = "torch not installed (ingest does not use it)"
    tmp = Path(tempfile.mkdtemp(prefix="robogs-bench-convert-"))
    try:
        src = tmp / "synthetic.mcap"
        t = time.perf_counter()
        facts = generate(src, args.size_mb)
        gen_s = time.perf_counter() - t
        mb = src.stat().st_size / 1e6
        bare = _run("bare", src, tmp / "out")
        tables = _run("tables", src, tmp / "out")
        video = _run("video", src, tmp / "out")
        lines = [
            f"machine: {platform.machine()} {platform.processor() or ''}, cpu_count={os.cpu_count()}, "
            f"python {platform.python_version()}, {threads}",
            f"input: {mb:.0f} MB MCAP (zstd chunks), {facts['seconds']:.0f} s recording, {facts['messages']:,} "
            f"messages: {facts['joint_msgs']:,} JointState at 500 Hz + {facts['frames']:,} JPEG 640x480 at 30 fps "
            f"({facts['jpeg_bytes'] / 1e3:.0f} kB each); generated in {gen_s:.0f} s",
            f"baseline, bare mcap iteration: {bare['seconds']:.2f} s ({mb / bare['seconds']:.0f} MB/s), "
            f"peak RSS {bare['maxrss'] / 1e6:.0f} MB",
            f"(ingest imports, not timed: {tables['import_s']:.1f} s)",
            f"ingest, video off (decode all, tables + frame index): {tables['seconds']:.2f} s "
            f"({mb / tables['seconds']:.0f} MB/s), peak RSS {tables['maxrss'] / 1e6:.0f} MB",
            f"ratio baseline/ingest (video off): {bare['seconds'] / tables['seconds']:.2f} (target >= 0.5)",
            f"ingest, full (JPEG decode + mp4v encode): {video['seconds']:.2f} s ({mb / video['seconds']:.0f} MB/s), "
            f"peak RSS {video['maxrss'] / 1e6:.0f} MB (target <= 1000 MB)",
            f"video decode+encode share: {video['seconds'] - tables['seconds']:.2f} s "
            f"({facts['frames'] / max(video['seconds'] - tables['seconds'], 1e-9):.0f} frames/s)",
        ]
        print("\n".join(lines))
        if args.append:
            cmd = "PYTHONPATH=. .venv/bin/python bench/convert.py " + " ".join(sys.argv[1:])
            text = (
                f"\n## convert — MCAP ingest throughput and memory (2026-11-22)\n\nCommand: `{cmd}`\n\n```\n"
                + "\n".join(lines)
                + "\n```\n"
            )
            with open(Path(__file__).with_name("RESULTS.md"), "a", encoding="utf-8") as fh:
                fh.write(text)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()

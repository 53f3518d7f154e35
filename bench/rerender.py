"""Re-render validation speed: the binding checks (B002-B006) on a 60 s episode at 30 fps.

Generates the synthetic push scene with a 60 s (``--duration``), 320x240 preset (1 cm splat spacing, as the
``small`` preset) unless ``--dataset`` names one, then runs the re-render checks with
``stride`` 5 (every 5th frame: 360 of 1800) at ``scale`` 1 (320x240 renders), the time-offset
and camera fit on ``fit_frames`` frames included. Target: <= 60 s on 2 threads.

Baseline: validating every frame (stride 1), extrapolated from the measured per-frame cost of the
pass; with ``--dense-frames N`` also the brute-force ``dense`` oracle backend on N frames (it
holds N_gaussians x pixels values at once: tens of GB at 320x240, so it is off by default).

Usage: ``PYTHONPATH=. .venv/bin/python bench/rerender.py [--threads 2] [--stride 5] [--scale 1.0]
[--dataset PATH] [--device cpu|cuda] [--append]``
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robogs.format.checks import CheckContext, InputReported, get_check  # noqa: E402
from robogs.format.checks.binding import alignment_fit, label_summary  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"
CODES = ("B002", "B003", "B004", "B005", "B006")


def _scene(out: Path, duration_s: float) -> Path:
    from robogs.synth.scene import scene, synthesize

    name = f"bench{duration_s:g}s"
    scene.SIZES.setdefault(name, scene.SizePreset(float(duration_s), 320, 240, 0.010))
    synthesize(out, seed=0, size=name, progress=False)
    return out


def _dense_frame_seconds(ctx: CheckContext, episode: str, stream: str, frames: int) -> float:
    """Seconds per frame of the dense oracle backend on the first strided frames."""
    from robogs.format.checks.binding import _camera_jobs, _frames, _rerenderer

    job = next(j for j in _camera_jobs(ctx) if j.ep.id == episode and j.stream == stream)
    rr, _lut = _rerenderer(ctx, job)
    t, _fi = _frames(ctx, job)
    backend = rr.backend
    rr.backend = "dense"
    try:
        t0 = time.perf_counter()
        for k in range(frames):
            rr.render(int(t[k]))
        return (time.perf_counter() - t0) / frames
    finally:
        rr.backend = backend


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--fit-frames", type=int, default=8)
    ap.add_argument("--dataset", type=Path, help="use this dataset instead of generating one")
    ap.add_argument(
        "--duration", type=float, default=60.0, help="length of the generated episode, s"
    )
    ap.add_argument("--device", default="cpu")
    ap.add_argument(
        "--dense-frames", type=int, default=0, help="frames rendered by the dense baseline"
    )
    ap.add_argument("--append", action="store_true", help=f"append the result to {RESULTS}")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        root = args.dataset or _scene(Path(tmp) / "bench", args.duration)
        gen = time.perf_counter() - t0
        print(f"dataset ready after {gen:.1f} s", flush=True)
        ctx = CheckContext(root)
        ctx.options = {
            "stride": args.stride,
            "scale": args.scale,  # type: ignore[attr-defined]
            "fit_frames": args.fit_frames,
            "device": args.device,
        }
        ep = ctx.episodes[0]
        stream = next(n for n, s in ep.streams.items() if s.get("kind") == "camera")
        n_frames = ctx.table(ep.streams[stream]["frames"], columns=("t_ns",)).num_rows
        times: dict[str, float] = {}
        findings = []
        t_all = time.perf_counter()
        for code in CODES:
            t1 = time.perf_counter()
            try:
                findings += list(get_check(code).run(ctx))
            except InputReported:
                pass
            times[code] = time.perf_counter() - t1
            print(f"{code}: {times[code]:.1f} s", flush=True)
        total = time.perf_counter() - t_all
        n_cmp = len(range(0, n_frames, args.stride))
        dense = (
            _dense_frame_seconds(ctx, ep.id, stream, args.dense_frames)
            if args.dense_frames
            else None
        )
        summary = label_summary(ctx, ep.id, stream)
        fit = alignment_fit(ctx, ep.id, stream)
        cam = ctx.camera(ep.streams[stream]["camera"])

    lines = [
        f"machine: {platform.machine()} {platform.processor() or ''}, cpu_count={os.cpu_count()}, "
        f"torch {torch.__version__}, torch threads={torch.get_num_threads()}, device={args.device}",
        f"dataset: {'given' if args.dataset else 'generated'} ({gen:.1f} s), {n_frames} frames "
        f"{cam.width}x{cam.height}, render {int(round(cam.width * args.scale))}x"
        f"{int(round(cam.height * args.scale))}, stride {args.stride} -> {n_cmp} frames compared",
        f"B002 label pass (render + compare every strided frame): {times['B002']:.1f} s "
        f"({1e3 * times['B002'] / n_cmp:.0f} ms/frame)",
        f"B005 time-offset + camera fit ({args.fit_frames} frames): {times['B005']:.1f} s",
        f"total B002-B006: {total:.1f} s (target <= 60 s)",
        f"baseline stride 1 (every frame): {times['B002'] / n_cmp * n_frames + times['B005']:.0f} s; "
        f"ratio baseline/measured {(times['B002'] / n_cmp * n_frames + times['B005']) / max(total, 1e-9):.1f}x",
        "clean-scene numbers: "
        + ", ".join(
            f"{s.name} IoU {s.iou:.3f} / {s.boundary_px:.2f} px" for s in summary if s.pixels
        )[:400],
    ]
    if dense is not None:
        lines.append(
            f"dense oracle backend: {dense:.2f} s/frame ({dense * n_cmp / max(times['B002'], 1e-9):.1f}x the pass)"
        )
    if fit is not None:
        lines.append(
            f"fit: offset {fit.offset_ms:+.2f} ms, camera {fit.shift_2d_mm:.2f} mm, "
            f"{len([f for f in findings if f.severity != 'info'])} warnings/errors"
        )
    text = "\n".join(lines)
    print(text)
    if args.append:
        cmd = "PYTHONPATH=. .venv/bin/python bench/rerender.py " + " ".join(sys.argv[1:])
        with RESULTS.open("a", encoding="utf-8") as f:
            f.write(
                f"\n\n## rerender — binding re-render validation speed (2026-11-22)\n\nCommand: `{cmd}`\n\n"
                f"```\n{text}\n```\n"
            )
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    raise SystemExit(main())

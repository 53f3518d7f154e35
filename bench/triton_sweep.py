"""Chunk size and warps of the fused ``triton`` render kernels, timed on the GPU (issue 23).

For 3DGS and 2DGS: forward 100k Gaussians at 640x480 for each (K, warps) of the forward kernel,
and forward + backward 20k at 320x240 for each (K, warps) of the backward kernel (forward at the
module default). The in-run baseline is the module default configuration (first row of each
block). Prints a table and writes ``--json``. Scenes are ``bench/render.py``'s.

``--fused-projection`` adds, for each kind, the forward and the forward + backward at the module
defaults with the other projection than the module's default (``triton_raster._FUSED_PROJECTION``:
the fused Triton projection of ``triton_project.py`` or the torch ``project()``), against the
default row of the same run as the baseline.

``--triton-binning`` does the same with ``triton_raster._TRITON_BINNING`` (the Triton kernels of
``triton_binning.py`` or torch's ``bin_tiles``), ``--fused-finish`` with ``_FUSED_FINISH``
(``triton_finish.py`` or ``finish_output``); with several, a last row flips them all together.
``--defaults-only`` skips the chunk and warps rows.

Usage: python bench/triton_sweep.py [--repeats 20] [--json PATH] [--scale 1.0]
       [--fused-projection] [--triton-binning] [--fused-finish] [--defaults-only]
       [--profile]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import render as rb  # noqa: E402  (bench/render.py: scenes and timers)

from robogs.format.render import RenderConfig, render  # noqa: E402
from robogs.format.render import triton_raster as tr  # noqa: E402

FWD = [(32, 8), (16, 8), (32, 4), (32, 16)]
BWD = [(16, 8, False), (32, 8, True), (16, 16, False), (32, 8, False)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--json")
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument(
        "--profile", action="store_true", help="also print the top kernels of one training step"
    )
    ap.add_argument(
        "--fused-projection",
        action="store_true",
        help="also time the other projection (fused Triton or torch; triton_raster._FUSED_PROJECTION)",
    )
    ap.add_argument(
        "--triton-binning",
        action="store_true",
        help="also time the other binning (Triton kernels or torch; triton_raster._TRITON_BINNING)",
    )
    ap.add_argument(
        "--fused-finish",
        action="store_true",
        help="also time the other finish (one Triton kernel or torch ops; triton_raster._FUSED_FINISH)",
    )
    ap.add_argument(
        "--defaults-only",
        action="store_true",
        help="time the module's chunk and warps only (no sweep of them)",
    )
    args = ap.parse_args()
    dev = "cuda" if torch.cuda.is_available() else "cpu"
    # (module flag, label of the flipped setting): each flipped against the default row
    variants = []
    if args.fused_projection:
        flip = "torch projection" if tr._FUSED_PROJECTION else "fused projection"
        variants.append(("_FUSED_PROJECTION", flip))
    if args.triton_binning:
        flip = "torch binning" if tr._TRITON_BINNING else "triton binning"
        variants.append(("_TRITON_BINNING", flip))
    if args.fused_finish:
        flip = "torch finish" if tr._FUSED_FINISH else "fused finish"
        variants.append(("_FUSED_FINISH", flip))
    if len(variants) > 1:  # and all of them flipped together
        variants.append((tuple(a for a, _ in variants), " + ".join(lab for _, lab in variants)))
    fwd_cfgs = FWD[:1] if args.defaults_only else FWD
    bwd_cfgs = BWD[:1] if args.defaults_only else BWD
    print(rb._device_line(dev), f"threads {torch.get_num_threads()}", f"pid {os.getpid()}")
    res: dict[str, float] = {}
    s = args.scale
    for kind in ("3dgs", "2dgs"):
        n, w, h = max(int(100_000 * s), 10), max(int(640 * s), 16), max(int(480 * s), 16)
        g, f = rb.make_scene(n, w, seed=5, kind=kind, device=dev)
        cam = rb.make_camera(w, h, f, dev)
        cfg = RenderConfig(kind=kind, validate=False, tile_size=16)
        base = None
        for k, warps in fwd_cfgs:
            tr._K_FWD, tr._WARPS_FWD = k, warps

            def fwd(g=g, cam=cam, cfg=cfg) -> None:
                with torch.no_grad():
                    render(g, cam, config=cfg, backend="triton")

            lo, med = rb._time_device(fwd, args.repeats, dev)
            base = base or lo
            res[f"{kind} fwd 100k K={k} warps={warps}"] = lo
            print(f"{kind} forward {n} @ {w}x{h} K={k} warps={warps}: {lo * 1e3:.2f} ms "
                  f"(median {med * 1e3:.2f}); {base / lo:.2f}x the default")  # fmt: skip
        tr._K_FWD, tr._WARPS_FWD = FWD[0]
        for attr, label in variants:
            lo, med = _flipped(attr, fwd, args.repeats, dev)
            res[f"{kind} fwd 100k {label}"] = lo
            print(f"{kind} forward {n} @ {w}x{h} {label}: {lo * 1e3:.2f} ms "
                  f"(median {med * 1e3:.2f}); {base / lo:.2f}x the default")  # fmt: skip
        n, w, h = max(int(20_000 * s), 10), max(int(320 * s), 16), max(int(240 * s), 16)
        g, f = rb.make_scene(n, w, seed=6, kind=kind, device=dev)
        cam = rb.make_camera(w, h, f, dev)
        leaves = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh]
        for p in leaves:
            p.requires_grad_(True)
        base = None
        for k, warps, dot in bwd_cfgs:
            tr._K_BWD, tr._WARPS_BWD, tr._BWD_DOT = k, warps, dot

            def step(g=g, cam=cam, cfg=cfg, leaves=leaves) -> None:
                out = render(g, cam, config=cfg, backend="triton")
                (out.rgb.sum() + out.depth_expected.mean()).backward()
                for p in leaves:
                    p.grad = None

            lo, med = rb._time_device(step, args.repeats, dev)
            base = base or lo
            res[f"{kind} fwd+bwd 20k K={k} warps={warps} dot={dot}"] = lo
            print(f"{kind} fwd+bwd {n} @ {w}x{h} K={k} warps={warps} dot={dot}: {lo * 1e3:.2f} ms "
                  f"(median {med * 1e3:.2f}); {base / lo:.2f}x the default")  # fmt: skip
        tr._K_BWD, tr._WARPS_BWD, tr._BWD_DOT = BWD[0]
        for attr, label in variants:
            lo, med = _flipped(attr, step, args.repeats, dev)
            res[f"{kind} fwd+bwd 20k {label}"] = lo
            print(f"{kind} fwd+bwd {n} @ {w}x{h} {label}: {lo * 1e3:.2f} ms "
                  f"(median {med * 1e3:.2f}); {base / lo:.2f}x the default")  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1))
    if args.profile:
        profile_step(dev, args.scale)
        for attr, label in variants:
            print(f"-- the same step with the {label} --")
            _flipped(attr, lambda: profile_step(dev, args.scale), 0, None)


def _flipped(attr, fn, repeats: int, dev: str | None):
    """``fn`` timed (or, with ``dev`` None, run) with the module flag(s) ``attr`` flipped."""
    attrs = (attr,) if isinstance(attr, str) else attr
    before = {a: getattr(tr, a) for a in attrs}
    for a, v in before.items():
        setattr(tr, a, not v)
    try:
        return fn() if dev is None else rb._time_device(fn, repeats, dev)
    finally:
        for a, v in before.items():
            setattr(tr, a, v)


def profile_step(dev: str, scale: float) -> None:
    """torch.profiler's table of one 3DGS forward + backward, 20k at 320x240 (after warm-up):
    where the step's device time goes (projection, sort, the two kernels, autograd glue)."""
    from torch.profiler import ProfilerActivity, profile

    n, w, h = max(int(20_000 * scale), 10), max(int(320 * scale), 16), max(int(240 * scale), 16)
    g, f = rb.make_scene(n, w, seed=6, kind="3dgs", device=dev)
    cam = rb.make_camera(w, h, f, dev)
    cfg = RenderConfig(kind="3dgs", validate=False, tile_size=16)
    leaves = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh]
    for p in leaves:
        p.requires_grad_(True)

    def step() -> None:
        out = render(g, cam, config=cfg, backend="triton")
        (out.rgb.sum() + out.depth_expected.mean()).backward()
        for p in leaves:
            p.grad = None

    for _ in range(3):
        step()
    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if dev == "cuda" else [])
    with profile(activities=acts) as prof:
        for _ in range(5):
            step()
        rb._sync(dev)
    key = "cuda_time_total" if dev == "cuda" else "cpu_time_total"
    print(prof.key_averages().table(sort_by=key, row_limit=25, max_name_column_width=60))


if __name__ == "__main__":
    main()

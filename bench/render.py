"""Speed and memory of the splat rasterizer (robogs.format.render).

Figures (targets from the renderer's design):
- forward render, 100k 3DGS Gaussians at 640x480, 2 threads: target <= 0.6 s;
- forward + backward, 20k Gaussians at 320x240: target <= 0.5 s and <= 1 GB peak memory;
- speed-up of the tiled backend over the dense oracle at 2k Gaussians, 128x96;
- the same on CUDA when a GPU is present;
- frames per second of the forward render, 100k Gaussians at 640x480 (issue 20), threads stated;
- frames per second of a ``robogs render`` frame (``--only fps``): 100k 2DGS surfels with 10 label
  channels (RGB, soft labels, median depth, argmax labels), at 1 and 2 threads in the same run
  (the 1-thread figure is the in-run baseline), wall and process-CPU time, load average stated;
  with ``--dataset DIR`` also ``render_dataset`` end to end (encode and write included) on that
  dataset's first camera (``robogs synth --size large`` has 104k Gaussians at 640x480);
- novel poses (``--only novel``): the binding of ``robogs synth --size small --splat-spacing
  0.007`` (``--spacing``, ``--seed``) rendered at joint configurations never recorded against
  the synthetic scene's independent triangle rasteriser (``tests/render/novel_pose.py``): IoU
  per link (void band excluded, the validator's rule), boundary error (px) and PSNR, at 2x the
  camera resolution (320x240).

Scenes are random but realistic: Gaussians spread through a 1 m cube whose centre is 1.2 m in
front of the camera (f = 0.9 W, so the cube fills most of the frame), with a screen-space 3-sigma
radius log-uniform in 1-20 px, mild anisotropy, random rotations, opacity sigmoid(N(1, 1.5)) and
degree-3 SH.

Memory: the peak resident-set growth of this process during the step (``ru_maxrss`` minus the
RSS before), measured first, before any larger render has raised the high-water mark. It
counts everything the step allocates (autograd's saved tensors included) and is what the OS
must provide.

- ``--only gpu`` (issue 23): forward 100k at 640x480 and forward + backward 20k at 320x240, for
  3DGS and 2DGS, on ``--device`` (cuda) with the ``torch`` and the fused ``triton`` backends, and
  the same on the CPU (``torch``, ``--threads``) in the same run as the baseline; max |d rgb| of
  triton against torch on the device; ``--json PATH`` writes the figures; ``--scale`` shrinks
  counts and images (to try the mode on a CPU under ``TRITON_INTERPRET=1``).

Usage: python bench/render.py [--threads 2] [--repeats 5] [--only all|speed|novel|fps|gpu]
[--dataset DIR] [--configs 8] [--seed 0] [--spacing M] [--no-append] [--device cuda]
[--scale 1.0] [--json PATH]
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from robogs.format.render import (  # noqa: E402
    Camera,
    Gaussians,
    RenderConfig,
    available_backends,
    render,
)
from robogs.format.render.binning import bin_tiles  # noqa: E402
from robogs.format.render.projection import project  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "RESULTS.md"


def make_scene(
    n: int, width: int, seed: int = 0, kind: str = "3dgs", device: str = "cpu"
) -> tuple[Gaussians, float]:
    """N random Gaussians in a 1 m cube centred 1.2 m ahead; returns them and the focal length."""
    f = 0.9 * width
    gen = torch.Generator().manual_seed(seed)
    xyz = torch.rand(n, 3, generator=gen) - 0.5
    xyz[:, 2] += 1.2
    r_px = torch.exp(torch.rand(n, generator=gen) * math.log(20.0))  # 3-sigma radius, px
    sigma_m = r_px / 3.0 * xyz[:, 2] / f
    ns = 3 if kind == "3dgs" else 2
    aniso = torch.exp((torch.rand(n, ns, generator=gen) - 0.5) * 0.8)
    sh = torch.randn(n, 16, 3, generator=gen) * 0.1
    sh[:, 0] = torch.randn(n, 3, generator=gen) * 0.8
    g = Gaussians(
        means=xyz,
        quats=torch.randn(n, 4, generator=gen),
        log_scales=torch.log(sigma_m)[:, None] + torch.log(aniso),
        opacity_logits=torch.randn(n, generator=gen) * 1.5 + 1.0,
        sh=sh,
    )
    return Gaussians(
        **{k: (v.to(device) if v is not None else None) for k, v in vars(g).items()}
    ), f


def make_camera(width: int, height: int, f: float, device: str = "cpu") -> Camera:
    return Camera(
        width=width,
        height=height,
        fx=f,
        fy=f,
        cx=width / 2,
        cy=height / 2,
        T_world_cam=torch.eye(4, device=device),
    )


def _sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def timed(fn, repeats: int, device: str = "cpu") -> tuple[float, float, float]:
    """(min wall s, median wall s, min process-CPU s) over ``repeats`` runs after one warm-up."""
    fn()
    _sync(device)
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        _sync(device)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    walls.sort()
    return walls[0], walls[len(walls) // 2], min(cpus)


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def pair_count(g: Gaussians, cam: Camera, cfg: RenderConfig, tile: int) -> int:
    with torch.no_grad():
        p = project(g, cam, cfg)
        return int(
            bin_tiles(p.bbox, p.depth, p.visible, cam.width, cam.height, tile).gaussian_ids.numel()
        )


def bench_train_step(
    repeats: int, device: str = "cpu", tile: int | None = None
) -> dict[str, float]:
    g, f = make_scene(20_000, 320, seed=1, device=device)
    cam = make_camera(320, 240, f, device)
    params = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh]
    for p in params:
        p.requires_grad_(True)
    cfg = RenderConfig(tile_size=tile)
    target = torch.rand(240, 320, 3, generator=torch.Generator().manual_seed(0)).to(device)
    times = {"fwd": [], "bwd": []}

    def step() -> None:
        _sync(device)
        t0 = time.perf_counter()
        out = render(g, cam, config=cfg)
        loss = (out.rgb - target).abs().mean() + 0.1 * out.depth_expected.mean()
        _sync(device)
        t1 = time.perf_counter()
        loss.backward()
        _sync(device)
        times["fwd"].append(t1 - t0)
        times["bwd"].append(time.perf_counter() - t1)
        for p in params:
            p.grad = None

    rss0 = _rss_mb()
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated()
    wall, med, cpu = timed(step, repeats, device)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024 - rss0
    res = {
        "wall": wall,
        "median": med,
        "cpu": cpu,
        "fwd": min(times["fwd"]),
        "bwd": min(times["bwd"]),
        "peak_mb": peak,
    }
    if device == "cuda":
        res["peak_mb"] = (torch.cuda.max_memory_allocated() - base) / 2**20
    return res


def bench_forward(
    repeats: int, tile: int | None, device: str = "cpu", n: int = 100_000, size=(640, 480)
) -> dict[str, float]:
    g, f = make_scene(n, size[0], seed=0, device=device)
    cam = make_camera(size[0], size[1], f, device)
    cfg = RenderConfig(tile_size=tile)
    with torch.no_grad():
        wall, med, cpu = timed(lambda: render(g, cam, config=cfg), repeats, device)
        out = render(g, cam, config=cfg)
    t = tile or (8 if device == "cpu" else 16)
    return {
        "wall": wall,
        "median": med,
        "cpu": cpu,
        "pairs": pair_count(g, cam, cfg, t) * t * t,
        "coverage": float((out.alpha > 0.5).float().mean()),
    }


def bench_oracle(repeats: int, device: str = "cpu") -> dict[str, float]:
    g, f = make_scene(2_000, 128, seed=2, device=device)
    cam = make_camera(128, 96, f, device)
    with torch.no_grad():
        tiled = timed(lambda: render(g, cam), repeats, device)
        dense = timed(lambda: render(g, cam, backend="dense"), 1, device)
        diff = float((render(g, cam).rgb - render(g, cam, backend="dense").rgb).abs().max())
    return {"tiled": tiled[0], "dense": dense[0], "ratio": dense[0] / tiled[0], "max_diff": diff}


def bench_label_frame(
    repeats: int, threads: int, backend: str = "torch", n: int = 100_000
) -> dict[str, float]:
    """Time one ``robogs render`` frame: 2DGS, 10 one-hot label channels, labels by argmax
    (torch and numba threads both set to ``threads``)."""
    g, f = make_scene(n, 640, seed=3, kind="2dgs")
    lab = torch.randint(0, 10, (n,), generator=torch.Generator().manual_seed(4))
    g = Gaussians(
        g.means,
        g.quats,
        g.log_scales,
        g.opacity_logits,
        g.sh[:, :1].contiguous(),
        extra=torch.nn.functional.one_hot(lab, 10).float(),
    )
    cam = make_camera(640, 480, f)
    cfg = RenderConfig(kind="2dgs", tile_size=8, validate=False)

    def frame() -> None:
        out = render(g, cam, config=cfg, backend=backend)
        none = (1.0 - out.extra.sum(-1, keepdim=True)).clamp(0.0, 1.0)
        torch.cat([none, out.extra], -1).argmax(-1)
        (out.rgb.clamp(0, 1) * 255).round().to(torch.uint8)

    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    if backend == "numba":
        import numba

        numba.set_num_threads(threads)
    try:
        with torch.no_grad():
            wall, med, cpu = timed(frame, repeats)
    finally:
        torch.set_num_threads(before)
    return {"wall": wall, "median": med, "cpu": cpu, "threads": threads, "backend": backend}


def bench_render_dataset(path: str, frames: int = 12) -> dict[str, float]:
    """``render_dataset`` end to end over ``frames`` recorded stamps of the first camera."""
    import shutil
    import tempfile

    from robogs.format import Dataset
    from robogs.format.kinematics import Chain
    from robogs.format.render_trajectory import episode_trajectory, render_dataset

    ds = Dataset.open(path)
    ep = ds.episode()
    cam = ds.camera_names[0]
    traj = episode_trajectory(ep, Chain.from_urdf(ds.urdf(load_meshes=False)), {})
    t = ep.frames(cam).column("t_ns").to_numpy()
    t = t[len(t) // 3 : len(t) // 3 + frames]
    out = Path(tempfile.mkdtemp(prefix="bench-render-")) / "out"
    try:
        c0, t0 = time.process_time(), time.perf_counter()
        render_dataset(ds, out, traj, cameras=[cam], frame_stamps=t)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        shutil.rmtree(out.parent, ignore_errors=True)
    m = ds.camera(cam)
    return {"wall": wall, "cpu": cpu, "frames": len(t), "size": f"{m.width}x{m.height}"}


def bench_novel_pose(
    configs: int, seed: int = 0, spacing: float | None = None
) -> tuple[list[tuple[str, str, str, str]], str]:
    """Rows of the novel-pose comparison (per link worst IoU and boundary, PSNR) and a summary,
    on ``synth --size small --splat-spacing spacing`` (default: the test's ``SPACING_M``)."""
    import tempfile

    import numpy as np

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "render"))
    from novel_pose import SPACING_M, novel_configurations, novel_pose_metrics  # test harness

    from robogs.format import Dataset
    from robogs.synth.scene import synthesize

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "s"
        spacing = SPACING_M if spacing is None else spacing
        synthesize(out, seed=seed, size="small", progress=False, splat_spacing_m=spacing)
        qs = novel_configurations(Dataset.open(out), configs, seed=seed)
        t0 = time.perf_counter()
        res = novel_pose_metrics(out, qs, scale=2.0)
        wall = time.perf_counter() - t0
    per: dict[str, tuple[list[float], list[float]]] = {}
    for r in res:
        for n, i, b in zip(r.names, r.iou, r.boundary_px, strict=True):
            per.setdefault(n, ([], []))
            if np.isfinite(i):
                per[n][0].append(float(i))
            per[n][1].append(float(b))
    rows = []
    for n, (ious, bs) in per.items():
        iou = f"IoU min {min(ious):.3f} / mean {np.mean(ious):.3f}" if ious else "IoU n/a (sliver)"
        rows.append(
            (
                f"novel pose: {n} ({len(bs)} of {len(res)} configs visible)",
                f"{iou}; boundary max {max(bs):.2f} / mean {np.mean(bs):.2f} px",
                "IoU >= 0.9, boundary <= 1.5 px (links)",
                (f"{min(ious) / 0.9:.2f}x IoU floor; " if ious else "")
                + f"{max(bs) / 1.5:.2f}x boundary budget",
            )
        )
    psnr = [r.psnr_db for r in res]
    dist = min(r.min_distance_rad for r in res)
    rows.append(
        (
            "novel pose: PSNR vs rasteriser (foreground)",
            f"mean {np.mean(psnr):.1f} dB (min {min(psnr):.1f})",
            "reported (baked splat colour vs flat-shaded meshes)",
            "-",
        )
    )
    summary = (
        f"novel poses: {len(res)} configurations of synth --size small seed {seed} "
        f"--splat-spacing {spacing:g}, each >= "
        f"{dist:.2f} rad (max-norm) from every recorded joint state, 320x240, {wall:.1f} s"
    )
    return rows, summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2, help="torch CPU threads (default 2)")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-append", action="store_true", help="do not append to bench/RESULTS.md")
    ap.add_argument("--only", choices=("all", "speed", "novel", "fps", "gpu"), default="all")
    ap.add_argument("--device", default="cuda", help="with --only gpu: the device (cuda)")
    ap.add_argument("--scale", type=float, default=1.0, help="with --only gpu: shrink the scenes")
    ap.add_argument("--json", help="with --only gpu: write the figures as JSON to this path")
    ap.add_argument("--dataset", help="with --only fps: also time render_dataset on this dataset")
    ap.add_argument("--configs", type=int, default=8, help="novel-pose configurations")
    ap.add_argument("--seed", type=int, default=0, help="novel-pose scene and configuration seed")
    ap.add_argument(
        "--spacing", type=float, default=None, help="novel-pose surfel spacing, m (default 0.007)"
    )
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    machine = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}"
    )
    head = [
        f"machine: {machine}; torch {torch.__version__}; threads {torch.get_num_threads()}; load avg {os.getloadavg()[0]:.1f}",
        f"backends: {sorted(available_backends())}",
    ]
    rows: list[tuple[str, str, str, str]] = []  # figure, measured, baseline / target, ratio
    if args.only in ("all", "novel"):
        nrows, summary = bench_novel_pose(args.configs, args.seed, args.spacing)
        head.append(summary)
        rows += nrows
    if args.only == "novel":
        _emit(head, rows, args)
        return
    if args.only == "gpu":
        head.append(_device_line(args.device))
        rows += bench_gpu(args)
        head.append(f"load avg after: {os.getloadavg()[0]:.1f}")
        _emit(head, rows, args)
        return
    if args.only == "fps":
        backends = ["torch"] + (["numba"] if "numba" in available_backends() else [])
        if "numba" in backends:
            # discarded: the first numba configuration of a process ran at ~4x the CPU time of
            # the later ones in every order tried (2.2-2.8 s vs 0.56 s, 2026-11-26)
            bench_label_frame(1, args.threads, "numba")
        base = None
        for th in sorted({1, args.threads}):
            for b in backends:
                r = bench_label_frame(args.repeats, th, b)
                base = base or r  # the in-run baseline: torch, 1 thread
                rows.append(
                    (
                        f"frames/s, robogs render frame (2DGS 100k + 10 label channels) "
                        f"@ 640x480, {b}, {th} thread(s)",
                        f"{1 / r['wall']:.2f} frames/s ({r['wall']:.3f} s best of "
                        f"{args.repeats}; median {r['median']:.3f}; cpu {r['cpu']:.3f})",
                        f"torch 1 thread: {base['wall']:.3f} s (cpu {base['cpu']:.3f}); "
                        "target >= 1 frame/s",
                        f"{base['wall'] / r['wall']:.2f}x wall, {base['cpu'] / r['cpu']:.2f}x "
                        f"cpu; {1 / r['wall']:.2f}x target",
                    )
                )
        two = r
        if args.dataset:
            e2e = bench_render_dataset(args.dataset)
            rows.append(
                (
                    f"render_dataset end to end, {e2e['size']}, {args.threads} threads",
                    f"{e2e['frames'] / e2e['wall']:.2f} frames/s ({e2e['frames']} frames in "
                    f"{e2e['wall']:.2f} s; cpu {e2e['cpu']:.2f} s)",
                    f"render alone ({two['backend']}): {two['wall']:.3f} s per frame",
                    f"{e2e['wall'] / e2e['frames'] / two['wall']:.2f}x the render alone",
                )
            )
        head.append(f"load avg after: {os.getloadavg()[0]:.1f}")
        _emit(head, rows, args)
        return

    tr = bench_train_step(args.repeats)
    rows.append(
        (
            "fwd+bwd 20k @ 320x240 (tile 8)",
            f"{tr['wall']:.3f} s (fwd {tr['fwd']:.3f} + bwd {tr['bwd']:.3f}; median {tr['median']:.3f}; cpu {tr['cpu']:.3f})",
            "target 0.5 s",
            f"{tr['wall'] / 0.5:.2f}x target",
        )
    )
    rows.append(
        (
            "peak RSS growth of that step",
            f"{tr['peak_mb']:.0f} MB",
            "target 1024 MB",
            f"{tr['peak_mb'] / 1024:.2f}x target",
        )
    )
    fw8 = bench_forward(args.repeats, 8)
    fw16 = bench_forward(args.repeats, 16)
    ns = fw8["wall"] / fw8["pairs"] * 1e9
    rows.append(
        (
            "forward 100k @ 640x480, tile 8 (default)",
            f"{fw8['wall']:.3f} s (median {fw8['median']:.3f}; cpu {fw8['cpu']:.3f}; {fw8['pairs'] / 1e6:.0f} M tile-pixel pairs binned, {ns:.1f} ns each; {fw8['coverage']:.0%} of pixels alpha > 0.5)",
            "target 0.6 s",
            f"{fw8['wall'] / 0.6:.2f}x target",
        )
    )
    rows.append(
        (
            f"frames/s, forward 100k @ 640x480, {torch.get_num_threads()} threads",
            f"{1.0 / fw8['wall']:.2f} frames/s (best of {args.repeats}; median "
            f"{1.0 / fw8['median']:.2f})",
            "target 0.6 s per frame",
            f"{(1.0 / fw8['wall']) / (1 / 0.6):.2f}x target rate",
        )
    )
    rows.append(
        (
            "forward 100k @ 640x480, tile 16",
            f"{fw16['wall']:.3f} s (median {fw16['median']:.3f})",
            f"tile 8: {fw8['wall']:.3f} s",
            f"tile 8 is {fw16['wall'] / fw8['wall']:.2f}x faster",
        )
    )
    orc = bench_oracle(args.repeats)
    rows.append(
        (
            "tiled vs dense oracle, 2k @ 128x96",
            f"tiled {orc['tiled'] * 1e3:.1f} ms",
            f"dense {orc['dense']:.2f} s",
            f"{orc['ratio']:.0f}x faster (max |d rgb| {orc['max_diff']:.1e})",
        )
    )
    if "numba" in available_backends():
        g, f = make_scene(100_000, 640, seed=0)
        cam = make_camera(640, 480, f)
        nb = timed(lambda: render(g, cam, backend="numba"), args.repeats)
        rows.append(
            (
                "forward 100k @ 640x480, numba",
                f"{nb[0]:.3f} s",
                f"torch {fw8['wall']:.3f} s; stretch 0.15 s",
                f"{fw8['wall'] / nb[0]:.2f}x faster than torch",
            )
        )
    if torch.cuda.is_available():
        head.append(f"cuda: {torch.cuda.get_device_name()}")
        fc = bench_forward(args.repeats, None, "cuda")
        rows.append(
            (
                "CUDA forward 100k @ 640x480 (tile 16)",
                f"{fc['wall'] * 1e3:.1f} ms",
                f"CPU {fw8['wall']:.3f} s",
                f"{fw8['wall'] / fc['wall']:.0f}x faster",
            )
        )
        tc = bench_train_step(args.repeats, "cuda")
        rows.append(
            (
                "CUDA fwd+bwd 20k @ 320x240",
                f"{tc['wall'] * 1e3:.1f} ms, peak {tc['peak_mb']:.0f} MB allocated",
                f"CPU {tr['wall']:.3f} s",
                f"{tr['wall'] / tc['wall']:.0f}x faster",
            )
        )
    else:
        head.append("cuda: not available (no CUDA figures)")
    _emit(head, rows, args)


def _device_line(device: str) -> str:
    if device.startswith("cuda") and torch.cuda.is_available():
        return f"device: {torch.cuda.get_device_name()} (torch {torch.__version__})"
    return f"device: {device} (no CUDA; Triton interpreter: {os.environ.get('TRITON_INTERPRET')})"


def _time_device(fn, repeats: int, device: str) -> tuple[float, float]:
    """(min, median) wall seconds of ``fn`` over ``repeats`` runs after two warm-ups."""
    for _ in range(2):
        fn()
    _sync(device)
    walls = []
    for _ in range(repeats):
        _sync(device)
        t0 = time.perf_counter()
        fn()
        _sync(device)
        walls.append(time.perf_counter() - t0)
    walls.sort()
    return walls[0], walls[len(walls) // 2]


def _gpu_case(
    kind: str, n: int, size: tuple[int, int], device: str, backend: str, train: bool, repeats: int
) -> tuple[float, float, torch.Tensor]:
    """Time one render (or render + backward) and return (min s, median s, rgb)."""
    g, f = make_scene(n, size[0], seed=5, kind=kind, device=device)
    cam = make_camera(size[0], size[1], f, device)
    cfg = RenderConfig(kind=kind, validate=False, tile_size=8 if device == "cpu" else 16)
    if backend == "triton":
        cfg = RenderConfig(kind=kind, validate=False, tile_size=16)
    leaves = [g.means, g.quats, g.log_scales, g.opacity_logits, g.sh]
    target = torch.rand(size[1], size[0], 3, generator=torch.Generator().manual_seed(0))
    target = target.to(device)

    def fwd() -> None:
        with torch.no_grad():
            render(g, cam, config=cfg, backend=backend)

    def step() -> None:
        out = render(g, cam, config=cfg, backend=backend)
        loss = (out.rgb - target).abs().mean() + 0.1 * out.depth_expected.mean()
        loss.backward()
        for p in leaves:
            p.grad = None

    if train:
        for p in leaves:
            p.requires_grad_(True)
    lo, med = _time_device(step if train else fwd, repeats, device)
    with torch.no_grad():
        rgb = render(g, cam, config=cfg, backend=backend).rgb.float().cpu()
    return lo, med, rgb


def bench_gpu(args: argparse.Namespace) -> list[tuple[str, str, str, str]]:
    """Issue 23's figures: torch and triton on the device against torch on the CPU."""
    import json

    dev = args.device
    rows: list[tuple[str, str, str, str]] = []
    figures: dict[str, float | str] = {"device": _device_line(dev), "threads": args.threads}
    s = args.scale
    cases = [
        ("forward", 100_000, (640, 480), False, 5e-3),
        ("fwd+bwd", 20_000, (320, 240), True, 5e-3),
    ]
    backends = ["torch"] + (["triton"] if "triton" in available_backends() else [])
    for kind in ("3dgs", "2dgs"):
        for what, n, (w, h), train, target in cases:
            n, size = max(int(n * s), 10), (max(int(w * s), 16), max(int(h * s), 16))
            label = f"{kind} {what} {n // 1000}k @ {size[0]}x{size[1]}"
            cpu = _gpu_case(kind, n, size, "cpu", "torch", train, max(1, args.repeats // 3))
            figures[f"{label} | cpu torch"] = cpu[0]
            ref_rgb = None
            for b in backends:
                r = _gpu_case(kind, n, size, dev, b, train, args.repeats)
                figures[f"{label} | {dev} {b}"] = r[0]
                if ref_rgb is None:
                    ref_rgb = r[2]
                dev_abs = (r[2] - ref_rgb).abs().flatten()
                diff = float(dev_abs.max())
                p999 = float(
                    torch.quantile(dev_abs[:: max(1, dev_abs.numel() // 1_000_000)], 0.999)
                )
                rows.append(
                    (
                        f"{label}, {dev} {b}",
                        f"{r[0] * 1e3:.2f} ms (median {r[1] * 1e3:.2f}); |d rgb| vs "
                        f"{dev} torch: max {diff:.1e}, 99.9 % {p999:.1e}",
                        f"CPU torch ({args.threads} threads) {cpu[0] * 1e3:.1f} ms; "
                        f"target {target * 1e3:.0f} ms",
                        f"{cpu[0] / r[0]:.1f}x CPU; {r[0] / target:.2f}x target",
                    )
                )
    if "triton" not in backends:
        rows.append(("triton", "not run", "backend unavailable", "-"))
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return rows


def _emit(head: list[str], rows: list[tuple[str, str, str, str]], args: argparse.Namespace) -> None:
    import datetime

    lines = (
        head
        + [""]
        + ["| figure | measured | baseline / target | ratio |", "|---|---|---|---|"]
        + [f"| {a} | {b} | {c} | {d} |" for a, b, c, d in rows]
    )
    print("\n".join(lines))
    if not args.no_append:
        cmd = "python bench/render.py " + " ".join(sys.argv[1:])
        day = datetime.date.today().isoformat()
        text = f"\n## render — {day}\n\nCommand: `{cmd.strip()}`\n\n" + "\n".join(lines) + "\n"
        with RESULTS.open("a") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()

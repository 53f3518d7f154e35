"""Reference reconstructor figures: TSDF fusion speed and accuracy, and a full reconstruction.

Scene: the generated UR5 of ``robogs.synth.scene`` over a table with a box, captured by
``robogs.synth.multiview`` from ``--views`` viewpoints on the upper hemisphere at ``--width`` x
``--height`` (static, lossless video, panoptic labels, URDF, object poses).

1. TSDF fusion of the *true* depth maps (the fixture's z-buffer) on a ``--tsdf-res``^3 grid over
   the scene box: our narrow-band fusion vs the same fusion on the dense grid (the baseline), and
   vs Open3D's ``UniformTSDFVolume`` when ``open3d`` is importable. Mesh F-score at 1 % of the
   scene diagonal and at 5 mm against the visible true surface.
2. ``reconstruct`` (2DGS, ``--iterations`` steps): wall time, held-out PSNR/SSIM, label mIoU,
   mesh F-score; baseline: the same pipeline with one training step (the seeds alone).

2b. ``--device cuda`` (or ``--cpu-baseline-iterations N`` / ``--same-steps`` on any device): the
   reconstruction of 2 on the device and, in the same run, the same job on the CPU
   (``--threads`` torch threads) as the baseline, instead of the seeds-only baseline. The Triton
   kernels are compiled by a warm-up render first. The CPU job follows the same
   ``--iterations``-step schedule and is stopped after ``--cpu-baseline-iterations`` steps (so
   its per-step time is measured on steps the device also ran, and no held-out PSNR exists for
   it); ``--same-steps`` runs it to the end, for the PSNR comparison. Printed: the card, the CPU
   threads, the training time of both, ms per step on the common window of steps (after the
   first ``--log-every`` steps), the speed ratio, held-out PSNR of both, and ``--json PATH``
   appends the figures as one JSON line.

3. ``--sfm``: the structure-from-motion route of ``docs/reconstruct.md`` instead of 1-2: the
   sample of ``robogs synth OUT --capture static --no-poses`` (``--seed``), posed by
   ``convert --sfm``, reconstructed with ``--align apply`` (``--iterations`` steps, no truth
   used), then scored against the truth: camera centres (% of the scene size) and rotations,
   held-out PSNR, mesh F@1 % of the scene diagonal against the visible true surface, and the
   URDF alignment residual. No in-run baseline: the acceptance figures are absolute.

Usage: ``PYTHONPATH=. .venv/bin/python bench/reconstruct.py [--views 60 --width 320 --height 240]``
``[--sfm --iterations 3000]``
``[--device cuda --skip-tsdf --iterations 3000 --cpu-baseline-iterations 600 --threads 16 --json F]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import trimesh


def _fscore(mesh: trimesh.Trimesh, ref: np.ndarray, ref_n: np.ndarray, taus_mm: tuple[float, ...]):
    from robogs.reconstruct.mesh_metrics import point_metrics, sample_mesh

    p, pn = sample_mesh(mesh, len(ref), 0)
    return point_metrics(p, ref, pred_normals=pn, ref_normals=ref_n, taus_mm=taus_mm, workers=1)


def _open3d_fusion(truth, vox: float, trunc: float, origin: np.ndarray, res: int):
    """Open3D's dense ``UniformTSDFVolume`` (a res^3 cube of the same voxel size at ``origin``).

    ``ScalableTSDFVolume`` (the one 2DGS uses) integrated nothing in the open3d 0.20.0 wheel on
    this machine (empty meshes even for a fronto-parallel plane), so the uniform volume stands in.
    """
    import open3d as o3d

    H, W = truth._depth[0].shape
    K = truth.K
    # Open3D puts pixel centres at integers: principal point - 0.5
    intr = o3d.camera.PinholeCameraIntrinsic(W, H, K[0, 0], K[1, 1], K[0, 2] - 0.5, K[1, 2] - 0.5)
    vol = o3d.pipelines.integration.UniformTSDFVolume(
        length=vox * res,
        resolution=res,
        sdf_trunc=trunc,
        color_type=o3d.pipelines.integration.TSDFVolumeColorType.NoColor,
        origin=np.asarray(origin, np.float64),
    )
    t0 = time.perf_counter()
    for d, T in zip(truth._depth, truth.T_world_cam, strict=True):
        depth = o3d.geometry.Image(np.ascontiguousarray(d, dtype=np.float32))
        color = o3d.geometry.Image(np.zeros((H, W, 3), np.uint8))
        rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
            color, depth, depth_scale=1.0, depth_trunc=100.0, convert_rgb_to_intensity=False
        )
        vol.integrate(rgbd, intr, np.linalg.inv(T))
    t_fuse = time.perf_counter() - t0
    m = vol.extract_triangle_mesh()
    t_all = time.perf_counter() - t0
    return (
        trimesh.Trimesh(np.asarray(m.vertices), np.asarray(m.triangles), process=False),
        t_fuse,
        t_all,
    )


def open3d_version() -> str:
    import open3d

    return open3d.__version__


def _camera_errors(ds_root: Path, truth) -> tuple[np.ndarray, np.ndarray]:
    """Per-view camera centre error (m) and rotation error (deg) of a posed dataset vs the truth."""
    from robogs.format.dataset import Dataset, read_parquet
    from robogs.format.frames import quat_to_matrix_np

    ds = Dataset.open(ds_root)
    tab = read_parquet(ds.resolve("episodes/static/cameras/orbit/extrinsics.parquet"))
    p = np.stack([tab.column(c).to_numpy() for c in "xyz"], -1)
    q = np.stack([tab.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
    Tt = np.asarray(truth.T_world_cam)
    d = np.einsum("nji,njk->nik", quat_to_matrix_np(q), Tt[:, :3, :3])
    ang = np.degrees(np.arccos(np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    return np.linalg.norm(p - Tt[:, :3, 3], axis=1), ang


def _link_residuals(root: Path) -> tuple[float, float]:
    """RMS (mm) of the written link parts (``reconstruction/links``, link frame) against their
    URDF meshes at the joint state: by the nearest of 20k area samples per link (the residual
    before 2026-11-26) and by the exact distance to the surface (since)."""
    import json

    from scipy.spatial import cKDTree

    from robogs.format.dataset import Dataset
    from robogs.reconstruct.align import _Surface
    from robogs.reconstruct.robot_geometry import link_meshes

    ds = Dataset.open(root)
    rest = json.loads((root / "manifest.json").read_text())["robot"]["splats"]["rest"]
    old, new = [], []
    for k, (name, lm) in enumerate(sorted(link_meshes(ds, rest["joint_positions"]).items())):
        f = root / "reconstruction" / "links" / f"{name}.ply"
        if not f.exists():
            continue
        p = trimesh.transform_points(trimesh.load(f, force="mesh").vertices, lm.T_world_link)
        s = _Surface(lm.world_mesh(), 20_000, k)
        old.append(cKDTree(s.points).query(p)[0])
        new.append(s.query(p)[1])
    rms = [float(np.sqrt((np.concatenate(d) ** 2).mean()) * 1e3) for d in (old, new)]
    return rms[0], rms[1]


def sfm_route(args: argparse.Namespace, tmp: Path) -> None:
    """The docs recipe, timed step by step and scored against the sample's truth."""
    from robogs.convert.ingest.context import ConvertOptions
    from robogs.convert.ingest.sfm import convert_sfm
    from robogs.reconstruct.evaluate import evaluate
    from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
    from robogs.reconstruct.train import TrainConfig
    from robogs.synth.multiview import synthesize_multiview

    t0 = time.perf_counter()
    truth = synthesize_multiview(
        tmp / "scan",
        robot="ur5",
        n_views=args.views,
        width=args.width,
        height=args.height,
        seed=args.seed,
        poses=False,
    )
    t_synth = time.perf_counter() - t0
    t0 = time.perf_counter()
    _, res = convert_sfm(
        tmp / "scan", tmp / "posed", options=ConvertOptions(), threads=args.threads
    )
    t_sfm = time.perf_counter() - t0
    print(
        f"SfM route: {args.views} views {args.width}x{args.height} (seed {args.seed}) generated in "
        f"{t_synth:.1f} s; SfM {res.registered} of {res.total} registered in {t_sfm:.1f} s "
        f"({res.points} points, {res.reprojection_px:.2f} px)"
    )
    opts = ReconstructOptions(
        train=TrainConfig(iterations=args.iterations, checkpoint_every=0),
        lr_scale=args.lr_scale,
        tsdf_resolution=args.tsdf_res,
        drop_depth_edges=args.drop_depth_edges,
        work_dir=tmp / "work",
        keep_checkpoint=args.keep_checkpoint,
        align="apply",
        force=True,  # the floors are reported, not enforced
    )
    t0 = time.perf_counter()
    rep = reconstruct(tmp / "posed", opts)
    wall = time.perf_counter() - t0
    size = float(np.linalg.norm(np.ptp(truth.scene_mesh.vertices, axis=0)))
    err, ang = _camera_errors(tmp / "posed", truth)
    ev = evaluate(tmp / "posed")
    ref, ref_n = truth.visible_surface_points(args.samples)
    tau = 0.01 * size * 1e3
    m = _fscore(
        trimesh.load(tmp / "posed" / "reconstruction" / "mesh.ply", force="mesh"),
        ref,
        ref_n,
        (tau, 5.0),
    )
    t, al = rep.timings_s, rep.alignment
    pre = al["sfm_prealign"]
    print(
        f"reconstruct --align apply{' --drop-depth-edges' * args.drop_depth_edges}, "
        f"{args.iterations} steps (lr x{args.lr_scale}): {wall:.1f} s "
        f"(prealign {t.get('prealign', 0):.1f}, init {t['init']:.1f}, train {t['train']:.1f}, "
        f"mesh {t['mesh']:.1f}); {sum(rep.gaussians.values())} Gaussians"
    )
    print(
        f"  cameras vs truth: centres max {err.max() * 1e3:.1f} mm = {err.max() / size:.2%} of the "
        f"{size:.2f} m scene (target <= 1 %), rotations max {ang.max():.2f} deg (target <= 1)"
    )
    print(
        f"  held-out PSNR {ev.psnr_db:.2f} dB (target >= 25), SSIM {ev.ssim:.4f}, mIoU {ev.miou:.4f}"
    )
    print(
        f"  mesh F@{tau:.2f}mm (1 %) {m.fscore[tau]:.4f} (target >= 0.9), F@5mm "
        f"{m.fscore[5.0]:.4f}, Chamfer-L1 {m.chamfer_l1_mm:.2f} mm"
    )
    print(
        f"  URDF alignment RMS {al['rms_mm']:.2f} mm (target <= 5), median {al['median_mm']:.2f} mm, "
        f"scale {al['scale']:.4f}; pre-alignment RMS {pre['rms_mm']:.2f} mm"
    )
    old, new = _link_residuals(tmp / "posed")
    print(
        f"  the same residual of the written link parts against the URDF at the joint state: "
        f"RMS {new:.2f} mm to the surface (exact); {old:.2f} mm by the statistic before "
        f"2026-11-26 (nearest of 20k samples per link)"
    )
    print(
        "  per-link median residual (mm): "
        + ", ".join(f"{k} {v:.1f}" for k, v in al["per_link_median_mm"].items())
        + (f"; left out of the fit: {', '.join(al['excluded'])}" if al.get("excluded") else "")
    )
    for name, sp in rep.support.items():  # the true top of the sample's table is z = 0
        print(
            f"  support: {name} plane at z {sp['height_mm']:.1f} mm (true top 0), free-fit tilt "
            f"{sp['free_tilt_deg']:.2f} deg, sigma {sp['sigma_mm']:.1f} mm; rested: "
            f"{', '.join(sp['objects_rested']) or 'none'}"
        )
    print(f"  load average now {os.getloadavg()[0]:.1f}")


class _StopAt(Exception):
    """Raised from ``on_step`` to stop the CPU baseline after its steps."""


#: bench option -> (triton_raster flag, the choice that sets it, what it switches)
_TRITON_SWITCHES = {
    "triton-projection": ("_FUSED_PROJECTION", "fused", "projection (triton_project.py)"),
    "triton-binning": ("_TRITON_BINNING", "triton", "tile binning (triton_binning.py)"),
    "fused-finish": ("_FUSED_FINISH", "triton", "output finish (triton_finish.py)"),
}


def _warm_up(device: torch.device, backend: str, width: int, height: int) -> float:
    """Render and back-propagate random surfels with and without the two depth channels (the
    variants training compiles), forward-only once; returns the seconds it took."""
    from robogs.format.render import Camera, Gaussians, RenderConfig, render

    t0 = time.perf_counter()
    g = torch.Generator().manual_seed(0)
    n = 4000
    f = 0.9 * width
    cam = Camera(
        width=width,
        height=height,
        fx=f,
        fy=f,
        cx=width / 2,
        cy=height / 2,
        T_world_cam=torch.eye(4, dtype=torch.float64, device=device),
    )
    xy = (torch.rand(n, 2, generator=g) - 0.5) * torch.tensor([width / f, height / f]) * 2.0
    means = torch.cat([xy, torch.full((n, 1), 2.0)], 1) + 0.05 * torch.randn(n, 3, generator=g)
    params = {
        "means": means,
        "quats": torch.randn(n, 4, generator=g),
        "log_scales": torch.full((n, 2), math.log(0.01)),
        "opacity_logits": torch.zeros(n),
        "sh": torch.rand(n, 1, 3, generator=g),
    }
    params = {k: v.to(device).requires_grad_(True) for k, v in params.items()}
    rc = RenderConfig(kind="2dgs", validate=False)
    for extra in (None, torch.stack([params["means"][:, 2], params["means"][:, 2] ** 2], 1)):
        out = render(Gaussians(**params, extra=extra), cam, config=rc, backend=backend)
        loss = out.rgb.sum() + out.normals.sum() + out.depth_expected.sum() + out.alpha.sum()
        if extra is not None:
            loss = loss + out.extra.sum()
        loss.backward()
    with torch.no_grad():
        render(Gaussians(**params), cam, config=rc, backend=backend)
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter() - t0


def _timed_reconstruct(
    tmp: Path, label: str, device: str, iterations: int, stop_at: int, args: argparse.Namespace
) -> dict:
    """One reconstruction of the bench scene on ``device``; ``stop_at`` < ``iterations`` stops
    training there (same schedule). Returns the figures; the step clock is read at each log
    point, where the PSNR gather has waited for the device."""
    import shutil

    from robogs.reconstruct.evaluate import evaluate
    from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
    from robogs.reconstruct.train import TrainConfig

    root = tmp / f"run-{label}"
    shutil.copytree(tmp / "ur5", root)
    marks: dict[int, tuple[float, float]] = {}

    def on_step(k: int, info: dict) -> None:
        marks[k] = (time.perf_counter(), info["n"])
        if k >= stop_at < iterations:
            raise _StopAt

    opts = ReconstructOptions(
        train=TrainConfig(
            iterations=iterations,
            checkpoint_every=0,
            log_every=args.log_every,
            backend=args.backend,
            cuda_graphs=not args.no_cuda_graphs,
        ),
        lr_scale=args.lr_scale,
        tsdf_resolution=args.tsdf_res,
        work_dir=tmp / f"work-{label}",
        device=device,
        force=True,
    )
    t0 = time.perf_counter()
    fig: dict = {"device": device, "steps": min(stop_at, iterations)}
    try:
        rep = reconstruct(root, opts, on_step=on_step)
    except _StopAt:
        fig.update(stopped=True, wall_s=time.perf_counter() - t0, psnr_db=None, gaussians=None)
    else:
        fig.update(stopped=False, wall_s=time.perf_counter() - t0)
        fig["train_s"] = rep.timings_s["train"]
        fig["ms_per_step"] = 1e3 * rep.timings_s["train"] / iterations
        fig["gaussians"] = sum(rep.gaussians.values())
        fig["psnr_db"] = evaluate(root).psnr_db
        fig["timings_s"] = {k: round(v, 3) for k, v in rep.timings_s.items()}
    fig["marks"] = {k: v for k, v in sorted(marks.items())}
    return fig


def _window(fig: dict, lo: int, hi: int) -> float | None:
    """ms per step between the log points ``lo`` and ``hi`` (None if either is missing)."""
    m = fig["marks"]
    if lo not in m or hi not in m or hi <= lo:
        return None
    return 1e3 * (m[hi][0] - m[lo][0]) / (hi - lo)


def device_vs_cpu(args: argparse.Namespace, tmp: Path) -> dict:
    """Part 2b: the reconstruction on ``--device`` and the same job on the CPU (see the
    module docstring)."""
    from robogs.reconstruct.train import resolve_backend

    device = torch.device(args.device)
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise SystemExit(f"--device {args.device}: CUDA is not available here")
        card = torch.cuda.get_device_name(device)
    else:
        card = f"CPU ({platform.processor() or platform.machine()})"
    backend = resolve_backend(args.backend, device)
    every = args.log_every
    n_cpu = (
        args.iterations if args.same_steps else (args.cpu_baseline_iterations or args.iterations)
    )
    n_cpu = min(args.iterations, every * math.ceil(n_cpu / every))  # end on a log point
    if n_cpu < 2 * every and n_cpu < args.iterations:
        raise SystemExit(
            f"--cpu-baseline-iterations must reach 2 x --log-every ({2 * every}) steps: the "
            "first logged interval (warm-up) is left out of the per-step window"
        )
    print(
        f"2b. reconstruct on {args.device} ({card}, backend {backend}) vs the CPU "
        f"({torch.get_num_threads()} torch threads of {os.cpu_count()} cores, backend "
        f"{resolve_backend(args.backend, 'cpu')}); {args.iterations}-step schedule"
    )
    warm = _warm_up(device, backend, args.width, args.height)
    print(
        f"  warm-up on {args.device} (kernel compilation, allocator): {warm:.1f} s, not timed below"
    )
    dev = _timed_reconstruct(tmp, "device", args.device, args.iterations, args.iterations, args)
    cpu = _timed_reconstruct(tmp, "cpu", "cpu", args.iterations, n_cpu, args)
    lo, hi = every, n_cpu
    w_dev, w_cpu = _window(dev, lo, hi), _window(cpu, lo, hi)
    print(
        f"  {args.device} (device run): {args.iterations} steps, training {dev['train_s']:.1f} s = "
        f"{dev['ms_per_step']:.1f} ms/step (warm-up steps included; {dev['gaussians']} Gaussians "
        f"written); "
        f"held-out PSNR {dev['psnr_db']:.2f} dB; whole reconstruction {dev['wall_s']:.1f} s "
        f"(init {dev['timings_s']['init']:.1f}, mesh {dev['timings_s']['mesh']:.1f})"
    )
    if cpu["stopped"]:
        proj = None if w_cpu is None else w_cpu * args.iterations / 1e3
        print(
            f"  cpu: stopped after {n_cpu} of the {args.iterations} steps (--cpu-baseline-"
            f"iterations); {cpu['wall_s']:.1f} s with loading and initialisation; no held-out "
            f"PSNR (pass --same-steps to train it to the end)"
        )
        if proj is not None:
            print(
                f"  cpu per step scaled to {args.iterations} steps: {proj:.1f} s (an estimate: "
                f"the later steps have more Gaussians after densification)"
            )
    else:
        proj = None
        print(
            f"  cpu: {n_cpu} steps, training {cpu['train_s']:.1f} s = {cpu['ms_per_step']:.1f} "
            f"ms/step ({cpu['gaussians']} Gaussians written); held-out PSNR {cpu['psnr_db']:.2f} dB"
        )
    ratio = None if not (w_dev and w_cpu) else w_cpu / w_dev
    if ratio is not None:
        print(
            f"  steps {lo + 1}-{hi}, the same on both: {args.device} {w_dev:.2f} ms/step "
            f"({dev['marks'][hi][1]:.0f} Gaussians at step {hi}), cpu {w_cpu:.2f} ms/step "
            f"({cpu['marks'][hi][1]:.0f}) -> speed ratio {ratio:.1f} (cpu time / {args.device} time)"
        )
    if not cpu["stopped"]:
        print(
            f"  whole training: speed ratio {cpu['train_s'] / dev['train_s']:.1f} (cpu / {args.device}); "
            f"held-out PSNR {args.device} - cpu = {dev['psnr_db'] - cpu['psnr_db']:+.2f} dB"
        )
    for f in (dev, cpu):
        f["marks"] = {str(k): [round(t, 4), n] for k, (t, n) in f["marks"].items()}
    return {
        "bench": "reconstruct --device",
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "device": args.device,
        "device_name": card,
        "backend": backend,
        "triton_projection": args.triton_projection,
        "triton_binning": args.triton_binning,
        "fused_finish": args.fused_finish,
        "cuda_graphs": not args.no_cuda_graphs,
        "cpu_threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "views": args.views,
        "size": [args.width, args.height],
        "iterations": args.iterations,
        "cpu_iterations": n_cpu,
        "log_every": every,
        "warm_up_s": round(warm, 3),
        "window_steps": [lo + 1, hi],
        "device_window_ms_per_step": w_dev,
        "cpu_window_ms_per_step": w_cpu,
        "speed_ratio_window": ratio,
        "device_train_s": dev["train_s"],
        "device_ms_per_step": dev["ms_per_step"],
        "cpu_train_s": cpu.get("train_s"),
        "cpu_ms_per_step": cpu.get("ms_per_step"),
        "cpu_projected_train_s": proj,
        "speed_ratio_train": None if cpu["stopped"] else cpu["train_s"] / dev["train_s"],
        "device_psnr_db": dev["psnr_db"],
        "cpu_psnr_db": cpu["psnr_db"],
        "runs": {"device": dev, "cpu": cpu},
    }


def _append_json(path: str | None, doc: dict) -> None:
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a") as fh:
            fh.write(json.dumps(doc, default=float) + "\n")
        print(f"figures appended to {path}")


def seeds_vs_trained(args: argparse.Namespace, tmp: Path, scene, ref, ref_n, tau, taus) -> None:
    """Part 2: the pipeline with one step (the seeds) and with ``--iterations`` steps, on the CPU."""
    import shutil

    from robogs.reconstruct.evaluate import evaluate
    from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
    from robogs.reconstruct.train import TrainConfig

    gt = tmp / "truth.ply"
    scene.export(gt)
    results = {}
    for label, iters in (("seeds only (1 step)", 1), (f"{args.iterations} steps", args.iterations)):
        root = tmp / f"run{iters}"
        shutil.copytree(tmp / "ur5", root)
        opts = ReconstructOptions(
            train=TrainConfig(iterations=iters, checkpoint_every=0),
            lr_scale=args.lr_scale,
            tsdf_resolution=args.tsdf_res,
            work_dir=tmp / f"work{iters}",
            force=True,  # measure short runs too: the floors are reported, not enforced
        )
        t0 = time.perf_counter()
        rep = reconstruct(root, opts)
        wall = time.perf_counter() - t0
        ev = evaluate(root)
        p, pn = trimesh.load(root / "reconstruction" / "mesh.ply", force="mesh"), None
        m = _fscore(p, ref, ref_n, taus)
        results[label] = (wall, rep, ev, m)
        t = rep.timings_s
        print(
            f"reconstruct, {label}: {wall:.1f} s (train {t['train']:.1f}, mesh {t['mesh']:.1f}, init {t['init']:.1f}); "
            f"{sum(rep.gaussians.values())} Gaussians; held-out PSNR {ev.psnr_db:.2f} dB, SSIM {ev.ssim:.4f}, "
            f"mIoU {ev.miou:.4f}; mesh F@{tau:.2f}mm {m.fscore[tau]:.4f}, F@5mm {m.fscore[5.0]:.4f}, "
            f"Chamfer-L1 {m.chamfer_l1_mm:.2f} mm; URDF alignment rms {rep.alignment['rms_mm']:.2f} mm "
            f"(scale {rep.alignment['scale']:.4f})"
        )
        del p, pn
    (w0, _, e0, m0), (w1, _, e1, m1) = results.values()
    print(
        f"training gain over the seeds: PSNR {e1.psnr_db - e0.psnr_db:+.2f} dB, "
        f"F@1% x{m1.fscore[tau] / max(m0.fscore[tau], 1e-9):.2f}, time x{w1 / w0:.1f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--views", type=int, default=60)
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--tsdf-res", type=int, default=128)
    ap.add_argument("--iterations", type=int, default=600)
    ap.add_argument("--lr-scale", type=float, default=3.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--samples", type=int, default=100_000)
    ap.add_argument("--skip-train", action="store_true")
    ap.add_argument("--sfm", action="store_true", help="the structure-from-motion route only")
    ap.add_argument("--seed", type=int, default=0, help="sample seed of the --sfm route")
    ap.add_argument(
        "--drop-depth-edges", action="store_true", help="--sfm: reconstruct --drop-depth-edges"
    )
    ap.add_argument(
        "--keep-checkpoint",
        action="store_true",
        help="--sfm: keep the trained model (work/checkpoint.pt beside the printed output)",
    )
    ap.add_argument(
        "--device",
        default="cpu",
        help="part 2 on this device (cuda, cuda:1) against the same job on the CPU (2b)",
    )
    ap.add_argument(
        "--cpu-baseline-iterations",
        type=int,
        default=None,
        help="2b: stop the CPU job after N steps of the --iterations schedule (default: all)",
    )
    ap.add_argument(
        "--same-steps",
        action="store_true",
        help="2b: train the CPU job to --iterations too (held-out PSNR of both comparable)",
    )
    ap.add_argument(
        "--backend", default="auto", help="render backend of training (auto: triton on CUDA)"
    )
    ap.add_argument("--log-every", type=int, default=50, help="steps between PSNR gathers")
    ap.add_argument(
        "--no-cuda-graphs",
        action="store_true",
        help="train without capturing the step loss as CUDA graphs (TrainConfig.cuda_graphs)",
    )
    for opt, (_, on, what) in _TRITON_SWITCHES.items():
        ap.add_argument(
            f"--{opt}",
            choices=("default", on, "torch"),
            default="default",
            help=f"the triton backend's {what} (triton_raster module flag): the module default, "
            f"{on} or the torch path",
        )
    ap.add_argument("--skip-tsdf", action="store_true", help="leave out part 1 (TSDF fusion)")
    ap.add_argument("--json", default=None, help="append the figures as one JSON line to this file")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    chosen = {o: getattr(args, o.replace("-", "_")) for o in _TRITON_SWITCHES}
    if any(v != "default" for v in chosen.values()):
        try:
            from robogs.format.render import triton_raster
        except ImportError as e:
            raise SystemExit(f"--{'/--'.join(_TRITON_SWITCHES)} need triton: {e}") from None
        for opt, value in chosen.items():
            flag, on, _ = _TRITON_SWITCHES[opt]
            if value != "default":
                setattr(triton_raster, flag, value == on)
    compare = args.device != "cpu" or args.cpu_baseline_iterations is not None or args.same_steps

    from robogs.format.render import Camera
    from robogs.reconstruct.mesh_clean import clean_mesh
    from robogs.reconstruct.tsdf import extract_mesh, fuse_tsdf
    from robogs.synth.multiview import synthesize_multiview

    print(
        f"machine: {platform.machine()} {platform.processor() or '?'}, cpu_count={os.cpu_count()}, "
        f"torch {torch.__version__}, torch threads={torch.get_num_threads()}, "
        f"load average {os.getloadavg()[0]:.1f} (shared machine: wall times include contention)"
    )
    tmp = Path(tempfile.mkdtemp(prefix="robogs-bench-recon-"))
    print(f"output: {tmp}")
    if args.sfm:
        sfm_route(args, tmp)
        return
    t0 = time.perf_counter()
    truth = synthesize_multiview(
        tmp / "ur5", robot="ur5", n_views=args.views, width=args.width, height=args.height
    )
    print(
        f"scene: UR5 + box + table, {args.views} views {args.width}x{args.height}, "
        f"generated in {time.perf_counter() - t0:.1f} s"
    )
    scene = truth.scene_mesh
    lo, hi = scene.bounds
    diag = float(np.linalg.norm(hi - lo))
    tau = 0.01 * diag * 1e3
    taus = (tau, 5.0)
    if args.skip_tsdf and compare and not args.skip_train:  # 2b scores no meshes
        _append_json(args.json, device_vs_cpu(args, tmp))
        return
    ref, ref_n = truth.visible_surface_points(args.samples)
    print(
        f"scene diagonal {diag:.3f} m -> F-score threshold 1 % = {tau:.2f} mm; "
        f"{len(ref)} visible reference samples"
    )
    if args.skip_tsdf:
        if args.skip_train:
            return
        seeds_vs_trained(args, tmp, scene, ref, ref_n, tau, taus)
        return

    # -- 1. TSDF fusion of the true depths ----------------------------------------------------
    K = truth.K
    cams = [
        Camera(
            width=args.width,
            height=args.height,
            fx=K[0, 0],
            fy=K[1, 1],
            cx=K[0, 2],
            cy=K[1, 2],
            T_world_cam=torch.as_tensor(T),
        )
        for T in truth.T_world_cam
    ]
    depths = [torch.as_tensor(d, dtype=torch.float32) for d in truth._depth]
    pad = 0.03 * (hi - lo).max()
    box_lo, box_hi = lo - pad, hi + pad
    fuse_tsdf(depths[:2], cams[:2], box_lo, box_hi, resolution=32)  # warm-up (allocator, kernels)
    t0 = time.perf_counter()
    vol = fuse_tsdf(depths, cams, box_lo, box_hi, resolution=args.tsdf_res)
    t_ours = time.perf_counter() - t0
    t1 = time.perf_counter()
    mesh_ours, _ = clean_mesh(extract_mesh(vol))
    t_mc = time.perf_counter() - t1
    t0 = time.perf_counter()
    vol_dense = fuse_tsdf(depths, cams, box_lo, box_hi, resolution=args.tsdf_res, narrow_band=False)
    t_dense = time.perf_counter() - t0
    m_ours = _fscore(mesh_ours, ref, ref_n, taus)
    print(
        f"TSDF {vol.dims} voxels of {vol.voxel_size * 1e3:.2f} mm, trunc {vol.trunc * 1e3:.1f} mm, "
        f"{args.views} views:"
    )
    print(
        f"  ours narrow band: fusion {t_ours:.2f} s ({vol.allocated_voxels / np.prod(vol.dims):.1%} of the grid "
        f"allocated), marching cubes + cleaning {t_mc:.2f} s (target fusion <= 10 s)"
    )
    print(
        f"  baseline dense grid: fusion {t_dense:.2f} s -> narrow band is {t_dense / t_ours:.2f}x faster"
    )
    print(
        f"  mesh: F@{tau:.2f}mm {m_ours.fscore[tau]:.4f}, F@5mm {m_ours.fscore[5.0]:.4f}, "
        f"Chamfer-L1 {m_ours.chamfer_l1_mm:.2f} mm, NC {m_ours.normal_consistency:.4f}"
    )
    del vol_dense
    try:
        mesh_o3d, t_o3d, t_o3d_all = _open3d_fusion(
            truth, vol.voxel_size, vol.trunc, box_lo, args.tsdf_res
        )
    except ImportError as exc:
        print(f"  Open3D: not importable ({exc}); no comparison")
    else:
        m_o3d = _fscore(mesh_o3d, ref, ref_n, taus)
        print(
            f"  Open3D {open3d_version()} UniformTSDFVolume {args.tsdf_res}^3: integrate {t_o3d:.2f} s, +extract {t_o3d_all:.2f} s; "
            f"F@{tau:.2f}mm {m_o3d.fscore[tau]:.4f}, F@5mm {m_o3d.fscore[5.0]:.4f}, "
            f"Chamfer-L1 {m_o3d.chamfer_l1_mm:.2f} mm"
        )
        print(
            f"  ratios ours/Open3D: fusion time {t_ours / t_o3d:.2f}, fusion+mesh time "
            f"{(t_ours + t_mc) / t_o3d_all:.2f}, F@1% {m_ours.fscore[tau] / max(m_o3d.fscore[tau], 1e-9):.3f}, "
            f"F@5mm {m_ours.fscore[5.0] / max(m_o3d.fscore[5.0], 1e-9):.3f}"
        )
    if args.skip_train:
        return
    if compare:
        _append_json(args.json, device_vs_cpu(args, tmp))
        return
    seeds_vs_trained(args, tmp, scene, ref, ref_n, tau, taus)


if __name__ == "__main__":
    main()

"""``robogs reconstruct DATASET`` and ``robogs evaluate DATASET`` (routed here by ``robogs.cli``)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError

__all__ = ["add_arguments_for", "run"]


def _rgb(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R,G,B in [0, 1], got {text!r}") from None
    if len(vals) != 3 or not all(0.0 <= v <= 1.0 for v in vals):
        raise argparse.ArgumentTypeError(f"expected R,G,B in [0, 1], got {text!r}")
    return vals  # type: ignore[return-value]


def add_arguments_for(verb: str, p: argparse.ArgumentParser) -> None:
    """Arguments of ``reconstruct`` or ``evaluate``."""
    p.add_argument("dataset", type=Path, help="dataset folder")
    p.add_argument("--episode", help="episode with the static views (default: the only one)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument(
        "--device",
        default="auto",
        help="torch device: auto (cuda when torch sees a GPU, else cpu), cpu, cuda, cuda:1, ...",
    )
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    if verb == "evaluate":
        p.add_argument(
            "--heldout",
            nargs="+",
            metavar="CAMERA/FRAME",
            help="held-out views (default: those the reconstruction left out)",
        )
        p.add_argument("--heldout-every", type=int, help="hold out every n-th static view instead")
        p.add_argument(
            "--reference", type=Path, help="reference mesh (m, world frame) for mesh metrics"
        )
        p.add_argument(
            "--mesh", type=Path, help="mesh to evaluate (default: reconstruction/mesh.ply)"
        )
        p.add_argument(
            "--visible-only",
            action="store_true",
            help="compare only with the reference surface the cameras see",
        )
        p.add_argument("--samples", type=int, default=200_000, help="points sampled per mesh")
        p.add_argument(
            "--tau-mm",
            type=float,
            nargs="+",
            default=[1.0, 2.0, 5.0],
            help="F-score thresholds, mm",
        )
        p.add_argument("--no-images", action="store_true", help="skip the held-out image metrics")
        return
    p.add_argument("--cameras", nargs="+", help="cameras to use (default: all)")
    p.add_argument(
        "--kind", choices=("2dgs", "3dgs"), default="2dgs", help="surfels (default) or 3D Gaussians"
    )
    p.add_argument("--iterations", type=int, default=3000)
    p.add_argument("--sh-degree", type=int, default=0, choices=(0, 1, 2, 3))
    p.add_argument("--lr-scale", type=float, default=1.0, help="multiply every learning rate")
    p.add_argument("--scale", type=float, default=1.0, help="train on images scaled by this factor")
    p.add_argument("--max-views", type=int, help="use at most this many static views")
    p.add_argument(
        "--heldout-every", type=int, default=8, help="hold out every n-th view (0: none)"
    )
    p.add_argument("--init", choices=("auto", "urdf", "hull", "random"), default="auto")
    p.add_argument(
        "--init-assets", action="store_true", help="also seed from existing asset meshes"
    )
    p.add_argument(
        "--carve-tau",
        type=float,
        default=0.03,
        help="colour tolerance (RGB in [0, 1]) of the space carving of the visual-hull seeds; "
        "0: seed on the visual hull itself",
    )
    p.add_argument(
        "--background", type=_rgb, default=(0.0, 0.0, 0.0), help="R,G,B behind the scene"
    )
    p.add_argument("--lambda-dist", type=float, default=10.0, help="depth-distortion weight (m^-2)")
    p.add_argument("--lambda-normal", type=float, default=0.05, help="normal-consistency weight")
    p.add_argument("--tsdf-resolution", type=int, default=128, help="voxels along the longest edge")
    p.add_argument(
        "--drop-depth-edges",
        action="store_true",
        help="do not fuse depth samples on depth edges (thin parts; see docs/reconstruct.md)",
    )
    p.add_argument(
        "--align",
        choices=("report", "apply", "off"),
        default="report",
        help="similarity to the URDF: report it, apply it to splats/meshes/cameras, or skip",
    )
    p.add_argument("--replace-meshes", action="store_true", help="overwrite existing asset meshes")
    p.add_argument(
        "--work-dir",
        type=Path,
        help="checkpoint folder (default: .<dataset>.reconstruct beside it)",
    )
    p.add_argument("--checkpoint-every", type=int, default=500)
    p.add_argument(
        "--backend",
        default="auto",
        help="render backend of training and meshing: auto (triton on CUDA when available, "
        "else torch), torch, triton, ... (robogs plugins lists them)",
    )
    p.add_argument(
        "--log-every",
        type=int,
        default=50,
        help="training steps between progress updates (one device-to-host copy each)",
    )
    p.add_argument("--restart", action="store_true", help="ignore an existing checkpoint")
    p.add_argument("--keep-checkpoint", action="store_true")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    g = p.add_argument_group(
        "coverage and floors",
        "refuse a capture below the coverage before training, and a result below the floors "
        "before writing it (docs/reconstruct.md, 'Coverage and floors')",
    )
    g.add_argument(
        "--force",
        action="store_true",
        help="reconstruct and write anyway (the figures are still reported)",
    )
    g.add_argument("--min-views", type=int, default=8, help="training views per link and object")
    g.add_argument(
        "--min-span-deg", type=float, default=60.0, help="angle spanned by those views, deg"
    )
    g.add_argument("--min-pixels", type=int, default=100, help="pixels for a view to count")
    g.add_argument("--min-psnr", type=float, default=20.0, help="held-out PSNR floor, dB")


def _fmt(x: float, unit: str = "") -> str:
    return (
        "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3f}{unit}"
    )


def resolve_device(name: str) -> str:
    """``auto``: ``cuda`` when torch sees a GPU, else ``cpu``; any other name as given."""
    import torch

    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    return name


def run(args: argparse.Namespace) -> int:
    import torch

    if args.threads is not None:
        if args.threads < 1:
            raise InputError(f"--threads must be >= 1, got {args.threads}")
        torch.set_num_threads(args.threads)
    args.device = resolve_device(args.device)
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(
            f"device {args.device!r} requested but CUDA is not available", where="--device"
        )
    if args.verb == "evaluate":
        return _run_evaluate(args)
    return _run_reconstruct(args)


def _run_reconstruct(args: argparse.Namespace) -> int:
    from robogs.reconstruct.coverage import CoverageThresholds
    from robogs.reconstruct.init import InitConfig
    from robogs.reconstruct.pipeline import ReconstructOptions, reconstruct
    from robogs.reconstruct.quality import QualityFloors, ReconstructionRejected
    from robogs.reconstruct.train import TrainConfig

    if args.iterations < 1:
        raise InputError(f"--iterations must be >= 1, got {args.iterations}")
    if args.log_every < 1:
        raise InputError(f"--log-every must be >= 1, got {args.log_every}", where="--log-every")
    tc = TrainConfig(
        kind=args.kind,
        iterations=args.iterations,
        sh_degree=args.sh_degree,
        seed=args.seed,
        background=args.background,
        lambda_dist=args.lambda_dist,
        lambda_normal=args.lambda_normal,
        checkpoint_every=args.checkpoint_every,
        backend=args.backend,
        log_every=args.log_every,
    )
    opts = ReconstructOptions(
        episode=args.episode,
        cameras=tuple(args.cameras) if args.cameras else None,
        scale=args.scale,
        max_views=args.max_views,
        heldout_every=args.heldout_every,
        train=tc,
        init=InitConfig(
            mode=args.init,
            use_assets=args.init_assets,
            carve_tau=args.carve_tau if args.carve_tau > 0 else None,
            seed=args.seed,
        ),
        lr_scale=args.lr_scale,
        tsdf_resolution=args.tsdf_resolution,
        drop_depth_edges=args.drop_depth_edges,
        align=args.align,
        replace_meshes=args.replace_meshes,
        work_dir=args.work_dir,
        restart=args.restart,
        keep_checkpoint=args.keep_checkpoint,
        device=args.device,
        progress=not args.no_progress and not args.json,
        coverage=CoverageThresholds(
            min_views=args.min_views, min_span_deg=args.min_span_deg, min_pixels=args.min_pixels
        ),
        floors=replace(QualityFloors(), min_psnr_db=args.min_psnr),
        force=args.force,
    )
    try:
        rep = reconstruct(args.dataset, opts)
    except ReconstructionRejected as exc:
        # readable input, a result below its floors: a finding (exit 1), nothing written
        if args.json:
            print(json.dumps({"rejected": exc.message, **exc.figures}, indent=2, default=float))
        print(f"robogs reconstruct: rejected: {exc.one_line()}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(rep.to_json(), indent=2, default=float))
        return 0
    _print_reconstruct(rep)
    return 0


def _print_reconstruct(rep: Any) -> None:
    from rich.console import Console

    c = Console()
    c.print(
        f"[bold]reconstructed[/bold] {rep.dataset}: {len(rep.views_train)} training views, "
        f"{len(rep.views_heldout)} held out, {rep.iterations} steps"
        + (f" (resumed at {rep.resumed_from})" if rep.resumed_from else "")
    )
    c.print(
        f"  training PSNR {rep.train_psnr_db:.2f} dB; Gaussians: "
        + ", ".join(f"{k} {v}" for k, v in rep.gaussians.items())
        + f"; unassigned {rep.gaussians_unassigned}"
    )
    c.print(
        f"  mesh {rep.mesh_faces} faces (removed {rep.clean['small_components']} small components, "
        f"{rep.clean['inner_shells']} inner shells)"
    )
    pre = (rep.alignment or {}).get("sfm_prealign")
    if pre:
        c.print(
            f"  cameras from SfM moved onto the URDF (labelled hull): scale {pre['scale']:.5f}, "
            f"rotation {pre['rotation_deg']:.3f} deg, residual rms {pre['rms_mm']:.2f} mm, "
            f"median {pre['median_mm']:.2f} mm"
        )
    if rep.alignment and "mode" in rep.alignment:
        a = rep.alignment
        c.print(
            f"  alignment to the URDF ({a['mode']}): scale {a['scale']:.5f}, rotation {a['rotation_deg']:.3f} deg, "
            f"residual rms {a['rms_mm']:.2f} mm, median {a['median_mm']:.2f} mm"
        )
        for n in a.get("excluded", []):
            c.print(
                f"  alignment: {n} left out of the fit (below the coverage), median residual "
                f"{a['per_link_median_mm'][n]:.1f} mm"
            )
    for name, sp in (rep.support or {}).items():
        rested = ", ".join(sp["objects_rested"]) or "no object"
        c.print(
            f"  support: {name} top flattened onto its plane at z {sp['height_mm']:.1f} mm "
            f"(free-fit tilt {sp['free_tilt_deg']:.2f} deg, sigma {sp['sigma_mm']:.1f} mm); "
            f"{rested} rest on it"
        )
    c.print(f"  binding residual max {rep.binding_max_mm:.2e} mm; wrote {', '.join(rep.written)}")
    c.print(
        f"  time {rep.timings_s.get('total', 0):.1f} s (train {rep.timings_s.get('train', 0):.1f} s)"
    )
    for p in rep.coverage.get("problems", []):
        c.print(f"[yellow]warning[/yellow] (--force): coverage: {p}")
    for f in rep.quality.get("failures", []):
        c.print(f"[yellow]warning[/yellow] (--force): {f}")


def _run_evaluate(args: argparse.Namespace) -> int:
    from robogs.reconstruct.evaluate import evaluate

    rep = evaluate(
        args.dataset,
        heldout=args.heldout,
        heldout_every=args.heldout_every,
        reference=args.reference,
        mesh=args.mesh,
        visible_only=args.visible_only,
        samples=args.samples,
        taus_mm=tuple(args.tau_mm),
        images=not args.no_images,
        device=args.device,
    )
    if args.json:
        print(json.dumps(rep.to_json(), indent=2, default=float))
        return 0
    from rich.console import Console
    from rich.table import Table

    c = Console()
    if rep.views:
        t = Table(title="held-out views")
        for col in ("view", "PSNR dB", "SSIM", "label mIoU"):
            t.add_column(col)
        for v in rep.views:
            t.add_row(v.key, _fmt(v.psnr_db), _fmt(v.ssim), _fmt(v.miou))
        t.add_row("[bold]mean", _fmt(rep.psnr_db), _fmt(rep.ssim), _fmt(rep.miou))
        c.print(t)
    if rep.mesh is not None:
        m = rep.mesh
        c.print(
            f"mesh vs {rep.reference}: accuracy {_fmt(m.accuracy_mm, ' mm')}, completeness "
            f"{_fmt(m.completeness_mm, ' mm')}, Chamfer-L1 {_fmt(m.chamfer_l1_mm, ' mm')}, "
            f"Chamfer-L2 {_fmt(m.chamfer_l2_mm2, ' mm^2')}, normal consistency {_fmt(m.normal_consistency)}"
        )
        c.print("  F-score " + ", ".join(f"@{k:g} mm {v:.3f}" for k, v in m.fscore.items()))
        rc = rep.robogs_compat or {}
        c.print(
            f"  Robo-GS-compatible reading (assumption: MSE = Chamfer-L2 in m^2, tolerance 1e-5 = squared "
            f"distance, tau {rc.get('tau_mm', float('nan')):.2f} mm): MSE {rc.get('mse_m2', float('nan')):.3e} m^2, "
            f"F {rc.get('fscore', float('nan')):.3f}"
        )
    for n in rep.notes:
        c.print(f"note: {n}")
    return 0

"""``reconstruct``: static views -> Gaussians -> mesh -> links and objects -> binding -> dataset.

Steps (each in its own module):

1. ``views``: read the static views, cameras, labels and the recorded state;
2. ``init`` + ``train``: seed and optimise 2D surfels (or 3D Gaussians), checkpointing;
3. ``tsdf`` + ``mesh_clean``: fuse the rendered median depth of the training views, marching
   cubes, cleaning;
4. ``segment``: label voting assigns mesh vertices and Gaussians to links and objects;
5. ``align``: similarity (Umeyama + ICP) of the link-labelled mesh onto the URDF meshes at the
   recorded joint state; reported in mm, applied to splats, meshes and cameras with
   ``align="apply"``;
6. ``bind``: nearest face, barycentric weights and normal offset on each target's mesh (a
   link's first URDF visual mesh; an object's asset mesh, the reconstructed one when the asset
   has none);
7. ``write``: splats, meshes, binding and a report go into the dataset through the atomic
   writer, in one commit. Nothing in the dataset changes before that commit.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
import trimesh

from robogs.format.dataset import Dataset
from robogs.format.errors import InputError, RobogsError
from robogs.format.frames import matrix_to_quat, quat_multiply, quat_to_matrix
from robogs.format.render import RenderConfig, render
from robogs.format.splats import SplatSet

from .align import AlignmentResult, Similarity, align_to_meshes
from .bind import bind_to_mesh
from .coverage import CoverageThresholds, assess_coverage
from .image_metrics import psnr
from .init import InitConfig, initial_points, initial_tensors
from .mesh_clean import clean_mesh
from .model import GaussianModel, LearningRates
from .prealign import needs_prealign, prealign_json, prealign_sfm
from .quality import QualityFloors, assess_quality
from .robot_geometry import link_meshes
from .segment import TargetMap, drop_fragments, split_mesh, target_map, vote_targets
from .support import fit_support_plane, flatten_table, rest_on_plane
from .train import TrainConfig, TrainResult, resolve_backend, train
from .tsdf import drop_depth_edges, extract_mesh, fuse_tsdf
from .views import Capture, View, load_capture, split_heldout

__all__ = [
    "ReconstructOptions",
    "ReconstructionReport",
    "reconstruct",
    "default_work_dir",
    "REPORT_KEY",
]

#: key of the reconstruction report in ``manifest.provenance``
REPORT_KEY = "reconstruction"


@dataclass(frozen=True)
class ReconstructOptions:
    """Everything ``robogs reconstruct`` can be told.

    Attributes:
        episode: episode with the static views (None: the only one).
        cameras: cameras to use (None: all).
        scale: image scale for training (intrinsics scaled with it).
        max_views: use at most this many static views (evenly spaced).
        heldout_every: every n-th view is held out for ``robogs evaluate`` (0: none).
        train: training options.
        init: initialisation options.
        lr_scale: multiplies every learning rate (short CPU schedules converge faster with 2-3).
        tsdf_resolution: voxels along the longest edge of the fusion box.
        trunc_voxels: TSDF truncation, voxels.
        drop_depth_edges: leave the rendered depth samples on depth edges out of the fusion
            (``tsdf.drop_depth_edges``): thin parts stop growing towards what is behind them,
            but at low resolution every part loses its silhouette rim (docs/reconstruct.md).
        align: ``report`` (fit and report), ``apply`` (also transform splats, meshes, cameras)
            or ``off``.
        replace_meshes: write the reconstructed object meshes over existing asset meshes.
        work_dir: checkpoint folder (None: ``.<dataset>.reconstruct`` beside the dataset).
        restart: ignore an existing checkpoint.
        keep_checkpoint: keep the checkpoint after a successful run.
        device: torch device ("cpu", "cuda", ...).
        progress: show progress bars.
        coverage: what the capture must offer before training (``coverage.py``).
        floors: what the result must reach before it is written (``quality.py``).
        force: reconstruct a capture below ``coverage`` and write a result below ``floors``
            (both are still measured and reported).
    """

    episode: str | None = None
    cameras: tuple[str, ...] | None = None
    scale: float = 1.0
    max_views: int | None = None
    heldout_every: int = 8
    train: TrainConfig = field(default_factory=TrainConfig)
    init: InitConfig = field(default_factory=InitConfig)
    lr_scale: float = 1.0
    tsdf_resolution: int = 128
    trunc_voxels: float = 4.0
    drop_depth_edges: bool = False
    align: str = "report"
    replace_meshes: bool = False
    work_dir: Path | None = None
    restart: bool = False
    keep_checkpoint: bool = False
    device: str = "cpu"
    progress: bool = False
    coverage: CoverageThresholds = field(default_factory=CoverageThresholds)
    floors: QualityFloors = field(default_factory=QualityFloors)
    force: bool = False


@dataclass
class ReconstructionReport:
    """What a reconstruction did and measured (also stored in ``manifest.provenance``)."""

    dataset: str
    views_total: int
    views_train: list[str]
    views_heldout: list[str]
    skipped: dict[str, int]
    iterations: int
    resumed_from: int
    train_psnr_db: float
    refinements: dict[str, int]
    gaussians: dict[str, int]
    gaussians_unassigned: int
    mesh_faces: int
    clean: dict[str, int]
    alignment: dict[str, Any] | None
    binding_max_mm: float
    kind: str
    background: list[float]
    timings_s: dict[str, float]
    written: list[str]
    coverage: dict[str, Any] = field(default_factory=dict)
    quality: dict[str, Any] = field(default_factory=dict)
    support: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def default_work_dir(dataset: Path) -> Path:
    """``.<name>.reconstruct`` beside the dataset folder (never inside it)."""
    dataset = Path(dataset).absolute()
    return dataset.parent / f".{dataset.name}.reconstruct"


def _fingerprint(ds: Dataset, views: list[View], opts: ReconstructOptions) -> str:
    files = ds.files
    rels = sorted({rel for v in views for rel in files if f"/cameras/{v.camera_name}/" in rel})
    doc = {
        # log_every changes when the PSNR is read, not what is trained
        "train": {k: v for k, v in opts.train.to_json().items() if k != "log_every"},
        "init": asdict(opts.init),
        "lr_scale": opts.lr_scale,
        "scale": opts.scale,
        "views": [v.key for v in views],
        "device": opts.device,
        "inputs": {r: files[r].get("sha256") for r in rels},
        "urdf": files.get((ds.manifest.get("robot") or {}).get("urdf", ""), {}).get("sha256"),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _scaled_lrs(lrs: LearningRates, k: float) -> LearningRates:
    if k == 1.0:
        return lrs
    return LearningRates(**{f: getattr(lrs, f) * k for f in lrs.__dataclass_fields__})


@torch.no_grad()
def _render_depths(
    model: GaussianModel,
    views: list[View],
    cfg: TrainConfig,
    drop_edges: bool = False,
    backend: str = "torch",
) -> list[torch.Tensor]:
    """Median depth [H, W] of every view (0 where alpha < 0.5, and on depth edges with
    ``drop_edges``), m."""
    rc = RenderConfig(kind=cfg.kind, background=tuple(cfg.background), validate=False)
    g = model.gaussians()
    out = []
    for v in views:
        r = render(g, v.camera, config=rc, backend=backend)
        d = torch.where(r.alpha >= 0.5, r.depth_median, torch.zeros_like(r.depth_median)).cpu()
        out.append(drop_depth_edges(d) if drop_edges else d)
    return out


def _fusion_box(means: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Robust bounds of the Gaussians (0.5-99.5 percentiles, 5 % margin), inside the workspace."""
    means = means[np.isfinite(means).all(axis=1)]
    if len(means) == 0:
        raise InputError(
            "training diverged: no Gaussian has a finite position",
            hint="lower --lr-scale or check the cameras",
        )
    a, b = np.percentile(means, 0.5, axis=0), np.percentile(means, 99.5, axis=0)
    pad = 0.05 * (b - a).max() + 1e-3
    return np.maximum(a - pad, lo), np.minimum(b + pad, hi)


def _pose_T(pose: list[float]) -> np.ndarray:
    T = np.eye(4)
    q = np.asarray(pose[3:7], np.float64)
    T[:3, :3] = quat_to_matrix(q / np.linalg.norm(q))
    T[:3, 3] = pose[:3]
    return T


def _apply_similarity(model: GaussianModel, S: Similarity) -> None:
    """Move the Gaussians by ``S`` in place: centres, rotations and log-scales."""
    p = model.params
    with torch.no_grad():
        dev = p["means"].device
        M = torch.as_tensor(S.matrix(), dtype=p["means"].dtype, device=dev)
        p["means"].copy_(p["means"] @ M[:3, :3].T + M[:3, 3])
        qR = torch.as_tensor(
            matrix_to_quat(torch.as_tensor(S.R)), dtype=p["quats"].dtype, device=dev
        )
        p["quats"].copy_(quat_multiply(qR.expand_as(p["quats"]), p["quats"]))
        p["log_scales"].add_(float(np.log(S.scale)))
        if p["sh_rest"].shape[1] > 0:
            from robogs.format.binding import rotate_sh

            R = torch.as_tensor(S.R, dtype=p["sh_rest"].dtype, device=dev).expand(len(model), 3, 3)
            sh = rotate_sh(torch.cat([p["sh_dc"], p["sh_rest"]], 1), R)
            p["sh_rest"].copy_(sh[:, 1:])


def _similarity_of_pose(S: Similarity, T: np.ndarray) -> np.ndarray:
    """A camera/world pose moved by the similarity (rotation kept orthonormal)."""
    out = np.eye(4)
    out[:3, :3] = S.R @ T[:3, :3]
    out[:3, 3] = S.apply(T[:3, 3][None])[0]
    return out


def reconstruct(
    path: str | Path, options: ReconstructOptions = ReconstructOptions(), *, on_step: Any = None
) -> ReconstructionReport:
    """Reconstruct the dataset at ``path`` and write splats, meshes and binding into it.

    Args:
        path: dataset folder (changed in one atomic commit at the end).
        options: see :class:`ReconstructOptions`.
        on_step: training callback ``(step, info)`` (for progress or tests).

    Returns:
        The report (also stored as ``manifest.provenance.reconstruction``).

    Raises:
        RobogsError: unusable input (see ``views.load_capture``); KeyboardInterrupt leaves the
            dataset untouched and the checkpoint in the work folder.
    """
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    path = Path(path)
    ds = Dataset.open(path)
    device = torch.device(options.device)
    capture = load_capture(
        ds,
        episode=options.episode,
        cameras=list(options.cameras) if options.cameras else None,
        scale=options.scale,
        max_views=options.max_views,
    )
    prealign: dict[str, Any] | None = None
    if needs_prealign(ds):  # cameras in an SfM frame: move them into the robot's world first
        t0 = time.perf_counter()
        full = capture
        if options.scale != 1.0:  # the hull at full resolution: ~1.5 % of the scene, not ~2 %
            full = load_capture(ds, episode=options.episode, cameras=options.cameras or None)
        pre = prealign_sfm(ds, full)
        with ds.edit() as w:
            _transform_cameras(w, ds, capture, pre.transform)
            prov = dict(w.manifest.get("provenance", {}))
            prealign = prealign_json(pre)
            prov["sfm"] = {
                **prov["sfm"],
                "frame": "robot (labelled hull fitted to the URDF)",
                "prealign": prealign,
            }
            w.manifest["provenance"] = prov
            w.commit()
        ds = Dataset.open(path)
        capture = load_capture(
            ds,
            episode=options.episode,
            cameras=list(options.cameras) if options.cameras else None,
            scale=options.scale,
            max_views=options.max_views,
        )
        timings["prealign"] = time.perf_counter() - t0
    train_views, held = split_heldout(capture.views, options.heldout_every)
    if len(train_views) < 2:
        raise InputError(
            f"only {len(train_views)} training view(s) after holding out every "
            f"{options.heldout_every}-th view",
            hint="lower --heldout-every or add views",
        )
    tcfg = replace(options.train, lrs=_scaled_lrs(options.train.lrs, options.lr_scale))
    backend = resolve_backend(tcfg.backend, device)  # unknown or unavailable: fails here
    timings["load"] = time.perf_counter() - t_start
    # -- coverage: refuse before spending time ----------------------------------------------
    t0 = time.perf_counter()
    lmeshes = (
        link_meshes(ds, capture.joint_positions)
        if ds.manifest.get("robot") and capture.joint_positions
        else {}
    )
    links: set[str] = set()
    if ds.manifest.get("robot"):
        from robogs.format.kinematics import Chain

        links = set(Chain.from_urdf(ds.urdf(load_meshes=False)).link_names)
    tmap = target_map(capture.segments, links)
    coverage = assess_coverage(
        train_views, tmap, _target_centres(ds, capture, lmeshes), options.coverage
    )
    timings["coverage"] = time.perf_counter() - t0
    if not options.force:
        coverage.raise_if_insufficient()
    t0 = time.perf_counter()
    seed_views = train_views
    if options.scale != 1.0:
        # the hull and its carving from the full-resolution views: at half size the 2.5 cm
        # tiles of the sample's table are ~3 px and the carving stopped 2-3 cm above its top;
        # at full size one voxel above (docs/reconstruct.md)
        full = load_capture(
            ds,
            episode=options.episode,
            cameras=list(options.cameras) if options.cameras else None,
            max_views=options.max_views,
        )
        seed_views = split_heldout(full.views, options.heldout_every)[0]
    ip = initial_points(ds, capture, seed_views, options.init)
    init = initial_tensors(
        ip, kind=tcfg.kind, sh_degree=tcfg.sh_degree, seed=options.init.seed, device=device
    )
    lo, hi = ip.lo, ip.hi
    extent = float(np.linalg.norm(hi - lo))
    timings["init"] = time.perf_counter() - t0
    work = Path(options.work_dir) if options.work_dir is not None else default_work_dir(path)
    ckpt = work / "checkpoint.pt"
    if options.restart and ckpt.exists():
        ckpt.unlink()
    # the resolved backend: 'auto' may mean another one where triton is installed later
    fp = _fingerprint(ds, capture.views, replace(options, train=replace(tcfg, backend=backend)))
    t0 = time.perf_counter()
    result: TrainResult = train(
        train_views,
        init,
        tcfg,
        extent=extent,
        checkpoint=ckpt,
        fingerprint=fp,
        progress=options.progress,
        on_step=on_step,
    )
    timings["train"] = time.perf_counter() - t0
    model = result.model
    # -- mesh ---------------------------------------------------------------------------------
    t0 = time.perf_counter()
    depths = _render_depths(model, train_views, tcfg, options.drop_depth_edges, backend)
    means = model.params["means"].detach().cpu().numpy().astype(np.float64)
    flo, fhi = _fusion_box(means, lo, hi)
    vol = fuse_tsdf(
        depths,
        [v.camera for v in train_views],
        flo,
        fhi,
        resolution=options.tsdf_resolution,
        trunc_voxels=options.trunc_voxels,
    )
    raw_mesh = extract_mesh(vol)
    mesh, clean_rep = clean_mesh(raw_mesh, free_space=vol.sample, probe_m=vol.voxel_size)
    timings["mesh"] = time.perf_counter() - t0
    # -- segmentation -----------------------------------------------------------------------------
    t0 = time.perf_counter()
    tol = 2.5 * vol.voxel_size
    v_target, _ = vote_targets(np.asarray(mesh.vertices), train_views, depths, tmap, tol)
    mesh, v_target, clean_rep.fragments = _without_fragments(mesh, v_target)
    g_target, _ = vote_targets(means, train_views, depths, tmap, tol)
    parts = split_mesh(mesh, v_target, len(tmap.names)) if len(mesh.faces) else {}
    timings["segment"] = time.perf_counter() - t0
    # -- floors: refuse to write what is not a reconstruction ------------------------------
    spacing = options.init.spacing_m or extent / 110.0  # the seed spacing of init.py
    quality = assess_quality(
        mesh_faces=len(mesh.faces),
        heldout_psnr_db=_heldout_psnr(model, held, tcfg, backend),
        link_gaussians={
            n: int((g_target == k).sum())
            for k, n in enumerate(tmap.names, start=1)
            if tmap.kinds[k - 1] == "robot_link"
        },
        link_areas_m2={n: float(lm.mesh.area) for n, lm in lmeshes.items()},
        spacing_m=spacing,
        floors=options.floors,
    )
    if not options.force:
        quality.raise_if_failed()  # the checkpoint stays: --force writes without retraining
    # -- alignment ----------------------------------------------------------------------------------
    align_rep: AlignmentResult | None = None
    if options.align != "off" and lmeshes:
        pts = {
            tmap.names[k - 1]: np.asarray(m.vertices)
            for k, m in parts.items()
            if tmap.kinds[k - 1] == "robot_link"
        }
        pts = {n: p for n, p in pts.items() if n in lmeshes}
        # a link below the coverage (only with --force) is a blob seen from one side: it
        # would bias the fit; its residual is reported apart (all of them fit when none is
        # covered)
        poor = {t.name for t in coverage.targets if t.problem(coverage.thresholds)}
        if pts:
            align_rep = align_to_meshes(
                pts,
                {n: lm.world_mesh() for n, lm in lmeshes.items()},
                exclude=poor if set(pts) - poor else (),
            )
            if options.align == "apply":
                S = align_rep.transform
                _apply_similarity(model, S)
                means = model.params["means"].detach().cpu().numpy().astype(np.float64)
                mesh = mesh.copy()
                mesh.apply_transform(S.matrix())
                parts = {k: m.copy().apply_transform(S.matrix()) for k, m in parts.items()}
    # -- support: the reconstructed table is its plane, the objects stand on it ---------------
    parts, support = _rest_on_support(ds, tmap, parts, options.replace_meshes, vol.voxel_size)
    # -- binding and writing ------------------------------------------------------------------------------
    t0 = time.perf_counter()

    def make_report(
        written: list[str], counts: dict[str, int], bind_max: float
    ) -> ReconstructionReport:
        timings["bind_write"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start
        return ReconstructionReport(
            dataset=str(path),
            views_total=len(capture.views),
            views_train=[v.key for v in train_views],
            views_heldout=[v.key for v in held],
            skipped=capture.skipped,
            iterations=result.iterations,
            resumed_from=result.resumed_from,
            train_psnr_db=float(np.mean(result.psnr_history[-20:]))
            if result.psnr_history
            else float("nan"),
            refinements={
                k: int(sum(r[k] for r in result.refinements)) for k in ("cloned", "split", "pruned")
            },
            gaussians=counts,
            gaussians_unassigned=int((g_target == 0).sum()),
            mesh_faces=len(mesh.faces),
            clean=asdict(clean_rep),
            alignment=_align_json(align_rep, options.align)
            if prealign is None
            else {**(_align_json(align_rep, options.align) or {}), "sfm_prealign": prealign},
            binding_max_mm=bind_max,
            kind=tcfg.kind,
            background=list(tcfg.background),
            timings_s=timings,
            written=written,
            coverage=coverage.to_json(),
            quality=quality.to_json(),
            support=support,
        )

    report = _write(
        ds,
        capture,
        model,
        tcfg,
        tmap,
        g_target,
        means,
        mesh,
        parts,
        lmeshes,
        options,
        align_rep,
        held,
        train_views,
        make_report,
    )
    if not options.keep_checkpoint and ckpt.exists():
        ckpt.unlink()
        try:
            work.rmdir()
        except OSError:
            pass
    return report


def _target_centres(
    ds: Dataset, capture: Capture, lmeshes: dict[str, Any]
) -> dict[str, tuple[np.ndarray, str]]:
    """World centres at rest: links' visual mesh centroids (FK), objects' rest poses (m)."""
    out: dict[str, tuple[np.ndarray, str]] = {
        n: (np.asarray(lm.world_mesh().centroid, np.float64), "fk") for n, lm in lmeshes.items()
    }
    for name, pose in capture.object_poses.items():
        T = _pose_T(pose)
        c = T[:3, 3]
        if ds.assets.get(name, {}).get("mesh"):
            try:
                c = T[:3, :3] @ np.asarray(ds.mesh(name).centroid) + T[:3, 3]
            except RobogsError:
                pass  # an unreadable asset mesh is reported where it is used
        out[name] = (np.asarray(c, np.float64), "pose")
    return out


@torch.no_grad()
def _heldout_psnr(
    model: GaussianModel, held: list[View], cfg: TrainConfig, backend: str = "torch"
) -> float:
    """Mean PSNR of the trained model in the held-out views, dB (nan without any)."""
    if not held:
        return float("nan")
    rc = RenderConfig(kind=cfg.kind, background=tuple(cfg.background), validate=False)
    g = model.gaussians()
    vals = [
        psnr(render(g, v.camera, config=rc, backend=backend).rgb.clamp(0, 1).cpu(), v.rgb)
        for v in held
    ]
    return float(np.mean(vals))


def _rest_on_support(
    ds: Dataset,
    tmap: TargetMap,
    parts: dict[int, trimesh.Trimesh],
    replace_meshes: bool,
    voxel_m: float,
) -> tuple[dict[int, trimesh.Trimesh], dict[str, Any]]:
    """Flatten each reconstructed ``table`` part onto its support plane and move the
    reconstructed objects' vertices below it onto it (``support.py``); parts of assets that
    keep their own mesh are left alone. Returns the parts and, per table, the figures (plane
    height in mm along world z, free-fit tilt, robust sigma, vertices moved, faces dropped)."""
    assets = ds.assets

    def reconstructed(k: int) -> bool:
        entry = assets.get(tmap.names[k - 1], {})
        return tmap.kinds[k - 1] == "object" and ("mesh" not in entry or replace_meshes)

    def kind(k: int) -> str | None:
        return assets.get(tmap.names[k - 1], {}).get("kind")

    out = dict(parts)
    report: dict[str, Any] = {}
    for k in [k for k in parts if reconstructed(k) and kind(k) == "table"]:
        m = parts[k]
        fit = fit_support_plane(np.asarray(m.vertices), np.asarray(m.vertex_normals))
        if fit is None:
            continue
        plane, tilt = fit
        out[k], moved, dropped = flatten_table(m, plane, min_band_m=0.5 * voxel_m)
        lo, hi = m.bounds[0, :2], m.bounds[1, :2]
        rested: dict[str, int] = {}
        for j in parts:
            if j == k or not reconstructed(j) or kind(j) == "table":
                continue
            c = parts[j].centroid[:2]
            if (c >= lo).all() and (c <= hi).all():  # stands over this table
                out[j], rested[tmap.names[j - 1]] = rest_on_plane(parts[j], plane)
        c = plane.project(np.asarray(m.vertices).mean(0, keepdims=True))[0]
        report[tmap.names[k - 1]] = {
            **plane.to_json(),
            "height_mm": float(c[2] * 1e3),
            "free_tilt_deg": tilt,
            "vertices_flattened": moved,
            "faces_dropped": dropped,
            "objects_rested": rested,
        }
    return out, report


def _without_fragments(
    mesh: trimesh.Trimesh, v_target: np.ndarray
) -> tuple[trimesh.Trimesh, np.ndarray, int]:
    """The mesh less each target's fragments (:func:`segment.drop_fragments`), the vertex
    targets re-indexed, and the number of faces dropped."""
    if len(mesh.faces) == 0:
        return mesh, v_target, 0
    keep = drop_fragments(mesh, v_target)
    if keep.all():
        return mesh, v_target, 0
    faces = np.asarray(mesh.faces)[keep]
    used = np.unique(faces)
    remap = np.full(len(mesh.vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    out = trimesh.Trimesh(np.asarray(mesh.vertices)[used], remap[faces], process=False)
    return out, np.asarray(v_target)[used], int((~keep).sum())


def _align_json(a: AlignmentResult | None, mode: str) -> dict[str, Any] | None:
    if a is None:
        return None
    S = a.transform
    return {
        "mode": mode,
        "scale": S.scale,
        "rotation_deg": S.rotation_deg,
        "translation_mm": (S.t * 1e3).tolist(),
        "rms_mm": a.rms_mm,
        "median_mm": a.median_mm,
        "p90_mm": a.p90_mm,
        "before_rms_mm": a.before_rms_mm,
        "pairs": a.pairs,
        "iterations": a.iterations,
        "per_link_median_mm": a.per_target_mm,
        "excluded": a.excluded,
        "matrix": S.matrix().tolist(),
    }


def _splat_subset(
    model: GaussianModel,
    idx: np.ndarray,
    bind_id: np.ndarray,
    face: np.ndarray,
    uv: np.ndarray,
    off: np.ndarray,
) -> SplatSet:
    p = {k: v.detach().cpu() for k, v in model.params.items()}
    q = p["quats"][idx]
    q = q / q.norm(dim=1, keepdim=True).clamp(min=1e-12)
    sh = torch.cat([p["sh_dc"], p["sh_rest"]], 1)[idx]
    return SplatSet(
        means=p["means"][idx].numpy().astype(np.float32),
        quats=q.numpy().astype(np.float32),
        log_scales=p["log_scales"][idx].numpy().astype(np.float32),
        opacity_logits=p["opacity_logits"][idx].numpy().astype(np.float32),
        sh=sh.numpy().astype(np.float32),
        bind_id=bind_id.astype(np.int32),
        bind_face=face.astype(np.int32),
        bind_uv=uv.astype(np.float32),
        bind_offset=off.astype(np.float32),
    )


def _write(
    ds: Dataset,
    capture: Capture,
    model: GaussianModel,
    cfg: TrainConfig,
    tmap: TargetMap,
    g_target: np.ndarray,
    means: np.ndarray,
    mesh: trimesh.Trimesh,
    parts: dict[int, trimesh.Trimesh],
    lmeshes: dict[str, Any],
    options: ReconstructOptions,
    align: AlignmentResult | None,
    held: list[View],
    train_views: list[View],
    make_report: Any,
) -> ReconstructionReport:
    rest: dict[str, Any] = {"t_ns": int(capture.rest_t_ns)}
    if capture.joint_positions:
        rest["joint_positions"] = dict(capture.joint_positions)
    if capture.object_poses:
        rest["object_poses"] = {k: list(v) for k, v in capture.object_poses.items()}
    written: list[str] = []
    counts: dict[str, int] = {}
    bind_max = 0.0
    apply = options.align == "apply" and align is not None
    with ds.edit() as w:
        # robot
        link_ids = [k for k in range(1, len(tmap.names) + 1) if tmap.kinds[k - 1] == "robot_link"]
        if link_ids:
            targets = [tmap.names[k - 1] for k in link_ids]
            sel_all, bid, faces, uvs, offs = [], [], [], [], []
            for j, k in enumerate(link_ids):
                sel = np.flatnonzero(g_target == k)
                if len(sel) == 0:
                    continue
                name = tmap.names[k - 1]
                counts[name] = len(sel)
                if name in lmeshes:
                    wm = lmeshes[name].world_mesh()
                    f, uv, off = bind_to_mesh(means[sel], wm)
                    bind_max = max(bind_max, _bind_residual_mm(wm, means[sel], f, uv, off))
                else:
                    f, uv, off = np.full(len(sel), -1), np.zeros((len(sel), 2)), np.zeros(len(sel))
                sel_all.append(sel)
                bid.append(np.full(len(sel), j))
                faces.append(f)
                uvs.append(uv)
                offs.append(off)
            if sel_all:
                idx = np.concatenate(sel_all)
                w.write_splats(
                    "robot/splats.ply",
                    _splat_subset(
                        model,
                        idx,
                        np.concatenate(bid),
                        np.concatenate(faces),
                        np.concatenate(uvs),
                        np.concatenate(offs),
                    ),
                )
                robot = dict(w.manifest.get("robot", {}))
                robot["splats"] = {
                    "path": "robot/splats.ply",
                    "kind": cfg.kind,
                    "sh_degree": cfg.sh_degree,
                    "targets": targets,
                    "rest": rest,
                }
                w.manifest["robot"] = robot
                written.append("robot/splats.ply")
            for k in link_ids:
                name = tmap.names[k - 1]
                if k in parts and name in lmeshes:
                    T_inv = np.linalg.inv(lmeshes[name].T_world_link)
                    rel = f"reconstruction/links/{name}.ply"
                    w.write_bytes(
                        rel, parts[k].copy().apply_transform(T_inv).export(file_type="ply")
                    )
                    written.append(rel)
        # objects
        assets = ds.assets
        for k in range(1, len(tmap.names) + 1):
            if tmap.kinds[k - 1] != "object":
                continue
            name = tmap.names[k - 1]
            sel = np.flatnonzero(g_target == k)
            if len(sel) == 0:
                continue
            entry = dict(assets.get(name, {}))
            pose = capture.object_poses.get(name)
            T_rest = _pose_T(pose) if pose is not None else np.eye(4)
            kind = entry.get("kind") or ("object" if pose is not None else "background")
            if kind == "object" and pose is None:
                raise InputError(
                    f"object {name!r} has no pose stream; its splats could not follow it",
                    hint="record object_poses for it, or declare it a table/background asset",
                )
            mesh_rel = entry.get("mesh")
            if k in parts and (mesh_rel is None or options.replace_meshes):
                mesh_rel = f"assets/{name}/mesh.ply"
                w.write_bytes(
                    mesh_rel,
                    parts[k].copy().apply_transform(np.linalg.inv(T_rest)).export(file_type="ply"),
                )
                written.append(mesh_rel)
                world = parts[k]
            elif mesh_rel is not None:
                world = ds.mesh(name).copy().apply_transform(T_rest)
            else:
                world = None
            if world is not None:
                f, uv, off = bind_to_mesh(means[sel], world)
                bind_max = max(bind_max, _bind_residual_mm(world, means[sel], f, uv, off))
            else:
                f, uv, off = np.full(len(sel), -1), np.zeros((len(sel), 2)), np.zeros(len(sel))
            counts[name] = len(sel)
            rel = f"assets/{name}/splats.ply"
            w.write_splats(rel, _splat_subset(model, sel, np.zeros(len(sel)), f, uv, off))
            written.append(rel)
            splats = {
                "path": rel,
                "kind": cfg.kind,
                "sh_degree": cfg.sh_degree,
                "targets": [name],
                "rest": rest,
            }
            fields: dict[str, Any] = {"kind": kind, "splats": splats}
            if mesh_rel is not None:
                fields["mesh"] = mesh_rel
            w.set_asset(name, **fields)
        w.write_bytes("reconstruction/mesh.ply", mesh.export(file_type="ply"))
        written.append("reconstruction/mesh.ply")
        if apply:
            _transform_cameras(w, ds, capture, align.transform)
        prov = dict(w.manifest.get("provenance", {}))
        prov[REPORT_KEY] = {
            "heldout": [v.key for v in held],
            "train": [v.key for v in train_views],
            "episode": capture.episode.id,
            "kind": cfg.kind,
            "background": list(cfg.background),
            "scale": options.scale,
        }
        report = make_report(written, counts, bind_max)
        prov[REPORT_KEY]["report"] = json.loads(json.dumps(report.to_json(), default=float))
        w.manifest["provenance"] = prov
        w.commit()
    return report


def _bind_residual_mm(
    mesh: trimesh.Trimesh, pts: np.ndarray, f: np.ndarray, uv: np.ndarray, off: np.ndarray
) -> float:
    from .bind import bound_positions

    ok = f >= 0
    if not ok.any():
        return 0.0
    p = bound_positions(mesh, f[ok], uv[ok], off[ok])
    return float(np.linalg.norm(p - pts[ok], axis=1).max() * 1e3)


def _transform_cameras(w: Any, ds: Dataset, capture: Capture, S: Similarity) -> None:
    """Move every camera of the dataset by ``S`` (static poses and extrinsics tables)."""
    import pyarrow as pa

    from robogs.format.dataset import read_parquet

    for name in ds.camera_names:
        cam = ds.camera(name)
        if cam.T_world_cam is not None:
            w.set_camera(
                replace(cam, T_world_cam=_similarity_of_pose(S, np.asarray(cam.T_world_cam)))
            )
    for ep in ds.episodes:
        for st in ep.streams.values():
            rel = st.get("extrinsics")
            if st.get("kind") != "camera" or not isinstance(rel, str):
                continue
            tab = read_parquet(ds.resolve(rel))
            xyz = np.stack([tab.column(c).to_numpy() for c in "xyz"], -1)
            q = np.stack([tab.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
            Rm = quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))
            R2 = np.einsum("ij,njk->nik", S.R, Rm)
            q2 = matrix_to_quat(R2)
            p2 = S.apply(xyz)
            cols = {"t_ns": tab.column("t_ns")}
            cols.update({c: pa.array(p2[:, i]) for i, c in enumerate("xyz")})
            cols.update({c: pa.array(q2[:, i]) for i, c in enumerate(("qw", "qx", "qy", "qz"))})
            w.write_table(rel, pa.table(cols), kind="camera_extrinsics")

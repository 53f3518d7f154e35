"""``robogs evaluate``: image metrics on held-out views and mesh metrics against a reference.

Image metrics render the dataset's *bound* Gaussians (posed through the binding at each view's
stamp, so the whole Gaussian–Mesh–Pixel chain is evaluated) into the held-out views and compare
with the recorded frames and labels: PSNR, SSIM (``image_metrics``) and the label IoU per link
and object (argmax over "nothing" = 1 - rendered label mass and the one-hot label channels
rendered with the colour). The report's IoU per label pools intersections and unions over all
held-out views (as PASCAL VOC does), and mIoU is their mean; per-view values are kept too.
Held-out views default to those the reconstruction left out
(``manifest.provenance.reconstruction.heldout``).

Mesh metrics compare ``reconstruction/mesh.ply`` (or ``mesh=``) with a reference mesh
(``mesh_metrics``). With ``visible_only`` the reference keeps only the samples that some camera
of the episode sees (a point z-buffer of the reference samples per view, 1 % depth tolerance),
like the observation masks of the DTU benchmark: surfaces no camera saw cannot be reconstructed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import trimesh

from robogs.format.binding import Binding
from robogs.format.dataset import Dataset
from robogs.format.errors import FormatError, InputError
from robogs.format.meshes import load_mesh
from robogs.format.render import Camera, Gaussians, RenderConfig, render
from robogs.format.rerender import label_channels

from .image_metrics import label_iou, psnr, ssim
from .mesh_metrics import MeshMetrics, point_metrics, robogs_compat, sample_mesh
from .pipeline import REPORT_KEY
from .views import View, load_capture, split_heldout

__all__ = ["ViewMetrics", "EvaluationReport", "evaluate", "visible_mask"]


@dataclass
class ViewMetrics:
    """Metrics of one held-out view: IoU per label id, and the pixel counts behind it."""

    key: str
    psnr_db: float
    ssim: float
    miou: float
    iou: dict[int, float]
    inter: dict[int, int] = field(default_factory=dict)
    union: dict[int, int] = field(default_factory=dict)


@dataclass
class EvaluationReport:
    """Everything ``robogs evaluate`` measured."""

    dataset: str
    views: list[ViewMetrics] = field(default_factory=list)
    psnr_db: float = float("nan")
    ssim: float = float("nan")
    miou: float = float("nan")
    iou: dict[int, float] = field(default_factory=dict)
    mesh: MeshMetrics | None = None
    robogs_compat: dict[str, float] | None = None
    reference: str | None = None
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["mesh"] = None if self.mesh is None else self.mesh.to_json()
        return d


@torch.no_grad()
def visible_mask(points: np.ndarray, cameras: list[Camera], *, rel_tol: float = 0.01) -> np.ndarray:
    """[N] bool: points that are frontmost at their pixel in at least one camera (point z-buffer)."""
    P = torch.as_tensor(points, dtype=torch.float32)
    seen = torch.zeros(len(P), dtype=torch.bool)
    for cam in cameras:
        T = cam.T_world_cam.to(torch.float32)
        pc = (P - T[:3, 3]) @ T[:3, :3]
        z = pc[:, 2]
        zs = torch.where(z > 1e-9, z, torch.ones_like(z))
        u = torch.floor(cam.fx * pc[:, 0] / zs + cam.cx).long()
        v = torch.floor(cam.fy * pc[:, 1] / zs + cam.cy).long()
        inside = (z > 1e-9) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
        pix = v.clamp(0, cam.height - 1) * cam.width + u.clamp(0, cam.width - 1)
        zbuf = torch.full((cam.width * cam.height,), float("inf"), dtype=torch.float32)
        zbuf.scatter_reduce_(0, pix[inside], z[inside], reduce="amin")
        seen |= inside & (z <= zbuf[pix] * (1.0 + rel_tol))
    return seen.numpy()


def _heldout_views(
    ds: Dataset, views: list[View], heldout: list[str] | None, every: int | None
) -> list[View]:
    by_key = {v.key: v for v in views}
    if heldout:
        missing = [k for k in heldout if k not in by_key]
        if missing:
            raise InputError(
                f"held-out view(s) {', '.join(missing[:5])} are not static views of the episode",
                hint="name views as <camera>/<frame_index>",
            )
        return [by_key[k] for k in heldout]
    if every:
        return split_heldout(views, every)[1]
    rec = (ds.manifest.get("provenance") or {}).get(REPORT_KEY) or {}
    keys = [k for k in rec.get("heldout", []) if k in by_key]
    if not keys:
        raise InputError(
            "no held-out views: the reconstruction recorded none",
            hint="pass --heldout CAMERA/FRAME ... or --heldout-every N",
        )
    return [by_key[k] for k in keys]


def _image_metrics(ds: Dataset, views: list[View], episode: str, device: str) -> list[ViewMetrics]:
    rec = (ds.manifest.get("provenance") or {}).get(REPORT_KEY) or {}
    bg = tuple(float(x) for x in rec.get("background", (0.0, 0.0, 0.0)))
    b = Binding(ds, episode, device=device)
    seg_name = next((n for n, s in b.episode.streams.items() if s.get("kind") == "segments"), None)
    channels = label_channels(b, b.episode.table(seg_name)) if seg_name is not None else None
    tid = b.target_index
    extra = None
    if channels is not None and channels.count:
        ch = torch.as_tensor(channels.target_channel, device=tid.device)[tid.clamp(min=0)]
        ch = torch.where(tid >= 0, ch, torch.zeros_like(ch))
        onehot = torch.zeros(
            len(tid), channels.count + 1, dtype=b.rest.means.dtype, device=tid.device
        )
        onehot[torch.arange(len(tid), device=tid.device), ch] = 1.0
        extra = onehot[:, 1:].contiguous()
    cfg = RenderConfig(kind=b.rest.kind, background=bg, validate=False)
    out: list[ViewMetrics] = []
    for v in views:
        g = b.pose(v.t_ns)
        g = Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, g.sh, extra=extra)
        with torch.no_grad():
            r = render(g, v.camera, config=cfg)
        rgb = r.rgb.clamp(0, 1).cpu().to(torch.float64)
        target = v.rgb.to(torch.float64)
        p = psnr(rgb, target)
        s = float(ssim(rgb, target))
        miou, ious = float("nan"), {}
        if v.labels is not None and extra is not None:
            e = r.extra.cpu().numpy()
            probs = np.concatenate([np.clip(1.0 - e.sum(-1, keepdims=True), 0, 1), e], -1)
            idx = probs.argmax(-1)
            lut = np.concatenate([[0], channels.label_ids])
            pred = lut[idx]
            truth = np.where(np.isin(v.labels, channels.label_ids), v.labels, 0)
            present = sorted(set(np.unique(pred).tolist() + np.unique(truth).tolist()) - {0})
            ious = label_iou(pred, truth, present)
            miou = float(np.mean(list(ious.values()))) if ious else float("nan")
            inter = {lab: int(((pred == lab) & (truth == lab)).sum()) for lab in present}
            union = {lab: int(((pred == lab) | (truth == lab)).sum()) for lab in present}
            out.append(ViewMetrics(v.key, p, s, miou, ious, inter, union))
            continue
        out.append(ViewMetrics(v.key, p, s, miou, ious))
    return out


def evaluate(
    path: str | Path,
    *,
    heldout: list[str] | None = None,
    heldout_every: int | None = None,
    reference: str | Path | None = None,
    mesh: str | Path | None = None,
    visible_only: bool = False,
    samples: int = 200_000,
    taus_mm: tuple[float, ...] = (1.0, 2.0, 5.0),
    images: bool = True,
    device: str = "cpu",
) -> EvaluationReport:
    """Evaluate a reconstructed dataset (see the module docstring).

    Raises:
        InputError: unknown held-out views, no splats, unreadable meshes.
    """
    path = Path(path)
    ds = Dataset.open(path)
    rep = EvaluationReport(dataset=str(path))
    rec = (ds.manifest.get("provenance") or {}).get(REPORT_KEY) or {}
    capture = None
    if images or visible_only:
        capture = load_capture(
            ds, episode=rec.get("episode"), scale=float(rec.get("scale", 1.0)), require_labels=False
        )
    if images:
        views = _heldout_views(ds, capture.views, heldout, heldout_every)
        try:
            rep.views = _image_metrics(ds, views, capture.episode.id, device)
        except FormatError as exc:
            if "has no splats" not in exc.message:
                raise
            raise InputError(
                "the dataset has no splats to evaluate",
                path=path,
                hint="run robogs reconstruct first",
            ) from None
        rep.psnr_db = float(np.mean([m.psnr_db for m in rep.views]))
        rep.ssim = float(np.mean([m.ssim for m in rep.views]))
        inter: dict[int, int] = {}
        union: dict[int, int] = {}
        for m in rep.views:
            for lab, n in m.inter.items():
                inter[lab] = inter.get(lab, 0) + n
                union[lab] = union.get(lab, 0) + m.union[lab]
        rep.iou = {lab: inter[lab] / union[lab] for lab in sorted(union) if union[lab] > 0}
        rep.miou = float(np.mean(list(rep.iou.values()))) if rep.iou else float("nan")
    if reference is not None:
        pred_path = Path(mesh) if mesh is not None else ds.resolve("reconstruction/mesh.ply")
        pred = _load_mesh(pred_path)
        ref = _load_mesh(Path(reference))
        p, pn = sample_mesh(pred, samples, 0)
        r, rn = sample_mesh(ref, samples, 1)
        if visible_only:
            keep = visible_mask(r, [v.camera for v in capture.views])
            rep.notes.append(
                f"reference restricted to the {keep.mean():.1%} of its surface the cameras see"
            )
            r, rn = r[keep], rn[keep]
        rep.mesh = point_metrics(p, r, pred_normals=pn, ref_normals=rn, taus_mm=taus_mm)
        rep.robogs_compat = robogs_compat(p, r)
        rep.reference = str(reference)
    return rep


def _load_mesh(path: Path) -> trimesh.Trimesh:
    return load_mesh(path, error=InputError, process=True)

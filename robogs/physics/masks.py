"""Mask-boundary stream: the bound Gaussians re-rendered into the recorded panoptic masks.

For a dataset with cameras, panoptic label images, a ``segments`` table and a Gaussian binding,
every compared frame (``max_frames`` spread evenly over each camera stream) is rendered with the
Gaussians posed at the frame's stamp: robot links by forward kinematics of the measured joints,
objects at the poses given in ``object_poses`` (a model's prediction) or, without them, at their
recorded poses. Per camera and per link/object the stream reports the mean symmetric boundary
distance [px] and [mm] (px converted at the rendered depth) and the IoU outside a void band.

The rendering and the per-frame measurements are the validator's
(:mod:`robogs.format.rerender`: :class:`~robogs.format.rerender.SceneRerenderer`,
:func:`~robogs.format.rerender.compare_frame`, :func:`~robogs.format.rerender.boundary_mm`), so
``compare`` and ``robogs validate`` (B002/B003) measure the same thing.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

import cv2
import numpy as np

from robogs.format.cameras import CameraModel
from robogs.format.errors import RobogsError

__all__ = [
    "MAX_FRAMES",
    "LabelBoundary",
    "MaskStream",
    "RenderedFrame",
    "mask_absent_reason",
    "rendered_frames",
    "mask_boundary",
    "safe_mask_boundary",
    "ObjectPoses",
]

#: frames compared per camera stream by default (spread evenly over the stream)
MAX_FRAMES = 30
#: renders wider than this many pixels are made at a reduced scale (compared at full size)
MAX_RENDER_WIDTH = 640

#: episode id -> object name -> (t_ns [N], xyz [N, 3] m, qwxyz [N, 4])
ObjectPoses = dict[str, dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]


@dataclass
class LabelBoundary:
    """Boundary agreement of one link or object in one camera, pooled over episodes and frames.

    Attributes:
        camera: camera name.
        label: link or object name.
        kind: ``robot_link``, ``object`` or ``static``.
        frames: frames compared.
        boundary_px: mean symmetric boundary distance, px (NaN without boundaries).
        boundary_mm: the same at the rendered depth, mm.
        iou: intersection over union outside the void band (NaN without pixels).
        pixels: non-void union summed over the frames, px.
    """

    camera: str
    label: str
    kind: str
    frames: int
    boundary_px: float
    boundary_mm: float
    iou: float
    pixels: int


@dataclass
class MaskStream:
    """The mask-boundary stream of ``compare``.

    Attributes:
        labels: one row per camera and link/object.
        cameras: per camera, pooled ``boundary_px``, ``boundary_mm``, ``iou`` and ``frames``.
        boundary_px / boundary_mm: pooled over every camera and label.
        object_poses: ``"model"`` (objects at the model's predicted poses) or ``"recorded"``.
        frames: frames compared in all.
        seconds: wall time of the renders and comparisons.
        notes: frames or cameras left out, and why.
    """

    labels: list[LabelBoundary]
    cameras: dict[str, dict[str, float]]
    boundary_px: float
    boundary_mm: float
    object_poses: str
    frames: int
    seconds: float
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN as None)."""

        def fin(x: Any) -> Any:
            return None if isinstance(x, float) and not np.isfinite(x) else x

        return {
            "labels": [{k: fin(v) for k, v in asdict(r).items()} for r in self.labels],
            "cameras": {c: {k: fin(v) for k, v in d.items()} for c, d in self.cameras.items()},
            "boundary_px": fin(self.boundary_px),
            "boundary_mm": fin(self.boundary_mm),
            "object_poses": self.object_poses,
            "frames": self.frames,
            "seconds": self.seconds,
            "notes": self.notes,
        }


@dataclass
class RenderedFrame:
    """One compared frame.

    Attributes:
        episode / stream: where it comes from.
        camera: the camera model it was rendered with.
        names / kinds: [C] link/object name and kind of label channel c+1.
        t_ns / frame_index: the frame.
        recorded: [H, W] int channel of every recorded pixel (0: none).
        rendered: [H, W] int channel of the re-render (argmax, recorded resolution).
        depth: [H, W] rendered median depth, m (0 where nothing was hit).
        inter, union, bsum, bcnt, depth_label: the validator's per-label measurements
            (:class:`robogs.format.rerender.FrameMetrics`), [C] each.
    """

    episode: str
    stream: str
    camera: CameraModel
    names: list[str]
    kinds: list[str]
    t_ns: int
    frame_index: int
    recorded: np.ndarray
    rendered: np.ndarray
    depth: np.ndarray
    inter: np.ndarray
    union: np.ndarray
    bsum: np.ndarray
    bcnt: np.ndarray
    depth_label: np.ndarray


def _camera_streams(ds: Any) -> list[tuple[Any, str, dict[str, Any]]]:
    return [
        (ep, name, st)
        for ep in ds.episodes
        for name, st in ep.streams.items()
        if st.get("kind") == "camera"
        and all(isinstance(st.get(k), str) for k in ("camera", "frames", "labels"))
    ]


def _has_splats(ds: Any) -> bool:
    robot = ds.manifest.get("robot") or {}
    return "splats" in robot or any("splats" in a for a in ds.assets.values())


def _segments_stream(ep: Any) -> str | None:
    return next((n for n, s in ep.streams.items() if s.get("kind") == "segments"), None)


def mask_absent_reason(ds: Any) -> str | None:
    """Why a dataset has no mask-boundary stream (None when it has one)."""
    if ds is None:
        return "an in-memory recording has no cameras or masks"
    streams = _camera_streams(ds)
    if not streams:
        return "no camera stream with panoptic label images"
    if not _has_splats(ds):
        return "no Gaussian binding (no splats bound to links or objects)"
    if not any(_segments_stream(ep) for ep, _, _ in streams):
        return "no segments table mapping label ids to links and objects"
    return None


def _frame_table(ds: Any, ep: Any, st: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    from robogs.format.dataset import read_parquet

    tab = read_parquet(ds.resolve(st["frames"]), columns=["t_ns", "frame_index"])
    return (
        tab.column("t_ns").to_numpy().astype(np.int64),
        tab.column("frame_index").to_numpy().astype(np.int64),
    )


def _spread(n: int, k: int) -> np.ndarray:
    """Up to ``k`` indices of ``range(n)`` spread evenly (first and last included)."""
    if n <= k:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, k)).astype(np.int64))


def _pose_of(ds: Any, ep: Any, st: dict[str, Any], model: CameraModel) -> Any:
    if model.extrinsics != "time_varying":
        return None
    from robogs.format.dataset import read_parquet
    from robogs.format.rerender import pose_stream

    tab = read_parquet(ds.resolve(st["extrinsics"]))
    col = lambda *c: np.stack([tab.column(x).to_numpy().astype(float) for x in c], -1)  # noqa: E731
    return pose_stream(
        tab.column("t_ns").to_numpy().astype(np.int64),
        col("x", "y", "z"),
        col("qw", "qx", "qy", "qz"),
    )


def rendered_frames(
    ds: Any,
    *,
    max_frames: int = MAX_FRAMES,
    object_poses: ObjectPoses | None = None,
    cameras: dict[str, CameraModel] | None = None,
    notes: list[str] | None = None,
) -> Iterator[RenderedFrame]:
    """Re-render up to ``max_frames`` frames of every labelled camera stream, compared.

    Args:
        ds: the dataset.
        max_frames: frames per camera stream, spread evenly over it.
        object_poses: poses objects follow instead of their recorded streams.
        cameras: camera models to render with instead of the stored ones (by name).
        notes: collects streams and frames that were left out, with the reason.

    Yields:
        One :class:`RenderedFrame` per compared frame, stream by stream, in time order.
    """
    import torch

    from robogs.format.binding import Binding
    from robogs.format.dataset import read_parquet
    from robogs.format.rerender import (
        SceneRerenderer,
        compare_frame,
        label_channels,
        read_label_frames,
    )

    notes = notes if notes is not None else []
    bindings: dict[str, Binding] = {}
    for ep, name, st in _camera_streams(ds):
        seg = _segments_stream(ep)
        model = (cameras or {}).get(st["camera"]) or ds.camera(st["camera"])
        if seg is None:
            notes.append(f"{ep.id}/{name}: no segments table")
            continue
        if model.T_world_cam is None and model.extrinsics != "time_varying":
            notes.append(f"{ep.id}/{name}: camera {model.name!r} has no extrinsics")
            continue
        if ep.id not in bindings:
            b = Binding(ds, ep.id)
            for obj, (t, xyz, q) in ((object_poses or {}).get(ep.id) or {}).items():
                if any(tg.name == obj and tg.kind == "object" for tg in b.targets):
                    b.set_object_poses(obj, t, xyz, q)
            bindings[ep.id] = b
        b = bindings[ep.id]
        channels = label_channels(b, read_parquet(ds.resolve(ep.stream(seg)["path"])))
        if channels.count == 0:
            notes.append(f"{ep.id}/{name}: no bound target has a label id")
            continue
        if model.extrinsics == "time_varying" and not isinstance(st.get("extrinsics"), str):
            notes.append(f"{ep.id}/{name}: time-varying camera without an extrinsics table")
            continue
        scale = min(1.0, MAX_RENDER_WIDTH / model.width)
        try:
            rr = SceneRerenderer(
                b, model, channels, scale=scale, pose_of=_pose_of(ds, ep, st, model)
            )
        except (ValueError, TypeError) as exc:  # degenerate camera values (validator: B009)
            notes.append(f"{ep.id}/{name}: camera {model.name!r} cannot be rendered ({exc})")
            continue
        lut = channels.lookup()
        t, fi = _frame_table(ds, ep, st)
        pick = _spread(len(t), max_frames)
        pos = {int(fi[k]): int(k) for k in pick}
        for i, lab in read_label_frames(ds.resolve(st["labels"]), fi[pick]):
            if lab.shape != (model.height, model.width):
                notes.append(f"{ep.id}/{name} frame {i}: label image size differs from the camera")
                continue
            k = pos.pop(i, None)
            if k is None:
                continue
            with torch.no_grad():
                out = rr.render(int(t[k]))
            p = rr.probabilities(out)
            d_med = out.depth_median.detach().cpu().numpy()
            rec = lut[lab]
            m = compare_frame(p, d_med, rec, channels.count)
            H, W = rec.shape
            # the rendered label image at the recorded size, as compare_frame makes it
            up = p if p.shape[:2] == (H, W) else cv2.resize(p, (W, H), cv2.INTER_LINEAR)
            depth = d_med if d_med.shape == (H, W) else cv2.resize(d_med, (W, H), cv2.INTER_NEAREST)
            yield RenderedFrame(
                ep.id,
                name,
                model,
                list(channels.names),
                list(channels.kinds),
                int(t[k]),
                i,
                rec,
                up.reshape(H, W, -1).argmax(-1),
                depth,
                m.inter,
                m.union,
                m.boundary_sum,
                m.boundary_count,
                m.depth_m,
            )
        if pos:
            notes.append(f"{ep.id}/{name}: {len(pos)} frames have no label image")


def mask_boundary(
    ds: Any,
    *,
    max_frames: int = MAX_FRAMES,
    object_poses: ObjectPoses | None = None,
    cameras: dict[str, CameraModel] | None = None,
) -> MaskStream:
    """Per camera and link/object boundary distance [px, mm] and IoU of the re-render.

    Args:
        ds: a dataset with cameras, label images, segments and a binding
            (see :func:`mask_absent_reason`).
        max_frames: frames per camera stream.
        object_poses: object poses to render (a model's prediction); None: the recorded ones.
        cameras: camera models to use instead of the stored ones.
    """
    from robogs.format.rerender import boundary_mm

    t0 = time.perf_counter()
    notes: list[str] = []
    # per (camera, label): sums of inter, union, bsum, bcnt, boundary mm, frames
    acc: dict[tuple[str, str], np.ndarray] = {}
    kind_of: dict[tuple[str, str], str] = {}
    per_stream: dict[tuple[str, str], list[RenderedFrame]] = {}
    n = 0
    for fr in rendered_frames(
        ds, max_frames=max_frames, object_poses=object_poses, cameras=cameras, notes=notes
    ):
        fr.recorded = fr.rendered = fr.depth = np.zeros(0)  # keep only the measurements
        per_stream.setdefault((fr.episode, fr.stream), []).append(fr)
        n += 1
    for frames in per_stream.values():
        cam = frames[0].camera
        bsum = np.stack([f.bsum for f in frames])
        mm = boundary_mm(bsum, np.stack([f.depth_label for f in frames]), cam.fx)
        for c, name in enumerate(frames[0].names):
            key = (cam.name, name)
            kind_of[key] = frames[0].kinds[c]
            a = acc.setdefault(key, np.zeros(6))
            a += [
                sum(f.inter[c] for f in frames),
                sum(f.union[c] for f in frames),
                bsum[:, c].sum(),
                sum(f.bcnt[c] for f in frames),
                float(np.nansum(mm[:, c])),
                len(frames),
            ]

    def row(a: np.ndarray) -> tuple[float, float, float]:
        px = a[2] / a[3] if a[3] else float("nan")
        mm_ = a[4] / a[3] if a[3] else float("nan")
        iou = a[0] / a[1] if a[1] else float("nan")
        return float(px), float(mm_), float(iou)

    labels = []
    for key, a in acc.items():
        px, mm_, iou = row(a)
        labels.append(
            LabelBoundary(key[0], key[1], kind_of[key], int(a[5]), px, mm_, iou, int(a[1]))
        )
    cams: dict[str, dict[str, float]] = {}
    for cam in sorted({k[0] for k in acc}):
        tot = sum(a for k, a in acc.items() if k[0] == cam)
        px, mm_, iou = row(tot)
        frames = sum(len(v) for v in per_stream.values() if v[0].camera.name == cam)
        cams[cam] = {"boundary_px": px, "boundary_mm": mm_, "iou": iou, "frames": frames}
    tot = sum(acc.values()) if acc else np.zeros(6)
    px, mm_, _ = row(tot)
    return MaskStream(
        labels=labels,
        cameras=cams,
        boundary_px=px,
        boundary_mm=mm_,
        object_poses="recorded" if object_poses is None else "model",
        frames=n,
        seconds=time.perf_counter() - t0,
        notes=notes,
    )


def safe_mask_boundary(ds: Any, **kwargs: Any) -> tuple[MaskStream | None, str | None]:
    """:func:`mask_boundary`, or ``(None, reason)`` when the dataset has no usable masks."""
    why = mask_absent_reason(ds)
    if why is not None:
        return None, why
    try:
        res = mask_boundary(ds, **kwargs)
    except RobogsError as exc:
        return None, f"masks could not be re-rendered: {exc.one_line()}"
    if res.frames == 0:
        return None, "no frame could be compared (" + "; ".join(res.notes[:3]) + ")"
    return res, None

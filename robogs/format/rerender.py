"""Re-render validation: pose the bound Gaussians at each frame's stamp and compare with the labels.

The Gaussian–Mesh–Pixel binding of Robo-GS (Lou et al. 2024) is only right if the Gaussians,
posed by forward kinematics and object poses at a frame's stamp and rendered into the recorded
camera, land on the pixels the recorded panoptic labels give their link or object. This module
does that comparison:

* :class:`SceneRerenderer` renders one camera of one episode: the Gaussians of every bound target
  carry a one-hot ``extra`` channel per label (targets map to label ids through the episode's
  ``segments`` table), so one render gives soft label probabilities ``p`` [H, W, C+1] (channel 0:
  nothing, ``1 - sum``), colour and median depth.
* :func:`compare_frame` turns a render into a label image (argmax of ``p`` after bilinear
  upsampling to the recorded resolution) and measures, per label, the intersection and union
  with the recorded label and the symmetric mean distance between the two boundaries (Euclidean
  distance transforms, ``cv2.distanceTransform``).
* :func:`fit_alignment` estimates the time offset of the camera stamps and a systematic camera
  displacement by least squares on the soft label disagreement ``sum (p - y)^2`` (``y``: the
  recorded one-hot labels, area-averaged to the render grid): coarse-to-fine Gauss–Newton on
  (offset, camera translation, label growth), whose Jacobian chains the image gradient of ``p``
  with the optical flow of each parameter (rendered image velocities for the offset; the
  rigid-motion flow field at the rendered depth for the translation, Longuet-Higgins & Prazdny
  1980), then a parabola through the unblurred disagreement around the offset.

Frames are read lazily (label PNGs decoded only for the frames used, video decoded in order).

By default the validator does not re-render every frame: :func:`plan_frames` picks as many
frames as a wall-time budget allows at the per-frame cost measured on the dataset itself
(evenly spaced frames plus the frames that matter, never random), and
``RerenderOptions(full=True)`` compares them all.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import torch

from .binding import Binding
from .cameras import CameraModel
from .errors import FormatError, InputError
from .frames import quat_to_matrix
from .images import decode_label_png, iter_video_frames
from .render import Camera, Gaussians, RenderConfig, RenderOutput, render
from .render.camera import camera_from_model

__all__ = [
    "RerenderOptions",
    "LabelChannels",
    "label_channels",
    "valid_gaussian_mask",
    "SceneRerenderer",
    "FrameMetrics",
    "compare_frame",
    "label_edges",
    "void_band",
    "VOID_BAND_PX",
    "pose_stream",
    "boundary_distance",
    "boundary_mm",
    "recorded_soft_labels",
    "AlignmentFit",
    "fit_alignment",
    "select_fit_frames",
    "read_label_frames",
    "read_video_frames",
    "foreground_psnr",
    "MAX_LOG_SCALE",
    "BLUR_SCHEDULE_PX",
    "DEFAULT_BUDGET_S",
    "MIN_PASS_FRAMES",
    "MIN_FIT_FRAMES",
    "FIT_FRAME_RENDERS",
    "FramePlan",
    "plan_frames",
    "spread_frames",
    "fit_frame_count",
]

#: half-width (px) of the void band around recorded label edges that IoU leaves out
VOID_BAND_PX = 2
#: Gaussians with a standard deviation above e^MAX_LOG_SCALE m (10 m) are absurd and not rendered
MAX_LOG_SCALE = math.log(10.0)
#: default wall-time budget of a validation's re-rendering (label pass and alignment fit of every
#: camera stream together), s; ``RerenderOptions(full=True)`` ignores it
DEFAULT_BUDGET_S = 4.0
#: the label pass compares at least this many frames (or all, when there are fewer)
MIN_PASS_FRAMES = 6
#: the alignment fit uses at least this many frames (or all candidates, when there are fewer):
#: on the small scene 2 frames still recover a 20 ms stamp offset to 2.5 ms and a 3 mm camera
#: displacement to 0.1 mm (8 frames: 0.5 ms)
MIN_FIT_FRAMES = 2
#: cost of one fit frame in plain renders: 4 Gauss–Newton renders with image velocities and the
#: Jacobian, one sharp evaluation and two parabola renders; measured on the small scene at 1.3 s
#: per fit frame against 0.16 s per render (1 thread)
FIT_FRAME_RENDERS = 8.0


@dataclass(frozen=True)
class RerenderOptions:
    """How much work re-render validation does.

    Attributes:
        stride: compare every k-th recorded frame (1: all).
        scale: render at this fraction of the camera resolution (intrinsics scaled with it);
            comparisons stay at the recorded resolution.
        backend: render backend name (see ``robogs.format.render.available_backends``).
        fit_frames: frames (those with the fastest image motion) used by the offset and
            camera-displacement fit.
        max_offset_ms: the time-offset estimate is kept within ±this, ms.
        device: torch device of the Gaussians ("cpu", "cuda", ...).
        full: compare every ``stride``-th frame and fit on ``fit_frames`` frames, whatever it costs.
        budget_s: otherwise, the wall time (s) the re-rendering of all camera streams should take;
            the frame counts follow from the per-frame cost measured on the dataset.
        frame_cost_s: use this per-frame render cost (s) instead of measuring it (tests, or
            reproducible frame choices across machines).
    """

    stride: int = 1
    scale: float = 1.0
    backend: str = "torch"
    fit_frames: int = 8
    max_offset_ms: float = 200.0
    device: str = "cpu"
    full: bool = False
    budget_s: float = DEFAULT_BUDGET_S
    frame_cost_s: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.stride, int) or isinstance(self.stride, bool) or self.stride < 1:
            raise InputError(
                f"stride must be an integer >= 1, got {self.stride!r}", where="--stride"
            )
        if not (isinstance(self.scale, int | float) and 0.0 < float(self.scale) <= 4.0):
            raise InputError(f"scale must be in (0, 4], got {self.scale!r}", where="--scale")
        if self.fit_frames < 1:
            raise InputError(f"fit_frames must be >= 1, got {self.fit_frames!r}")
        if not (isinstance(self.budget_s, int | float) and float(self.budget_s) > 0.0):
            raise InputError(
                f"the re-render budget must be > 0 s, got {self.budget_s!r}",
                where="--rerender-budget",
                hint="give seconds, e.g. --rerender-budget 10, or --full for every frame",
            )
        cost = self.frame_cost_s
        if cost is not None and not (isinstance(cost, int | float) and float(cost) > 0.0):
            raise InputError(f"frame_cost_s must be > 0 s, got {cost!r}")


@dataclass(frozen=True)
class FramePlan:
    """Which of ``total`` candidate frames a re-render compares, and why.

    Attributes:
        chosen: sorted indices into the candidates.
        total: number of candidates.
        budget_s: wall time allowed, s (``inf`` when every frame was asked for).
        cost_s: measured (or given) seconds per frame.
        floor: True when the minimum frame count, not the budget, set the number.
    """

    chosen: np.ndarray
    total: int
    budget_s: float
    cost_s: float
    floor: bool = False

    @property
    def count(self) -> int:
        """Number of frames chosen."""
        return len(self.chosen)

    @property
    def subsampled(self) -> bool:
        """True when some candidates are left out."""
        return self.count < self.total

    @property
    def expected_s(self) -> float:
        """Expected wall time of the chosen frames, s."""
        return self.count * self.cost_s


def spread_frames(total: int, k: int, must: Sequence[int] = ()) -> np.ndarray:
    """``k`` of ``total`` indices: an even grid (both ends included) holding the ``must`` indices.

    Each ``must`` index (in priority order) that the grid misses replaces the nearest grid
    point that is neither an end nor an earlier ``must``; the count stays ``k``. Deterministic.

    Returns:
        Sorted int64 indices.
    """
    k = max(0, min(int(k), total))
    if k == total:
        return np.arange(total, dtype=np.int64)
    if k == 0:
        return np.zeros(0, np.int64)
    if k == 1:
        return np.asarray([int(must[0]) if len(must) else 0], np.int64)
    grid = [int(math.floor(x + 0.5)) for x in np.linspace(0.0, total - 1, k)]
    fixed = {grid[0], grid[-1]}
    for m in (int(x) for x in must):
        if not 0 <= m < total or m in grid:
            fixed.add(m)
            continue
        free = [g for g in grid if g not in fixed]
        if not free:
            break
        nearest = min(free, key=lambda g: (abs(g - m), g))
        grid[grid.index(nearest)] = m
        fixed.add(m)
    return np.asarray(sorted(grid), np.int64)


def plan_frames(
    total: int,
    cost_s: float,
    budget_s: float,
    *,
    min_frames: int = MIN_PASS_FRAMES,
    must: Sequence[int] = (),
) -> FramePlan:
    """Choose as many of ``total`` frames as ``budget_s`` allows at ``cost_s`` each.

    ``floor(budget_s / cost_s)`` frames, at least ``min_frames`` and at most ``total``, spread
    by :func:`spread_frames` (even grid plus ``must``). ``budget_s = inf`` takes every frame.
    """
    if total <= 0:
        return FramePlan(np.zeros(0, np.int64), 0, budget_s, cost_s)
    # (+1e-9: a budget of exactly k frames is k frames despite rounding, e.g. 2.4 / 0.4)
    fit = total if math.isinf(budget_s) else int(budget_s / max(cost_s, 1e-9) + 1e-9)
    k = min(total, max(fit, min_frames))
    return FramePlan(spread_frames(total, k, must), total, budget_s, cost_s, floor=fit < k)


def fit_frame_count(render_s: float, budget_s: float, most: int) -> int:
    """Frames the alignment fit can use within ``budget_s`` at ``render_s`` per plain render.

    ``floor(budget_s / (FIT_FRAME_RENDERS x render_s))`` within ``[MIN_FIT_FRAMES, most]``.
    """
    if math.isinf(budget_s):
        return most
    fit = int(budget_s / max(FIT_FRAME_RENDERS * render_s, 1e-9) + 1e-9)
    return max(min(MIN_FIT_FRAMES, most), min(fit, most))


@dataclass(frozen=True)
class LabelChannels:
    """Label channels of a re-render: one per bound target that a segment names.

    Attributes:
        label_ids: [C] panoptic label id of channel c+1 (channel 0 is "nothing").
        names: [C] target (link or object) name of each channel.
        kinds: [C] "robot_link" or "object" (from the binding target).
        target_channel: [n_targets] channel (1..C) of each binding target, 0 for none.
        unlabelled_targets: targets with Gaussians but no segment (cannot be compared).
    """

    label_ids: np.ndarray
    names: list[str]
    kinds: list[str]
    target_channel: np.ndarray
    unlabelled_targets: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        """Number of label channels C (without the "nothing" channel)."""
        return len(self.names)

    def lookup(self, max_label: int = 65535) -> np.ndarray:
        """[max_label + 1] int array: label id -> channel (0 for ids with no channel)."""
        lut = np.zeros(max_label + 1, np.int64)
        for c, lab in enumerate(self.label_ids):
            if 0 < lab <= max_label:
                lut[int(lab)] = c + 1
        return lut


def label_channels(binding: Binding, segments: pa.Table) -> LabelChannels:
    """Map the binding's targets to label ids through a ``segments`` table.

    A target is matched by name against the ``target`` column (first row wins); a labelled
    target keeps its channel even when no Gaussian is bound to it (it then re-renders empty).
    Targets with Gaussians that no segment names get no channel (``unlabelled_targets``).
    """
    names = [str(x) for x in segments.column("target").to_pylist()]
    ids = segments.column("label_id").to_numpy().astype(np.int64)
    by_name: dict[str, int] = {}
    for n, i in zip(names, ids, strict=True):
        if n and n not in by_name:
            by_name[n] = int(i)
    present = np.zeros(len(binding.targets), bool)
    present[np.unique(binding.target_index[binding.target_index >= 0].cpu().numpy())] = True
    present |= np.array([tg.name in by_name for tg in binding.targets], bool)
    label_ids: list[int] = []
    cnames: list[str] = []
    kinds: list[str] = []
    target_channel = np.zeros(len(binding.targets), np.int64)
    unlabelled: list[str] = []
    channel_of_label: dict[int, int] = {}
    for k, tg in enumerate(binding.targets):
        if not present[k]:
            continue
        lab = by_name.get(tg.name)
        if lab is None or lab <= 0:
            unlabelled.append(tg.name)
            continue
        if lab not in channel_of_label:
            label_ids.append(lab)
            cnames.append(tg.name)
            kinds.append(tg.kind)
            channel_of_label[lab] = len(label_ids)
        target_channel[k] = channel_of_label[lab]
    return LabelChannels(np.asarray(label_ids, np.int64), cnames, kinds, target_channel, unlabelled)


def valid_gaussian_mask(
    means: torch.Tensor,
    quats: torch.Tensor,
    log_scales: torch.Tensor,
    opacity_logits: torch.Tensor,
    sh: torch.Tensor,
) -> torch.Tensor:
    """[N] bool: Gaussians that can be rendered (finite, non-zero rotation, scale below 10 m).

    ``-inf`` log-scales (zero extent) and NaN anywhere, infinite centres or colours, zero
    quaternions and standard deviations above 10 m are excluded; the validator reports them.
    """
    ok = torch.isfinite(means).all(1) & torch.isfinite(quats).all(1) & (quats.norm(dim=1) > 1e-12)
    ok &= (
        ~torch.isnan(log_scales).any(1)
        & (log_scales < MAX_LOG_SCALE).all(1)
        & torch.isfinite(log_scales).all(1)
    )
    ok &= ~torch.isnan(opacity_logits) & torch.isfinite(sh).flatten(1).all(1)
    return ok


def _shifted(T_world_cam: np.ndarray, shift_m: np.ndarray | None) -> np.ndarray:
    """``T_world_cam`` moved by ``shift_m`` [3] (m) along its own axes."""
    if shift_m is None:
        return T_world_cam
    T = np.array(T_world_cam, np.float64)
    T[:3, 3] = T[:3, 3] + T[:3, :3] @ np.asarray(shift_m, np.float64)
    return T


class SceneRerenderer:
    """Renders the bound Gaussians of one episode into one camera, with label channels.

    Args:
        binding: the episode's binding (cached by the caller; it is reused for every frame).
        camera: the stored camera model.
        channels: label channels (from :func:`label_channels`).
        scale: render resolution as a fraction of the camera's.
        backend: render backend.
        pose_of: ``t_ns -> T_world_cam`` [4, 4] for time-varying extrinsics (None: static).

    Raises:
        InputError: the camera has no extrinsics.
    """

    def __init__(
        self,
        binding: Binding,
        camera: CameraModel,
        channels: LabelChannels,
        *,
        scale: float = 1.0,
        backend: str = "torch",
        pose_of: Callable[[int], np.ndarray] | None = None,
    ) -> None:
        self.binding = binding
        self.model = camera
        self.channels = channels
        self.scale = float(scale)
        self.backend = backend
        if pose_of is None and camera.T_world_cam is None:
            raise InputError(
                f"camera {camera.name!r} has no T_world_cam", where=f"cameras/{camera.name}"
            )
        self._pose_of = pose_of
        rest = binding.rest
        self.valid = valid_gaussian_mask(
            rest.means, rest.quats, rest.log_scales, rest.opacity_logits, rest.sh
        )
        self.num_invalid = int((~self.valid).sum())
        tid = binding.target_index
        ch = torch.as_tensor(channels.target_channel, device=tid.device)
        chan = torch.where(tid >= 0, ch[tid.clamp(min=0)], torch.zeros_like(tid))[self.valid]
        onehot = torch.zeros(
            int(chan.shape[0]), channels.count + 1, dtype=rest.means.dtype, device=tid.device
        )
        onehot[torch.arange(chan.shape[0], device=tid.device), chan] = 1.0
        self.extra = onehot[:, 1:].contiguous()
        cpu = rest.means.device.type == "cpu"
        self.config = RenderConfig(kind=rest.kind, tile_size=8 if cpu else 16, validate=False)
        cam0 = camera_from_model(camera, self.T_world_cam(0), self.scale)
        self.width, self.height = cam0.width, cam0.height
        self.fx, self.fy, self.cx, self.cy = cam0.fx, cam0.fy, cam0.cx, cam0.cy

    def T_world_cam(self, t_ns: int) -> np.ndarray:
        """Stored ``T_world_cam`` at ``t_ns`` [4, 4]."""
        if self._pose_of is not None:
            return self._pose_of(int(t_ns))
        return np.asarray(self.model.T_world_cam, np.float64)

    def camera(self, t_ns: int, shift_m: np.ndarray | None = None) -> Camera:
        """The render camera at ``t_ns``, optionally moved by ``shift_m`` [3] m in its own frame."""
        return camera_from_model(self.model, _shifted(self.T_world_cam(t_ns), shift_m), self.scale)

    def render(
        self,
        t_ns: int,
        *,
        offset_ns: float = 0.0,
        shift_m: np.ndarray | None = None,
        velocity: bool = False,
    ) -> RenderOutput:
        """Render the Gaussians posed at ``t_ns + offset_ns`` into the (shifted) camera.

        With ``velocity`` two more extra channels carry each Gaussian's image velocity (px/ms,
        render grid, pinhole projection), blended like the labels (divide by alpha to read them).
        """
        t = int(t_ns) + int(round(offset_ns))
        g = self.binding.pose(t)
        v = self.valid
        extra = self.extra
        if velocity:
            vel = self._velocity(t, self.T_world_cam(t_ns), shift_m)
            extra = torch.cat([extra, vel.to(dtype=extra.dtype, device=extra.device)], 1)
        g = Gaussians(
            g.means[v], g.quats[v], g.log_scales[v], g.opacity_logits[v], g.sh[v], extra=extra
        )
        return render(g, self.camera(t_ns, shift_m), config=self.config, backend=self.backend)

    def probabilities(self, out: RenderOutput) -> np.ndarray:
        """[H, W, C+1] float32 soft labels: channel 0 = 1 - sum of the label channels."""
        e = out.extra[..., : self.channels.count].detach().to("cpu", torch.float32).numpy()
        none = np.clip(1.0 - e.sum(-1, keepdims=True), 0.0, 1.0)
        return np.concatenate([none, e], -1)

    def _project(self, x_world: torch.Tensor, T_world_cam: np.ndarray) -> torch.Tensor:
        """[M, 2] pinhole pixel coordinates (render grid) of world points [M, 3] (float64)."""
        T = torch.as_tensor(T_world_cam, dtype=torch.float64, device=x_world.device)
        xc = (x_world - T[:3, 3]) @ T[:3, :3]
        z = torch.where(xc[:, 2] > 1e-3, xc[:, 2], torch.full_like(xc[:, 2], float("nan")))
        return torch.stack([self.fx * xc[:, 0] / z + self.cx, self.fy * xc[:, 1] / z + self.cy], -1)

    def _moved(self, t_ns: int, idx: torch.Tensor | None = None) -> torch.Tensor:
        """World centres [M, 3] (float64) of the valid Gaussians (or ``idx`` of them) at ``t_ns``."""
        b = self.binding
        sel = torch.nonzero(self.valid)[:, 0] if idx is None else idx
        tid = b.target_index[sel]
        M = b.target_motion(int(t_ns)).to(tid.device)[tid.clamp(min=0)]
        x0 = b.rest.means[sel].double()
        moved = (M[:, :3, :3] @ x0[..., None])[..., 0] + M[:, :3, 3]
        return torch.where((tid >= 0)[:, None], moved, x0)

    def _velocity(
        self, t_ns: int, T_world_cam: np.ndarray, shift_m: np.ndarray | None, dt_ns: int = 2_000_000
    ) -> torch.Tensor:
        """[N_valid, 2] image velocity of every rendered Gaussian, px/ms (0 where not projectable)."""
        T = _shifted(T_world_cam, shift_m)
        uv0 = self._project(self._moved(t_ns - dt_ns), T)
        uv1 = self._project(self._moved(t_ns + dt_ns), T)
        vel = (uv1 - uv0) / (2 * dt_ns * 1e-6)
        return torch.nan_to_num(vel, nan=0.0, posinf=0.0, neginf=0.0)

    def image_motion_px(
        self, t_ns: Sequence[int], *, dt_ns: int = 10_000_000, sample: int = 2048
    ) -> np.ndarray:
        """[F] mean image displacement over ``2 dt_ns`` (px, render grid) of moving Gaussians.

        A fixed subsample of the Gaussians bound to links and objects is projected at
        ``t - dt_ns`` and ``t + dt_ns``; used to pick the frames that constrain the time offset.
        """
        b = self.binding
        kinds = torch.as_tensor(
            [tg.kind != "static" for tg in b.targets] + [False], device=b.target_index.device
        )
        moving = (
            self.valid & kinds[torch.where(b.target_index >= 0, b.target_index, len(b.targets))]
        )
        idx = torch.nonzero(moving)[:, 0]
        if idx.numel() == 0:
            return np.zeros(len(t_ns))
        gen = torch.Generator().manual_seed(0)
        idx = idx[torch.randperm(idx.numel(), generator=gen)[:sample].to(idx.device)]
        out = np.zeros(len(t_ns))
        for i, t in enumerate(t_ns):
            T = self.T_world_cam(int(t))
            d = self._project(self._moved(int(t) + dt_ns, idx), T) - self._project(
                self._moved(int(t) - dt_ns, idx), T
            )
            d = d.norm(dim=1)
            d = d[torch.isfinite(d)]
            out[i] = float(d.mean()) if d.numel() else 0.0
        return out


# --------------------------------------------------------------------------------- comparison


@dataclass
class FrameMetrics:
    """Per-label measurements of one frame, arrays of length C (channel c+1).

    Attributes:
        inter: intersection of recorded and re-rendered masks outside the void band, px.
        union: union outside the void band, px.
        recorded: recorded mask size outside the void band, px.
        rendered: re-rendered mask size outside the void band, px.
        boundary_sum: sum of boundary-to-boundary distances (both directions), px.
        boundary_count: number of boundary pixels summed (both directions).
        depth_m: median rendered depth of the re-rendered mask, m (NaN if empty).
    """

    inter: np.ndarray
    union: np.ndarray
    recorded: np.ndarray
    rendered: np.ndarray
    boundary_sum: np.ndarray
    boundary_count: np.ndarray
    depth_m: np.ndarray


_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def _boundary(mask: np.ndarray) -> np.ndarray:
    """Pixels of ``mask`` with a 4-neighbour outside it (outside the image counts as inside)."""
    m = mask.astype(np.uint8)
    return (m - cv2.erode(m, _CROSS)).astype(bool)


def boundary_distance(a: np.ndarray, b: np.ndarray) -> tuple[float, int]:
    """Symmetric boundary distance of two masks: (sum of distances, number of boundary pixels).

    Each boundary pixel of ``a`` contributes its Euclidean distance (px, pixel centres) to the
    nearest boundary pixel of ``b`` and vice versa; the mean is ``sum / count``. Work is confined
    to the bounding box of both masks (exact: every boundary pixel lies inside it).

    Returns:
        ``(0.0, 0)`` when either mask has no boundary.
    """
    both = a | b
    rows = np.flatnonzero(both.any(1))
    cols = np.flatnonzero(both.any(0))
    if rows.size == 0:
        return 0.0, 0
    H, W = a.shape
    r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, H)
    c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, W)
    ba = _boundary(a[r0:r1, c0:c1])
    bb = _boundary(b[r0:r1, c0:c1])
    if not ba.any() or not bb.any():
        return 0.0, 0
    da = cv2.distanceTransform((~bb).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    db = cv2.distanceTransform((~ba).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return float(da[ba].sum() + db[bb].sum()), int(ba.sum() + bb.sum())


def boundary_mm(bsum: np.ndarray, depth: np.ndarray, fx: float) -> np.ndarray:
    """Boundary distances [px] converted to mm at the rendered depth: ``px x depth / fx``.

    Args:
        bsum: [F, C] summed boundary distances, px (recorded resolution).
        depth: [F, C] median rendered depth of each label, m; NaN entries use the median depth
            of the whole array (NaN when it has none).
        fx: focal length at the recorded resolution, px.

    Returns:
        [F, C] the same sums in mm.
    """
    depth = np.where(
        np.isnan(depth),
        np.nanmedian(depth) if np.isfinite(depth).any() else np.nan,
        depth,
    )
    return bsum * depth / fx * 1000.0


def _upsample(p: np.ndarray, width: int, height: int) -> np.ndarray:
    """Bilinear resampling with pixel centres aligned (OpenCV's half-pixel convention)."""
    if p.shape[1] == width and p.shape[0] == height:
        return p
    return cv2.resize(p, (width, height), interpolation=cv2.INTER_LINEAR).reshape(
        height, width, p.shape[-1]
    )


def label_edges(labels: np.ndarray) -> np.ndarray:
    """[H, W] bool: pixels with a 4-neighbour of another label (both sides of every label edge)."""
    edge = np.zeros(labels.shape, bool)
    dv = labels[1:] != labels[:-1]
    dh = labels[:, 1:] != labels[:, :-1]
    edge[1:] |= dv
    edge[:-1] |= dv
    edge[:, 1:] |= dh
    edge[:, :-1] |= dh
    return edge


def void_band(labels: np.ndarray, width_px: int = VOID_BAND_PX) -> np.ndarray:
    """[H, W] bool: pixels within ``width_px`` of a label edge (Chebyshev distance, both sides)."""
    edge = label_edges(labels).astype(np.uint8)
    if width_px <= 1:
        return edge.astype(bool)
    k = 2 * width_px - 1
    return cv2.dilate(edge, np.ones((k, k), np.uint8)).astype(bool)


def compare_frame(
    prob: np.ndarray, depth: np.ndarray, recorded_channels: np.ndarray, num_channels: int
) -> FrameMetrics:
    """Compare a re-render with a recorded label image.

    Intersection and union leave out a void band of :data:`VOID_BAND_PX` pixels on both sides of
    every recorded label edge (as PASCAL VOC's void band, Everingham et al. 2010): boundary
    placement is measured by the boundary distance, so IoU measures gross errors (wrong, missing
    or extra labels) and is not dominated by the splats' silhouette growth on thin links.

    Args:
        prob: [h, w, C+1] soft labels on the render grid.
        depth: [h, w] rendered median depth, m (0 where nothing was hit).
        recorded_channels: [H, W] channel index (0..C) of every recorded pixel.
        num_channels: C.

    Returns:
        Per-channel measurements at the recorded resolution.
    """
    H, W = recorded_channels.shape
    C = num_channels
    low = prob.argmax(-1)
    rendered = _upsample(prob, W, H).argmax(-1)
    rec = recorded_channels
    keep = ~void_band(rec)
    pair = (rec * (C + 1) + rendered)[keep]
    conf = np.bincount(pair, minlength=(C + 1) ** 2).reshape(C + 1, C + 1)
    inter = np.diag(conf)[1:].astype(np.int64)
    n_rec = conf.sum(1)[1:].astype(np.int64)
    n_ren = conf.sum(0)[1:].astype(np.int64)
    bsum = np.zeros(C)
    bcnt = np.zeros(C, np.int64)
    dep = np.full(C, np.nan)
    present = np.zeros(C + 1, bool)
    present[np.unique(rec)] = True
    present[np.unique(rendered)] = True
    for c in np.flatnonzero(present[1:]) + 1:
        bsum[c - 1], bcnt[c - 1] = boundary_distance(rec == c, rendered == c)
        z = depth[(low == c) & (depth > 0)]
        if z.size:
            dep[c - 1] = float(np.median(z))
    return FrameMetrics(inter, n_rec + n_ren - inter, n_rec, n_ren, bsum, bcnt, dep)


def recorded_soft_labels(
    recorded_channels: np.ndarray, num_channels: int, width: int, height: int
) -> np.ndarray:
    """[height, width, C+1] float32 one-hot of the recorded channels, area-averaged to the render grid."""
    onehot = np.eye(num_channels + 1, dtype=np.float32)[recorded_channels]
    if onehot.shape[:2] == (height, width):
        return onehot
    return cv2.resize(onehot, (width, height), interpolation=cv2.INTER_AREA).reshape(
        height, width, -1
    )


def foreground_psnr(rgb: np.ndarray, alpha: np.ndarray, frame: np.ndarray) -> float:
    """PSNR (dB) of a re-rendered colour image against a video frame over the rendered foreground.

    Args:
        rgb: [h, w, 3] rendered colour in [0, 1].
        alpha: [h, w] rendered opacity; pixels with alpha >= 0.5 are compared.
        frame: [H, W, 3] uint8 video frame (area-resampled to the render grid).
    """
    h, w = alpha.shape
    f = (
        frame
        if frame.shape[:2] == (h, w)
        else cv2.resize(frame, (w, h), interpolation=cv2.INTER_AREA)
    )
    m = alpha >= 0.5
    if not m.any():
        return float("nan")
    err = np.mean((np.clip(rgb[m], 0.0, 1.0) - f[m].astype(np.float64) / 255.0) ** 2)
    return float("inf") if err == 0 else float(10.0 * math.log10(1.0 / err))


# ---------------------------------------------------------------------------------- fitting


@dataclass(frozen=True)
class AlignmentFit:
    """Result of :func:`fit_alignment`.

    Attributes:
        offset_ms: pose time minus frame stamp that best explains the labels, ms (the camera
            stamps are ``-offset_ms`` late); NaN when the frames show no motion.
        shift_mm: [3] camera translation in its own frame (x right, y down, z forward), mm, that
            best aligns the re-render: the stored camera is off by ``-shift_mm``.
        cost_before: soft label disagreement at the declared stamps and camera (px).
        cost_after: the same after the fit (px).
        frames: frame stamps used, ns.
        motion_px: image speed of each fit frame (px per 20 ms, render grid).
        offset_observable: False when the fit frames show too little motion.
        dilation_px: the common growth of the re-rendered labels over the recorded ones, px.
    """

    offset_ms: float
    shift_mm: np.ndarray
    cost_before: float
    cost_after: float
    frames: list[int]
    motion_px: list[float]
    offset_observable: bool
    dilation_px: float = 0.0

    @property
    def shift_2d_mm(self) -> float:
        """Camera displacement across the optical axis, mm: the part labels see as a 2D shift."""
        return float(np.hypot(self.shift_mm[0], self.shift_mm[1]))


def select_fit_frames(stamps: np.ndarray, motion: np.ndarray, k: int) -> np.ndarray:
    """Indices of up to ``k`` frames with the fastest image motion, a few frames apart.

    Frames moving at least a quarter of the fastest come first (fastest first, at least
    ``len(stamps) // (10 k)`` frames apart); slower ones fill up the remaining places.
    """
    n = len(stamps)
    if n <= k:
        return np.arange(n)
    gap = max(1, n // (10 * k))
    order = np.argsort(-motion, kind="stable")
    fast = motion[order] >= 0.25 * motion.max(initial=0.0)
    chosen: list[int] = []
    for i in [*order[fast], *order[~fast]]:
        if all(abs(int(i) - j) >= gap for j in chosen):
            chosen.append(int(i))
        if len(chosen) == k:
            break
    return np.sort(np.asarray(chosen, np.int64))


def _depth_filled(depth: np.ndarray) -> np.ndarray:
    """Rendered depth with empty pixels given their nearest surface's depth (5x5 max filter)."""
    grown = cv2.dilate(depth.astype(np.float32), np.ones((5, 5), np.uint8))
    return np.where(depth > 0, depth, grown)


#: Gauss–Newton blur schedule (px on the render grid): coarse to fine widens the basin of
#: convergence to offsets that move edges by several pixels (Bouguet 2001, pyramidal Lucas–Kanade)
BLUR_SCHEDULE_PX: tuple[float, ...] = (3.0, 1.0, 0.0, 0.0)


def _blur(x: np.ndarray, sigma: float) -> np.ndarray:
    if sigma <= 0:
        return x
    return cv2.GaussianBlur(x, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)


def _growth_into_background(gu: np.ndarray, gv: np.ndarray) -> np.ndarray:
    """[h, w, C+1] change of the soft labels when every label grows by 1 px into the background.

    Label c gains ``relu(-grad p_0 . n_c)`` (the part of its edge that faces channel 0,
    "nothing", with ``n_c`` its unit gradient) and channel 0 loses the sum. Edges between two
    labels are left alone: which one grows there depends on the occlusion order.
    """
    g0u, g0v = gu[..., :1], gv[..., :1]
    norm = np.hypot(gu[..., 1:], gv[..., 1:])
    face = -(g0u * gu[..., 1:] + g0v * gv[..., 1:]) / np.maximum(norm, 1e-12)
    gain = np.where(norm > 1e-9, np.maximum(face, 0.0), 0.0)
    return np.concatenate([-gain.sum(-1, keepdims=True), gain], -1)


def fit_alignment(
    rr: SceneRerenderer,
    stamps: Sequence[int],
    targets: Sequence[np.ndarray],
    *,
    fit_offset: bool = True,
    fit_depth: bool = False,
    schedule: Sequence[float] = BLUR_SCHEDULE_PX,
    max_offset_ms: float = 200.0,
    refine_ms: float = 4.0,
    motion_px: Sequence[float] | None = None,
    progress: Callable[[float], None] | None = None,
) -> AlignmentFit:
    """Estimate the camera time offset and a camera translation from label disagreement.

    Minimises ``sum over frames, pixels, channels of (p(t + offset; shift) - y)^2`` where ``p``
    are the rendered soft labels and ``y`` the recorded ones (:func:`recorded_soft_labels`), by
    Gauss–Newton with one render per frame and iteration, coarse to fine (both images blurred
    by ``schedule[i]`` px at iteration i). The Jacobian chains the image gradient of ``p`` with
    the optical flow of each parameter: for the offset, the rendered image velocity of the
    Gaussians; for a camera translation (dX, dY, dZ) in its own frame, the rigid-motion flow
    ``du = -fx dX / Z + (u - cx) dZ / Z`` (likewise ``v``) at the rendered depth Z
    (Longuet-Higgins & Prazdny 1980). A nuisance parameter grows every label into the background
    by the same amount (:func:`_growth_into_background`): it absorbs the silhouette growth of
    splats over their mesh, which one-sided edges (a table cut by the image border) would
    otherwise read as a camera translation. With ``refine_ms > 0`` the offset is last refined by
    the vertex of a parabola through the unblurred disagreement at ``offset ± refine_ms``
    (two more renders per frame).

    Args:
        rr: the re-renderer.
        stamps: frame stamps, ns.
        targets: per frame, [h, w, C+1] recorded soft labels on the render grid.
        fit_offset: False to keep the offset at 0.
        fit_depth: also fit the translation along the optical axis (weakly observable; it
            trades off against the label growth).
        schedule: blur (px) of each iteration; its length is the number of iterations.
        max_offset_ms: offsets are kept within ±this.
        refine_ms: half-width of an optional final parabola fit of the offset on the unblurred
            disagreement (0: none).
        motion_px: image speed of each frame (reported; all zero makes the offset unobservable).
        progress: called with the fraction of the renders done (0..1).

    Returns:
        The fit.
    """
    stamps = [int(t) for t in stamps]
    n_renders = max(1, len(stamps) * (len(schedule) + 1 + (2 if refine_ms > 0 else 0)))
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(min(1.0, done / n_renders))

    ys = [np.asarray(y, np.float32) for y in targets]
    motion = np.asarray(motion_px if motion_px is not None else np.ones(len(stamps)), np.float64)

    def cost_of(off_ms: float, shift_mm: np.ndarray) -> float:
        total = 0.0
        for f, t in enumerate(stamps):
            p = rr.probabilities(rr.render(t, offset_ns=off_ms * 1e6, shift_m=shift_mm * 1e-3))
            total += float(np.square(p - ys[f]).sum())
            tick()
        return total

    observable = bool(fit_offset and motion.max(initial=0.0) > 1e-6)
    H, W = rr.height, rr.width
    u = (np.arange(W) + 0.5 - rr.cx)[None, :, None]
    v = (np.arange(H) + 0.5 - rr.cy)[:, None, None]
    theta = np.zeros(5)  # offset ms, shift x y z mm, dilation px
    cost0 = float("nan")
    history: list[tuple[float, np.ndarray]] = []
    for it, sigma in enumerate([*schedule, 0.0]):
        last = it == len(schedule)
        A = np.zeros((5, 5))
        b = np.zeros(5)
        sharp = 0.0
        for f, t in enumerate(stamps):
            o = rr.render(
                t,
                offset_ns=theta[0] * 1e6,
                shift_m=theta[1:4] * 1e-3,
                velocity=observable and not last,
            )
            p0 = rr.probabilities(o)
            sharp += float(np.square(p0 - ys[f]).sum())
            tick()
            if last:
                continue
            p = _blur(p0, sigma).astype(np.float64)
            r = p - _blur(ys[f], sigma)
            gv, gu = np.gradient(p, axis=(0, 1))
            z = _depth_filled(o.depth_expected.detach().cpu().numpy().astype(np.float64))
            inv_z = np.where(z > 0, 1.0 / np.maximum(z, 1e-6), 0.0)
            inv_z = _blur(inv_z.astype(np.float32), sigma).astype(np.float64)[..., None]
            if observable:
                alpha = o.alpha.detach().cpu().numpy().astype(np.float64)
                vel = o.extra[..., rr.channels.count :].detach().cpu().numpy().astype(np.float64)
                vel = np.where(
                    alpha[..., None] > 1e-3, vel / np.maximum(alpha, 1e-3)[..., None], 0.0
                )
                vel = _blur(vel.astype(np.float32), sigma).astype(np.float64)
                j_off = -(gu * vel[..., :1] + gv * vel[..., 1:2])
            else:
                j_off = np.zeros_like(r)
            grow = _growth_into_background(gu, gv)
            cols = [
                j_off,
                rr.fx * inv_z * gu * 1e-3,
                rr.fy * inv_z * gv * 1e-3,
                -(u * gu + v * gv) * inv_z * 1e-3 if fit_depth else np.zeros_like(r),
                grow,
            ]
            J = np.stack([c.ravel() for c in cols], 1)
            A += J.T @ J
            b += J.T @ r.ravel()
        if it == 0:
            cost0 = sharp
        history.append((sharp, theta.copy()))
        if last:
            break
        for k in ([0] if not observable else []) + ([3] if not fit_depth else []):
            A[k, :] = A[:, k] = 0.0
            A[k, k] = 1.0
            b[k] = 0.0
        damp = np.diag(np.diag(A)) * 1e-3 + np.eye(5) * 1e-12 * max(np.trace(A), 1.0)
        try:
            dx = -np.linalg.solve(A + damp, b)
        except np.linalg.LinAlgError:
            break
        dx[0] = float(np.clip(dx[0], -50.0, 50.0))
        dx[1:4] = np.clip(dx[1:4], -10.0, 10.0)
        theta[:4] += dx[:4]
        theta[4] = dx[4]  # the growth is not rendered: it is solved afresh, not accumulated
        theta[0] = float(np.clip(theta[0], -max_offset_ms, max_offset_ms))
    # the last iterations are unblurred: keep the best of them
    fine = [h for h, s in zip(history, [*schedule, 0.0], strict=False) if s == 0.0] or history
    final, theta = min(fine, key=lambda h: h[0])
    theta = theta.copy()
    if observable and refine_ms > 0:
        # Gauss–Newton's offset leans on blended image velocities; the vertex of a parabola
        # through the sharp disagreement at offset ± refine_ms is free of that approximation
        c_minus = cost_of(theta[0] - refine_ms, theta[1:4])
        c_plus = cost_of(theta[0] + refine_ms, theta[1:4])
        den = c_minus - 2.0 * final + c_plus
        if den > 0:
            theta[0] += refine_ms * float(np.clip(0.5 * (c_minus - c_plus) / den, -1.0, 1.0))
    return AlignmentFit(
        float(theta[0]) if observable else float("nan"),
        theta[1:4].copy(),
        cost0,
        final,
        stamps,
        [float(m) for m in motion],
        observable,
        float(theta[4]),
    )


# ---------------------------------------------------------------------------------- reading


def read_label_frames(
    path: Path, wanted: Sequence[int], *, batch_rows: int = 32
) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame_index, labels [H, W] uint16)`` for the wanted frame indices, in table order.

    Only the wanted rows are decoded; the table is read in batches (never whole).

    Raises:
        FormatError: unreadable table or image.
    """
    want = set(int(i) for i in wanted)
    try:
        pf = pq.ParquetFile(path)
        for batch in pf.iter_batches(batch_size=batch_rows, columns=["frame_index", "png"]):
            if batch.column(0).null_count or batch.column(1).null_count:
                raise FormatError(
                    "label table holds null frame indices or images",
                    path=path,
                    hint="every row needs a frame_index and a PNG; re-export the labels",
                )
            idx = batch.column(0).to_numpy()
            hit = [k for k, i in enumerate(idx) if int(i) in want]
            if not hit:
                continue
            blobs = batch.column(1)
            for k in hit:
                i = int(idx[k])
                yield i, decode_label_png(blobs[k].as_py(), path=path, where=f"frame_index {i}")
    except (pa.ArrowException, OSError) as exc:
        raise FormatError(
            f"unreadable label table ({str(exc)[:200]})",
            path=path,
            hint="the file is truncated or not parquet; re-export it",
        ) from None


def read_video_frames(path: Path, wanted: Sequence[int]) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame_index, rgb [H, W, 3] uint8)`` for the wanted indices (decoding in order)."""
    want = set(int(i) for i in wanted)
    last = max(want) if want else -1
    for i, img in enumerate(iter_video_frames(path)):
        if i > last:
            break
        if i in want:
            yield i, img


def pose_stream(
    t_ns: np.ndarray, xyz: np.ndarray, qwxyz: np.ndarray
) -> Callable[[int], np.ndarray]:
    """``t -> T_world_cam`` [4, 4] interpolating a ``camera_extrinsics`` table (clamped at the ends)."""
    from .interp import interp_pose

    def at(t: int) -> np.ndarray:
        p, q = interp_pose(np.array([int(t)], np.int64), t_ns, xyz, qwxyz, outside="clamp")
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(np.asarray(q[0], np.float64))
        T[:3, 3] = p[0]
        return T

    return at

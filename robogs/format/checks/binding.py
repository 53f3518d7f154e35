"""Binding checks (B0xx): bound Gaussians sit on their faces and re-render onto the recorded labels.

* ``B001`` measures each bound Gaussian's distance to its face plus offset at the rest state.
* ``B002``–``B006`` re-render frames of every labelled camera (:mod:`robogs.format.rerender`):
  label IoU, boundary distance (px and mm), photometric match (PSNR against a floor), the
  camera's time offset and a systematic camera displacement.
* ``B007``–``B011`` report inputs the re-render cannot trust: bad splat values, unnormalised
  quaternions, degenerate cameras, label ids without a segment, targets without labels.

Work is shared through a per-context cache: one :class:`~robogs.format.binding.Binding` per
episode, one re-render pass and one alignment fit per camera stream. Speed options come from
``ctx.options`` (``stride``, ``scale``, ``backend``, ``fit_frames``, ``device``, ``full``,
``budget_s``, ``frame_cost_s``) when the caller sets them.

**Time budget.** Unless ``full`` is set, the re-rendering of all camera streams together should
take about ``budget_s`` seconds of wall time (default
:data:`~robogs.format.rerender.DEFAULT_BUDGET_S`). Each stream gets an equal share; the label pass
(B002–B004) gets :data:`PASS_SHARE` of it, the alignment fit (B005, B006) the rest. The pass times
its first two frames and compares as many as the rest of its share allows (an even grid plus the
frames of fastest and slowest image motion, :func:`~robogs.format.rerender.plan_frames`); the
fit uses as many of its fastest frames as its share allows at the measured render cost. Each
subsampled stream leaves a note (:func:`run_notes`) naming the counts, the budget and ``--full``.
"""

from __future__ import annotations

import math
import time
import weakref
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cameras import CameraModel
from ..dataset import Episode
from ..errors import FormatError, RobogsError
from ..findings import Finding
from ._common import column, frame_stamps, stack_columns
from .context import CheckContext, InputReported
from .registry import Check, check

# torch, the renderer and the binding load only when a binding check runs: registering these
# checks must not cost ``robogs-validate --quick`` the ~2 s torch import
if TYPE_CHECKING:
    import torch

    from ..binding import Binding
    from ..rerender import (
        AlignmentFit,
        FrameMetrics,
        FramePlan,
        LabelChannels,
        RerenderOptions,
        SceneRerenderer,
    )

__all__ = [
    "rerender_options",
    "run_notes",
    "expected_seconds",
    "PASS_SHARE",
    "alignment_fit",
    "label_summary",
    "LabelSummary",
    "IOU_MIN_PIXELS",
    "QUAT_NORM_TOL",
    "MIN_MOTION_PX",
    "EDGE_SIGMA_PX",
]

#: a label needs this many non-void pixels (summed over the compared frames) for its IoU to count
IOU_MIN_PIXELS = 200
#: frames must move by this much (px per 20 ms on the render grid) for the time offset to be fitted
MIN_MOTION_PX = 0.05
#: quaternion norms further than this from 1 are flagged (spec §4)
QUAT_NORM_TOL = 1e-3
#: share of a camera stream's time budget given to the label pass (B002-B004); the fit gets the rest
PASS_SHARE = 0.4
#: fit candidates: at most this many frames spread over the episode (``full``: 600)
FIT_CANDIDATES = 60

_STATE: weakref.WeakKeyDictionary[CheckContext, dict[Any, Any]] = weakref.WeakKeyDictionary()


def rerender_options(ctx: CheckContext) -> RerenderOptions:
    """Re-render options of a validation run, from ``ctx.options`` (defaults otherwise).

    Recognised keys: ``stride`` (int), ``scale`` (float), ``backend``, ``fit_frames``, ``device``,
    ``max_offset_ms``, ``full`` (bool), ``budget_s`` (float), ``frame_cost_s`` (float).
    """
    from ..rerender import RerenderOptions

    raw = getattr(ctx, "options", None) or {}
    keys = (
        "stride",
        "scale",
        "backend",
        "fit_frames",
        "device",
        "max_offset_ms",
        "full",
        "budget_s",
        "frame_cost_s",
    )
    return RerenderOptions(**{k: raw[k] for k in keys if raw.get(k) is not None})


def expected_seconds(code: str, ctx: CheckContext) -> float | None:
    """Rough wall time of a binding check, s, for the validator's progress bar (None: default).

    B002 carries the label pass and B005 the alignment fit (the checks after them reuse those
    results); with ``full`` the counts are not known before the run, so 10x the budget shares.
    """
    if code not in ("B001", "B002", "B005"):
        return None
    raw = getattr(ctx, "options", None) or {}
    if code == "B001":
        return 1.0  # the binding itself and the link triangles
    budget = raw.get("budget_s")
    if budget is None:
        from ..rerender import DEFAULT_BUDGET_S

        budget = DEFAULT_BUDGET_S
    share = PASS_SHARE if code == "B002" else 1.0 - PASS_SHARE
    return float(budget) * share * (10.0 if raw.get("full") else 1.0) + 0.5


def run_notes(ctx: CheckContext) -> list[str]:
    """Notes on what the re-render left out of this run (one per subsampled camera stream).

    Example: ``binding re-render ep000/camera/cam0: labels compared on 9 of 120 frames (0.17 s
    per frame) and the time offset and camera fitted on 2 of 8 fast-moving frames (0.16 s per
    render), to stay within the 4 s re-render budget; --full for all``. When the minimum frame
    counts cost more than the budget, the note says so instead of "to stay within".
    """
    notes: dict[tuple[str, str], dict[str, str]] = _state(ctx).get("notes", {})
    out = []
    budget = f"{rerender_options(ctx).budget_s:g} s re-render budget"
    for (ep, stream), parts in notes.items():
        said = " and ".join(parts[k] for k in ("pass", "fit") if k in parts)
        over = parts.get("over")
        why = f"the minimum counts, over the {budget}" if over else f"to stay within the {budget}"
        out.append(f"binding re-render {ep}/{stream}: {said}, {why}; --full for all")
    return out


def _note(ctx: CheckContext, job: _CameraJob, part: str, text: str) -> None:
    _state(ctx).setdefault("notes", {}).setdefault((job.ep.id, job.stream), {})[part] = text


def _fraction(ctx: CheckContext) -> Callable[[float], None]:
    """The progress hook for the fraction of a long check done (a no-op outside the validator)."""
    hook = getattr(getattr(ctx, "progress", None), "fraction", None)
    return hook if callable(hook) else (lambda _f: None)


def _state(ctx: CheckContext) -> dict[Any, Any]:
    if ctx not in _STATE:
        _STATE[ctx] = {}
    return _STATE[ctx]


def _cached(ctx: CheckContext, key: Any, build: Any) -> Any:
    st = _state(ctx)
    if key not in st:
        try:
            st[key] = build()
        except (RobogsError, InputReported) as exc:
            st[key] = exc
    value = st[key]
    if isinstance(value, RobogsError | InputReported):
        raise value
    return value


# ------------------------------------------------------------------------------- inputs


def _splat_owners(ctx: CheckContext) -> list[tuple[str, dict[str, Any]]]:
    """``(owner, manifest splat entry)`` for the robot and every asset with splats (safe paths only)."""
    out = []
    robot = ctx.manifest.get("robot")
    if isinstance(robot, dict) and isinstance(robot.get("splats"), dict):
        out.append(("robot", robot["splats"]))
    assets = ctx.manifest.get("assets")
    for name, a in sorted(assets.items()) if isinstance(assets, dict) else []:
        if isinstance(a, dict) and isinstance(a.get("splats"), dict):
            out.append((name, a["splats"]))
    usable = []
    for owner, entry in out:
        try:
            ctx.existing(entry.get("path"), where=f"{owner}/splats/path")
        except InputReported:
            continue
        usable.append((owner, entry))
    return usable


def _binding(ctx: CheckContext, ep: Episode) -> Binding:
    """The episode's binding (cached); no splats at all: :class:`InputReported`."""
    from ..binding import Binding

    if not _splat_owners(ctx):
        raise InputReported("splats")
    opts = rerender_options(ctx)
    return _cached(
        ctx,
        ("binding", ep.id),
        lambda: Binding(
            ctx.dataset, ep.id, owners=[o for o, _ in _splat_owners(ctx)], device=opts.device
        ),
    )


@dataclass
class _CameraJob:
    ep: Episode
    stream: str
    entry: dict[str, Any]
    model: CameraModel


def _camera_jobs(ctx: CheckContext) -> Iterator[_CameraJob]:
    """Labelled camera streams whose camera, frames and labels can be read."""
    for ep, name, st in ctx.streams(("camera",)):
        if not all(isinstance(st.get(k), str) for k in ("frames", "labels", "camera")):
            continue
        try:
            model = ctx.camera(st["camera"])
            ctx.existing(st["frames"])
            ctx.existing(st["labels"])
        except (InputReported, RobogsError, KeyError, ValueError, TypeError):
            continue
        yield _CameraJob(ep, name, st, model)


def _segments(ctx: CheckContext, ep: Episode) -> Any:
    name = ctx.find_stream(ep, "segments")
    if name is None:
        raise InputReported("segments")
    return ctx.stream_table(ep, name)


def _render_camera_ok(model: CameraModel) -> list[str]:
    """Why a stored camera cannot be rendered from (degenerate values), as messages."""
    import torch

    from ..render import Camera, validate_camera

    T = model.T_world_cam if model.T_world_cam is not None else np.eye(4)
    try:
        cam = Camera(
            width=model.width,
            height=model.height,
            fx=model.fx,
            fy=model.fy,
            cx=model.cx,
            cy=model.cy,
            T_world_cam=torch.as_tensor(np.asarray(T, np.float64)),
            distortion_model=model.distortion_model,
            distortion=tuple(model.distortion),
        )
    except (TypeError, ValueError) as exc:
        return [str(exc)]
    return [
        f"{p.where} {p.message}"
        for p in validate_camera(cam)
        if p.where != "camera.distortion_model"
    ]


def _pose_of(ctx: CheckContext, job: _CameraJob) -> Any:
    from ..rerender import pose_stream

    if job.model.extrinsics != "time_varying":
        return None
    rel = job.entry.get("extrinsics")
    if not isinstance(rel, str):
        raise InputReported(f"{job.stream}/extrinsics")
    tab = ctx.table(rel)
    return pose_stream(
        column(tab, "t_ns").astype(np.int64),
        stack_columns(tab, ("x", "y", "z")),
        stack_columns(tab, ("qw", "qx", "qy", "qz")),
    )


# ------------------------------------------------------------------------------- re-render pass


@dataclass
class _Pass:
    """Per-frame measurements of one camera stream (arrays [F, C] unless noted)."""

    channels: LabelChannels
    frame_index: np.ndarray  # [F]
    t_ns: np.ndarray  # [F]
    inter: np.ndarray
    union: np.ndarray
    recorded: np.ndarray
    rendered: np.ndarray
    bsum: np.ndarray
    bcnt: np.ndarray
    depth: np.ndarray
    psnr: np.ndarray  # [F]
    fx: float  # full-resolution focal length, px
    rr: SceneRerenderer
    lut: np.ndarray
    skipped: str | None = None
    notes: list[str] = field(default_factory=list)
    plan: FramePlan | None = None  # which candidate frames were compared


def _rerenderer(ctx: CheckContext, job: _CameraJob) -> tuple[SceneRerenderer, np.ndarray]:
    def build() -> tuple[SceneRerenderer, np.ndarray]:
        from ..rerender import SceneRerenderer, label_channels

        problems = _render_camera_ok(job.model)
        if problems or job.model.T_world_cam is None and job.model.extrinsics != "time_varying":
            raise InputReported(f"cameras/{job.model.name}")  # B009 reports it
        from ..render.camera import DISTORTION_MODELS

        if job.model.distortion_model not in DISTORTION_MODELS:
            raise FormatError(
                f"the renderer has no {job.model.distortion_model!r} lens model",
                hint=f"re-render supports {', '.join(sorted(DISTORTION_MODELS))}",
            )
        b = _binding(ctx, job.ep)
        channels = label_channels(b, _segments(ctx, job.ep))
        opts = rerender_options(ctx)
        rr = SceneRerenderer(
            b,
            job.model,
            channels,
            scale=opts.scale,
            backend=opts.backend,
            pose_of=_pose_of(ctx, job),
        )
        return rr, channels.lookup()

    return _cached(ctx, ("rerenderer", job.ep.id, job.stream), build)


def _frames(ctx: CheckContext, job: _CameraJob) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and frame indices of every ``stride``-th frame (the label pass's candidates)."""
    t, fi = frame_stamps(ctx.table(job.entry["frames"], columns=("t_ns", "frame_index")))
    k = rerender_options(ctx).stride
    return t[::k], fi[::k]


def _job_budget_s(ctx: CheckContext) -> float:
    """Wall time one camera stream's re-render may take, s (``inf`` with ``full``)."""
    opts = rerender_options(ctx)
    if opts.full:
        return math.inf
    n = _cached(ctx, ("n_jobs",), lambda: sum(1 for _ in _camera_jobs(ctx)))
    return float(opts.budget_s) / max(int(n), 1)


def _candidates(ctx: CheckContext, job: _CameraJob) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps, frame indices and image motion (px per 20 ms) of frames spread over the stream.

    Every frame of short streams, about :data:`FIT_CANDIDATES` (``full``: 600) of long ones;
    the alignment fit picks its frames here and the label pass its fastest and slowest.
    """

    def build() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rr, _lut = _rerenderer(ctx, job)
        t, fi = frame_stamps(ctx.table(job.entry["frames"], columns=("t_ns", "frame_index")))
        step = max(1, len(t) // (600 if rerender_options(ctx).full else FIT_CANDIDATES))
        t, fi = t[::step], fi[::step]
        return t, fi, rr.image_motion_px(t)

    return _cached(ctx, ("candidates", job.ep.id, job.stream), build)


def _render_cost(ctx: CheckContext, job: _CameraJob, t_ns: np.ndarray) -> float:
    """Wall seconds of one plain render of this stream: given, timed by the pass, or probed."""
    given = rerender_options(ctx).frame_cost_s
    if given is not None:
        return float(given)
    st = _state(ctx)
    key = ("render_s", job.ep.id, job.stream)
    if key not in st:
        rr, _lut = _rerenderer(ctx, job)
        rr.render(int(t_ns[0]))  # warm-up: first-call costs are not per-frame costs
        t0 = time.perf_counter()
        rr.render(int(t_ns[len(t_ns) // 2]))
        st[key] = time.perf_counter() - t0
    return float(st[key])


def _pass_must(ctx: CheckContext, job: _CameraJob, t_ns: np.ndarray) -> list[int]:
    """Pass candidates that matter: nearest to the fastest and the slowest image motion."""
    tc, _fi, motion = _candidates(ctx, job)
    if len(tc) == 0 or not np.isfinite(motion).all() or motion.max(initial=0.0) <= 0.0:
        return []
    out = []
    for k in (int(np.argmax(motion)), int(np.argmin(motion))):
        j = int(np.clip(np.searchsorted(t_ns, tc[k]), 0, len(t_ns) - 1))
        if j > 0 and abs(int(t_ns[j - 1]) - int(tc[k])) <= abs(int(t_ns[j]) - int(tc[k])):
            j -= 1
        out.append(j)
    return out


def _run_pass(ctx: CheckContext, job: _CameraJob) -> _Pass:
    from ..rerender import (
        MIN_PASS_FRAMES,
        FramePlan,
        compare_frame,
        foreground_psnr,
        plan_frames,
        read_label_frames,
        read_video_frames,
    )

    start = time.perf_counter()  # set-up counts against the budget too
    rr, lut = _rerenderer(ctx, job)
    ch = rr.channels
    t, fi = _frames(ctx, job)
    C, n = ch.count, len(fi)
    sx = job.model.width / rr.width
    if C == 0:
        every = FramePlan(np.arange(n), n, math.inf, math.nan)
        result = _assemble(ch, fi, t, every, {}, rr, lut, rr.fx * sx)
        result.skipped = "no bound target has a segment (label id) to compare with"
        return result
    ctx.progress(f"re-rendering {job.ep.id}/{job.stream}")
    opts = rerender_options(ctx)
    labels_path = ctx.existing(job.entry["labels"])
    video = job.entry.get("video")
    metrics: dict[int, FrameMetrics] = {}
    rgbs: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    seen: set[int] = set()
    notes: list[str] = []
    render_s: list[float] = []
    fraction = _fraction(ctx)
    planned = [min(n, MIN_PASS_FRAMES)]

    def compare(keys: list[int]) -> None:
        want = {int(fi[k]): k for k in keys if k not in seen}
        for i, lab in read_label_frames(labels_path, list(want)):
            k = want[i]
            if k in seen:
                continue
            seen.add(k)
            if lab.shape != (job.model.height, job.model.width):
                notes.append(
                    f"frame {i}: label image is {lab.shape[1]}x{lab.shape[0]}, "
                    f"camera says {job.model.width}x{job.model.height}"
                )
                continue
            t0 = time.perf_counter()
            out = rr.render(int(t[k]))
            render_s.append(time.perf_counter() - t0)
            p = rr.probabilities(out)
            metrics[k] = compare_frame(p, out.depth_median.detach().cpu().numpy(), lut[lab], C)
            if isinstance(video, str):
                rgbs[k] = (out.rgb.detach().cpu().numpy(), out.alpha.detach().cpu().numpy())
            fraction(min(1.0, len(seen) / max(planned[0], 1)))

    budget = _job_budget_s(ctx) * PASS_SHARE
    if math.isinf(budget) or n <= MIN_PASS_FRAMES:
        plan = FramePlan(np.arange(n), n, budget, math.nan)
    else:
        # time the two ends (always in the plan): the first absorbs the warm-up, the second is
        # the per-frame cost (render, label decode and comparison)
        must = _pass_must(ctx, job, t)
        compare([0])
        t1 = time.perf_counter()
        compare([n - 1])
        t2 = time.perf_counter()
        key = ("render_s", job.ep.id, job.stream)
        if render_s:
            _state(ctx).setdefault(key, render_s[-1])
        if opts.frame_cost_s is not None:
            cost, allowed = float(opts.frame_cost_s), budget
        else:
            cost = (t2 - t1) if len(seen) == 2 and (n - 1) in metrics else _render_cost(ctx, job, t)
            allowed = budget - (t2 - start) + 2.0 * cost  # what is left, plus the two frames done
        plan = plan_frames(n, cost, allowed, min_frames=MIN_PASS_FRAMES, must=must)
        if plan.subsampled:
            _note(
                ctx,
                job,
                "pass",
                f"labels compared on {plan.count} of {n} frames ({cost:.2g} s per frame)",
            )
            if plan.floor:
                _note(ctx, job, "over", "pass")
    planned[0] = plan.count
    compare([int(k) for k in plan.chosen])
    result = _assemble(ch, fi, t, plan, metrics, rr, lut, rr.fx * sx)
    result.notes.extend(notes)
    pos = {int(fi[k]): j for j, k in enumerate(plan.chosen)}
    if isinstance(video, str) and rgbs:
        try:
            for i, img in read_video_frames(ctx.existing(video), sorted(int(fi[k]) for k in rgbs)):
                rgb, alpha = rgbs.pop(int(plan.chosen[pos[i]]))
                result.psnr[pos[i]] = foreground_psnr(rgb, alpha, img)
        except (RobogsError, InputReported) as exc:
            result.notes.append(f"video not compared: {getattr(exc, 'message', exc)}")
    missing = plan.count - sum(1 for k in plan.chosen if int(k) in seen)
    if missing:
        result.notes.append(f"{missing} of {plan.count} frames have no label image")
    return result


def _assemble(
    ch: LabelChannels,
    fi: np.ndarray,
    t: np.ndarray,
    plan: FramePlan,
    metrics: dict[int, FrameMetrics],
    rr: SceneRerenderer,
    lut: np.ndarray,
    fx: float,
) -> _Pass:
    """The pass arrays [F, C] of the planned frames (zeros / NaN where a frame was not compared)."""
    F, C = plan.count, ch.count
    arrays = {
        k: np.zeros((F, C)) for k in ("inter", "union", "recorded", "rendered", "bsum", "bcnt")
    }
    depth = np.full((F, C), np.nan)
    for j, k in enumerate(plan.chosen):
        m = metrics.get(int(k))
        if m is None:
            continue
        for name, value in (
            ("inter", m.inter),
            ("union", m.union),
            ("recorded", m.recorded),
            ("rendered", m.rendered),
            ("bsum", m.boundary_sum),
            ("bcnt", m.boundary_count),
        ):
            arrays[name][j] = value
        depth[j] = m.depth_m
    chosen = plan.chosen
    return _Pass(
        ch,
        fi[chosen],
        t[chosen],
        *arrays.values(),
        depth,
        np.full(F, np.nan),
        fx,
        rr,
        lut,
        plan=plan,
    )


def _boundary_mm(ps: _Pass) -> np.ndarray:
    """[F, C] summed boundary distances in mm: px x rendered depth / focal length (frames
    without a depth use the median depth of the pass)."""
    from ..rerender import boundary_mm

    return boundary_mm(ps.bsum, ps.depth, ps.fx)


def _pass(ctx: CheckContext, job: _CameraJob) -> _Pass:
    return _cached(ctx, ("pass", job.ep.id, job.stream), lambda: _run_pass(ctx, job))


def _fit(ctx: CheckContext, job: _CameraJob) -> AlignmentFit | None:
    def build() -> AlignmentFit | None:
        from ..rerender import (
            FIT_FRAME_RENDERS,
            fit_alignment,
            fit_frame_count,
            read_label_frames,
            recorded_soft_labels,
            select_fit_frames,
        )

        rr, lut = _rerenderer(ctx, job)
        if rr.channels.count == 0:
            return None
        t, fi, motion = _candidates(ctx, job)
        if len(t) == 0:
            return None
        opts = rerender_options(ctx)
        budget = _job_budget_s(ctx) * (1.0 - PASS_SHARE)
        k = opts.fit_frames
        if not math.isinf(budget) and len(t) > 1:
            render_s = _render_cost(ctx, job, t)
            k = fit_frame_count(render_s, budget, opts.fit_frames)
            if k * FIT_FRAME_RENDERS * render_s > budget:
                _note(ctx, job, "over", "fit")  # the minimum count costs more than the budget
            if k < min(opts.fit_frames, len(t)):
                _note(
                    ctx,
                    job,
                    "fit",
                    f"the time offset and camera fitted on {k} of {min(opts.fit_frames, len(t))} "
                    f"fast-moving frames ({render_s:.2g} s per render)",
                )
        sel = select_fit_frames(t, motion, k)
        ys = {
            i: recorded_soft_labels(lut[lab], rr.channels.count, rr.width, rr.height)
            for i, lab in read_label_frames(ctx.existing(job.entry["labels"]), fi[sel])
            if lab.shape == (job.model.height, job.model.width)
        }
        keep = [k for k in sel if int(fi[k]) in ys]
        if not keep:
            return None
        ctx.progress(f"fitting time offset and camera {job.ep.id}/{job.stream}")
        moving = motion[keep]
        return fit_alignment(
            rr,
            t[keep],
            [ys[int(fi[k])] for k in keep],
            motion_px=moving,
            fit_offset=bool(moving.max() >= MIN_MOTION_PX),
            max_offset_ms=opts.max_offset_ms,
            progress=_fraction(ctx),
        )

    return _cached(ctx, ("fit", job.ep.id, job.stream), build)


def alignment_fit(ctx: CheckContext, episode: str, stream: str) -> AlignmentFit | None:
    """The time-offset and camera-displacement fit of one camera stream (cached per context).

    Args:
        ctx: the validation context.
        episode: episode id.
        stream: camera stream name.

    Returns:
        The fit, or None when the stream has no comparable labels.

    Raises:
        InputReported: the stream's camera, frames or labels are unusable (reported elsewhere).
    """
    for job in _camera_jobs(ctx):
        if job.ep.id == episode and job.stream == stream:
            return _fit(ctx, job)
    raise InputReported(f"{episode}/{stream}")


@dataclass(frozen=True)
class LabelSummary:
    """Re-render agreement of one link or object over the compared frames of a camera stream.

    Attributes:
        name: link or object name.
        label_id: its panoptic label id.
        iou: pooled IoU outside the void band (NaN when it has no pixels).
        boundary_px: mean symmetric boundary distance, px (NaN without boundaries).
        boundary_mm: the same at the rendered depth, mm.
        pixels: non-void union summed over the frames, px.
    """

    name: str
    label_id: int
    iou: float
    boundary_px: float
    boundary_mm: float
    pixels: int


def label_summary(ctx: CheckContext, episode: str, stream: str) -> list[LabelSummary]:
    """Per link/object agreement of the re-render with the recorded labels (cached pass).

    Raises:
        InputReported: the stream's camera, frames or labels are unusable (reported elsewhere).
    """
    for job in _camera_jobs(ctx):
        if job.ep.id != episode or job.stream != stream:
            continue
        ps = _pass(ctx, job)
        mm = _boundary_mm(ps)
        out = []
        for c, name in enumerate(ps.channels.names):
            u, n = ps.union[:, c].sum(), ps.bcnt[:, c].sum()
            out.append(
                LabelSummary(
                    name,
                    int(ps.channels.label_ids[c]),
                    float(ps.inter[:, c].sum() / u) if u else float("nan"),
                    float(ps.bsum[:, c].sum() / n) if n else float("nan"),
                    float(np.nansum(mm[:, c]) / n) if n else float("nan"),
                    int(u),
                )
            )
        return out
    raise InputReported(f"{episode}/{stream}")


def _where(job: _CameraJob, name: str, kind: str) -> dict[str, Any]:
    loc: dict[str, Any] = {"episode": job.ep.id, "stream": job.stream}
    loc["link" if kind == "robot_link" else "object"] = name
    return loc


# ------------------------------------------------------------------------------- B001 face distance


def _rest_q(ctx: CheckContext, entry: dict[str, Any]) -> torch.Tensor:
    import torch

    chain = ctx.chain()
    rest = (entry.get("rest") or {}).get("joint_positions") or {}
    missing = [j for j in chain.joint_names if j not in rest]
    if missing:
        raise FormatError(
            f"robot splats' rest state lacks joints {', '.join(missing[:5])}",
            path=ctx.dataset.manifest_path,
            where="/robot/splats/rest/joint_positions",
            hint="record every actuated joint's position at the rest state",
        )
    return torch.tensor([float(rest[j]) for j in chain.joint_names], dtype=torch.float64)


def _link_triangles(ctx: CheckContext, entry: dict[str, Any]) -> dict[str, np.ndarray | str]:
    """Per link: world triangles [F, 3, 3] of its first visual mesh at the rest state, or why none."""
    import torch

    from ..meshes import load_mesh

    urdf = ctx.urdf()
    chain = ctx.fitted_chain()[0]
    T = chain.forward(_rest_q(ctx, entry))  # [L, 4, 4] root frame
    base = (ctx.manifest.get("robot") or {}).get("base_link")
    if isinstance(base, str) and base in chain.link_names and base != chain.link_names[0]:
        T = torch.linalg.inv(T[chain.link_index(base)]) @ T
    resolved = {(r.link, r.kind, r.uri): r.path for r in getattr(urdf, "robogs_mesh_refs", [])}
    out: dict[str, np.ndarray | str] = {}
    for link in urdf.robot.links:
        visual = next(
            (v for v in link.visuals if v.geometry is not None and v.geometry.mesh is not None),
            None,
        )
        if visual is None:
            out[link.name] = "has no visual mesh"
            continue
        path = resolved.get((link.name, "visual", visual.geometry.mesh.filename))
        if path is None or link.name not in chain.link_names:
            out[link.name] = "visual mesh could not be resolved"
            continue
        try:
            mesh = load_mesh(path, where=f"link {link.name} visual")
        except RobogsError as exc:
            out[link.name] = f"has an unreadable visual mesh ({exc.message})"
            continue
        v = np.asarray(mesh.vertices, np.float64)
        f = np.asarray(mesh.faces, np.int64)
        if visual.geometry.mesh.scale is not None:
            v = v * np.broadcast_to(np.asarray(visual.geometry.mesh.scale, np.float64), (3,))
        M = T[chain.link_index(link.name)].numpy() @ np.asarray(
            visual.origin if visual.origin is not None else np.eye(4), np.float64
        )
        out[link.name] = (v @ M[:3, :3].T + M[:3, 3])[f]
    return out


def _asset_triangles(ctx: CheckContext, name: str, entry: dict[str, Any]) -> np.ndarray | str:
    """World triangles of an asset's mesh at its rest pose (identity when none is declared)."""
    from ..frames import quat_to_matrix

    if name not in ctx.asset_names():
        return "is not an asset of the manifest"
    mesh = ctx.asset_mesh(name)
    pose = ((entry.get("rest") or {}).get("object_poses") or {}).get(name)
    M = np.eye(4)
    if pose is not None:
        pose = np.asarray(pose, np.float64)
        M[:3, :3] = quat_to_matrix(pose[3:7] / max(np.linalg.norm(pose[3:7]), 1e-12))
        M[:3, 3] = pose[:3]
    v = np.asarray(mesh.vertices, np.float64)
    return (v @ M[:3, :3].T + M[:3, 3])[np.asarray(mesh.faces, np.int64)]


def _face_points(
    tri: np.ndarray, face: np.ndarray, uv: np.ndarray, offset: np.ndarray
) -> np.ndarray:
    """Bound positions [N, 3]: barycentric point of ``face`` plus ``offset`` along its unit normal (NaN if degenerate)."""
    t = tri[face]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(norm > 1e-15, n / np.where(norm > 1e-15, norm, 1.0), np.nan)
    w = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], 1)
    p = np.einsum("nk,nkd->nd", w, t)
    return p + np.where(offset[:, None] != 0.0, offset[:, None] * n, 0.0)


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "B001",
    group="binding",
    severity="error",
    title="bound Gaussians sit on their faces",
    quantity="largest distance of a Gaussian centre to its face point plus offset",
    unit="mm",
    budget="binding.face_distance_mm",
    hint="re-run the binding (nearest face, barycentric weights and normal offset at the rest state), "
    "or check bind_id, the rest state and the target mesh",
)
def _face_distance(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("binding.face_distance_mm")
    for owner, entry in _splat_owners(ctx):
        rel = entry["path"]
        s = ctx.dataset.splats(owner)
        targets = [str(x) for x in entry.get("targets") or []]
        if owner == "robot":
            tris: dict[str, np.ndarray | str] = _link_triangles(ctx, entry)
            tris = {n: tris.get(n, "is not a link of the URDF") for n in targets}
        else:
            tris = {n: _asset_triangles(ctx, n, entry) for n in targets}
        bound = (s.bind_id >= 0) & (s.bind_id < len(targets)) & (s.bind_face >= 0)
        means = s.means.astype(np.float64)
        uv = s.bind_uv.astype(np.float64)
        off = s.bind_offset.astype(np.float64)
        dist = np.full(len(s), np.nan)
        for k, name in enumerate(targets):
            sel = np.flatnonzero(bound & (s.bind_id == k))
            if sel.size == 0:
                continue
            tri = tris[name]
            kind = "robot_link" if owner == "robot" else "object"
            loc = {"file": rel, "link" if kind == "robot_link" else "object": name}
            if isinstance(tri, str):
                yield chk.finding(
                    f"{sel.size} Gaussians are bound to faces of {name!r}, which {tri}",
                    value=None,
                    hint="bind them to a target with a mesh, or set bind_face to -1",
                    **loc,
                )
                continue
            face = s.bind_face[sel].astype(np.int64)
            out_of_range = face >= len(tri)
            if out_of_range.any():
                yield chk.finding(
                    f"{int(out_of_range.sum())} Gaussians bound to {name!r} name faces beyond its "
                    f"{len(tri)} triangles (largest {int(face.max())})",
                    hint="bind_face must index the target mesh's triangles",
                    where="bind_face",
                    **loc,
                )
            ok = sel[~out_of_range]
            if ok.size == 0:
                continue
            p = _face_points(tri, s.bind_face[ok].astype(np.int64), uv[ok], off[ok])
            dist[ok] = np.linalg.norm(means[ok] - p, axis=1) * 1e3
            d = dist[ok]
            bad = ~(d <= budget)
            if not bad.any():
                continue
            worst = int(ok[np.nanargmax(np.where(np.isnan(d), np.inf, d))])
            value = float(np.nanmax(np.where(np.isnan(d), np.inf, d)))
            msg = (
                f"{int(bad.sum())} of {ok.size} Gaussians bound to {name!r} lie off their face "
                f"(largest {value:.4g} mm at Gaussian {worst}, median {float(np.nanmedian(d)):.4g} mm)"
            )
            other = _better_target(
                tris, name, means[ok[bad]], s.bind_face[ok[bad]], uv[ok[bad]], off[ok[bad]], budget
            )
            if other is not None:
                msg += f"; they lie on the same faces of {other!r}: their bind_id names the wrong target"
            yield chk.finding(msg, value=value, budget=budget, where=f"vertex {worst}", **loc)


def _better_target(
    tris: dict[str, np.ndarray | str],
    name: str,
    x: np.ndarray,
    face: np.ndarray,
    uv: np.ndarray,
    off: np.ndarray,
    budget: float,
) -> str | None:
    """The other target whose same faces the misplaced Gaussians sit on (median within budget)."""
    take = np.arange(min(len(x), 2000))
    best, best_d = None, budget
    for other, tri in tris.items():
        if other == name or isinstance(tri, str):
            continue
        f = face[take].astype(np.int64)
        inside = f < len(tri)
        if inside.mean() < 0.9:
            continue
        p = _face_points(tri, f[inside], uv[take][inside], off[take][inside])
        d = float(np.nanmedian(np.linalg.norm(x[take][inside] - p, axis=1))) * 1e3
        if d <= best_d:
            best, best_d = other, d
    return best


# ------------------------------------------------------------------------------- B002-B004 labels


@check(
    "B002",
    group="binding",
    severity="warning",
    title="re-rendered labels overlap the recorded ones",
    quantity="IoU per link/object over the compared frames, outside a 2 px void band at label edges",
    unit="ratio",
    budget="binding.iou_min",
    hint="a link or object re-renders where the recorded labels do not have it: check its bind_id, "
    "its poses (joint states, object poses) and the segments table",
)
def _iou(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("binding.iou_min")
    for job in _camera_jobs(ctx):
        ps = _pass(ctx, job)
        if ps.skipped:
            yield chk.finding(
                f"labels not re-rendered: {ps.skipped}",
                severity="info",
                episode=job.ep.id,
                stream=job.stream,
            )
            continue
        for note in ps.notes:
            yield chk.finding(
                f"re-render: {note}", severity="info", episode=job.ep.id, stream=job.stream
            )
        inter, union = ps.inter.sum(0), ps.union.sum(0)
        for c, name in enumerate(ps.channels.names):
            loc = _where(job, name, ps.channels.kinds[c])
            if union[c] < IOU_MIN_PIXELS:
                continue
            iou = inter[c] / union[c]
            if iou >= budget:
                continue
            per = np.where(
                ps.union[:, c] > 0, ps.inter[:, c] / np.maximum(ps.union[:, c], 1), np.inf
            )
            k = int(np.argmin(per))
            yield chk.finding(
                f"{name!r} re-renders with IoU {iou:.3f} against label {int(ps.channels.label_ids[c])} over "
                f"{len(ps.frame_index)} frames (worst frame {int(ps.frame_index[k])}: IoU {per[k]:.3f}, "
                f"{int(ps.recorded[k, c])} recorded vs {int(ps.rendered[k, c])} re-rendered px)",
                value=float(iou),
                budget=budget,
                frame=int(ps.frame_index[k]),
                t_ns=int(ps.t_ns[k]),
                **loc,
            )


@check(
    "B003",
    group="binding",
    severity="warning",
    title="re-rendered label boundaries match the recorded ones",
    quantity="mean symmetric boundary distance per link/object, flagged above both the px and the mm "
    "(binding.boundary_mm, at the rendered depth) budgets",
    unit="px",
    budget="binding.boundary_px",
    hint="boundaries are off by more than the budget: check the splat scales, the binding and the camera "
    "intrinsics; B005 and B006 tell a time offset or a camera displacement apart",
)
def _boundary(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    b_px = ctx.budget("binding.boundary_px")
    b_mm = ctx.budget("binding.boundary_mm")
    for job in _camera_jobs(ctx):
        ps = _pass(ctx, job)
        if ps.skipped:
            continue
        mm = _boundary_mm(ps)
        for c, name in enumerate(ps.channels.names):
            n = ps.bcnt[:, c].sum()
            if n == 0:
                continue
            px = ps.bsum[:, c].sum() / n
            mean_mm = float(np.nansum(mm[:, c]) / n)
            if px <= b_px or not mean_mm > b_mm:
                continue  # within the pixel grid's reach or physically negligible
            per = np.where(ps.bcnt[:, c] > 0, ps.bsum[:, c] / np.maximum(ps.bcnt[:, c], 1), -np.inf)
            k = int(np.argmax(per))
            loc = _where(job, name, ps.channels.kinds[c])
            yield chk.finding(
                f"{name!r} re-renders with boundaries {px:.3g} px ({mean_mm:.3g} mm at its depth) from the recorded "
                f"ones, above both budgets ({b_px:g} px, {b_mm:g} mm; worst frame {int(ps.frame_index[k])}: "
                f"{per[k]:.3g} px)",
                value=px,
                budget=b_px,
                frame=int(ps.frame_index[k]),
                t_ns=int(ps.t_ns[k]),
                **loc,
            )


@check(
    "B004",
    group="binding",
    severity="warning",
    title="re-rendered colour matches the video",
    quantity="mean PSNR of the re-rendered foreground (alpha >= 0.5) against the video frames, "
    "flagged below the floor",
    unit="dB",
    budget="binding.psnr_min_db",
    hint="low PSNR with good labels points at colour rather than geometry: exposure, white balance, "
    "SH coefficients, or splat colours stored in linear RGB instead of the images' colour space (sRGB)",
)
def _psnr(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    floor = ctx.budget("binding.psnr_min_db")
    for job in _camera_jobs(ctx):
        ps = _pass(ctx, job)
        ok = np.isfinite(ps.psnr)
        if ps.skipped or not ok.any():
            continue
        mean = float(np.mean(ps.psnr[ok]))
        if mean >= floor:
            continue
        k = int(np.flatnonzero(ok)[np.argmin(ps.psnr[ok])])
        yield chk.finding(
            f"re-rendered colour has PSNR {mean:.2f} dB over {int(ok.sum())} frames, below the "
            f"{floor:g} dB floor (foreground only; worst frame {int(ps.frame_index[k])}: "
            f"{ps.psnr[k]:.2f} dB)",
            value=mean,
            budget=floor,
            episode=job.ep.id,
            stream=job.stream,
            frame=int(ps.frame_index[k]),
            t_ns=int(ps.t_ns[k]),
        )


# ------------------------------------------------------------------------------- B005-B006 alignment


#: per-frame uncertainty of label edge placement after averaging along the edges, px; measured on
#: the synthetic scenes (160x120 and 320x240: offset estimates scatter by 0.6-1.4 ms with 8 frames
#: moving 0.5 px per 20 ms, i.e. about 0.07 px per frame)
EDGE_SIGMA_PX = 0.1


def _offset_resolution_ms(fit: AlignmentFit) -> float:
    """Standard error of the offset estimate the images allow, ms.

    A frame whose labels move ``v`` px per 20 ms resolves time to ``EDGE_SIGMA_PX · 20 / v`` ms;
    ``n`` frames average that down by ``√n``. Offsets within three standard errors are not
    reported.
    """
    speeds = np.asarray([v for v in fit.motion_px if v > 0], dtype=float)
    if speeds.size == 0:
        return math.inf
    per_frame = EDGE_SIGMA_PX * 20.0 / speeds
    return float(1.0 / np.sqrt(np.sum(1.0 / per_frame**2)))


@check(
    "B005",
    group="binding",
    severity="error",
    title="camera stamps agree with the re-render in time",
    quantity="time shift that best aligns re-rendered and recorded labels, reported beyond the "
    "budget and three standard errors of what the image motion resolves",
    unit="ms",
    budget="time.offset_ms",
    hint="correct the camera stream's offset_ns (or its stamp source) by the estimate",
)
def _time_offset(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.offset_ms")
    for job in _camera_jobs(ctx):
        fit = _fit(ctx, job)
        if fit is None:
            continue
        loc = {"episode": job.ep.id, "stream": job.stream}
        if not fit.offset_observable:
            yield chk.finding(
                "time offset not estimated: the compared frames show no motion",
                severity="info",
                **loc,
            )
            continue
        late = -fit.offset_ms
        declared = float(job.entry.get("offset_ns") or 0) * 1e-6
        if abs(late) <= max(budget, 3.0 * _offset_resolution_ms(fit)) or not math.isfinite(late):
            continue
        yield chk.finding(
            f"camera {job.model.name!r} frames are stamped {late:+.2f} ms late against the joint and object "
            f"streams (from {len(fit.frames)} moving frames; declared offset_ns {declared:g} ms, "
            f"aligned with {declared - late:.2f} ms)",
            value=late,
            budget=budget,
            **loc,
        )


@check(
    "B006",
    group="binding",
    severity="error",
    title="camera extrinsics agree with the re-render",
    quantity="camera displacement across the optical axis that best aligns the labels",
    unit="mm",
    budget="binding.extrinsic_mm",
    hint="re-calibrate T_world_cam (hand-eye or a target); the estimate gives the direction",
)
def _extrinsic(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("binding.extrinsic_mm")
    for job in _camera_jobs(ctx):
        fit = _fit(ctx, job)
        if fit is None:
            continue
        mm = fit.shift_2d_mm
        if mm <= budget:
            continue
        err = -fit.shift_mm
        yield chk.finding(
            f"camera {job.model.name!r} appears displaced by {mm:.2f} mm across its optical axis "
            f"(x {err[0]:+.2f} mm, y {err[1]:+.2f} mm in the camera frame; from {len(fit.frames)} frames, "
            f"label disagreement {fit.cost_before:.0f} -> {fit.cost_after:.0f} px)",
            value=mm,
            budget=budget,
            episode=job.ep.id,
            stream=job.stream,
            file=(ctx.manifest.get("cameras") or {}).get(job.model.name),
        )


# ------------------------------------------------------------------------------- B007-B011 inputs


@check(
    "B007",
    group="binding",
    severity="error",
    title="splat values are finite and plausible",
    quantity="Gaussians with NaN/inf values, zero or absurd scales, zero rotations or bad bind ids",
    hint="drop or re-fit these Gaussians; log-scales must be finite and below log(10 m)",
)
def _bad_splats(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    from ..rerender import MAX_LOG_SCALE

    for owner, entry in _splat_owners(ctx):
        rel = entry["path"]
        s = ctx.dataset.splats(owner)
        n = len(s)
        if n == 0:
            continue
        ls = s.log_scales.astype(np.float64)
        tests = [
            ("non-finite centre", ~np.isfinite(s.means).all(1)),
            ("non-finite rotation", ~np.isfinite(s.quats).all(1)),
            (
                "zero rotation quaternion",
                np.isfinite(s.quats).all(1) & (np.linalg.norm(s.quats, axis=1) < 1e-8),
            ),
            ("NaN or +inf log-scale", (np.isnan(ls) | np.isposinf(ls)).any(1)),
            ("zero scale (log-scale -inf)", np.isneginf(ls).any(1)),
            (
                f"scale above {math.exp(MAX_LOG_SCALE):g} m",
                (ls >= MAX_LOG_SCALE).any(1) & np.isfinite(ls).all(1),
            ),
            ("NaN opacity", np.isnan(s.opacity_logits)),
            ("non-finite colour", ~np.isfinite(s.sh.reshape(n, -1)).all(1)),
            (
                "bind_id outside the targets",
                (s.bind_id < -1) | (s.bind_id >= len(entry.get("targets") or [])),
            ),
        ]
        for what, mask in tests:
            if mask.any():
                first = int(np.flatnonzero(mask)[0])
                yield chk.finding(
                    f"{int(mask.sum())} of {n} Gaussians of {owner!r} have a {what} (first: vertex {first})",
                    value=float(mask.sum()),
                    unit="Gaussians",
                    file=rel,
                    where=f"vertex {first}",
                )


@check(
    "B008",
    group="binding",
    severity="warning",
    title="splat quaternions are normalised",
    quantity="largest deviation of |q| from 1",
    unit="",
    hint="normalise rot_0..3 when writing the PLY",
)
def _quat_norms(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for owner, entry in _splat_owners(ctx):
        s = ctx.dataset.splats(owner)
        norm = np.linalg.norm(s.quats.astype(np.float64), axis=1)
        dev = np.abs(norm - 1.0)
        bad = np.isfinite(dev) & (dev > QUAT_NORM_TOL) & (norm > 1e-8)
        if bad.any():
            k = int(np.flatnonzero(bad)[np.argmax(dev[bad])])
            yield chk.finding(
                f"{int(bad.sum())} of {len(s)} quaternions of {owner!r} have |q| off 1 by more than "
                f"{QUAT_NORM_TOL:g} (worst {norm[k]:.6g} at vertex {k})",
                value=float(dev[k]),
                budget=QUAT_NORM_TOL,
                file=entry["path"],
                where=f"vertex {k}",
            )


def _has_splats(ctx: CheckContext) -> bool:
    """Whether the dataset has splats to re-render (robot or any asset)."""
    assets = ctx.manifest.get("assets")
    entries = [
        ctx.manifest.get("robot") or {},
        *(assets.values() if isinstance(assets, dict) else []),
    ]
    return any(isinstance(e, dict) and "splats" in e for e in entries)


@check(
    "B009",
    group="binding",
    severity="error",
    title="cameras can be rendered from",
    quantity="degenerate camera parameters",
    hint="focal lengths > 0, finite principal point, positive image size and a rigid T_world_cam",
)
def _cameras(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    cams = ctx.manifest.get("cameras")
    for name, rel in sorted(cams.items()) if isinstance(cams, dict) else []:
        try:
            model = ctx.camera(name)
        except (InputReported, KeyError, ValueError, TypeError):
            continue  # unreadable or schema-invalid: reported by the schema checks
        problems = _render_camera_ok(model)
        if model.T_world_cam is None and model.extrinsics != "time_varying" and _has_splats(ctx):
            problems.append(
                "T_world_cam is missing for static extrinsics (needed to re-render the splats)"
            )
        for p in problems:
            yield chk.finding(f"camera {name!r}: {p}", file=rel)


@check(
    "B010",
    group="binding",
    severity="error",
    title="every label id has a segment",
    quantity="label ids in label images that the segments table does not define",
    hint="add the ids to segments.parquet (label_id, category, instance, kind, target) or relabel the images",
)
def _unknown_labels(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    for job in _camera_jobs(ctx):
        try:
            seg = _segments(ctx, job.ep)
        except InputReported:
            continue
        known = set(int(x) for x in seg.column("label_id").to_numpy(zero_copy_only=False))
        lb = ctx.label_boxes(job.ep, job.stream)
        ids = np.asarray(lb.label_id)
        unknown = sorted(set(int(x) for x in np.unique(ids)) - known - {0})
        if not unknown:
            continue
        rows = np.isin(ids, unknown)
        first = int(np.asarray(lb.frame_index)[rows][0])
        yield chk.finding(
            f"label ids {unknown[:10]}{' ...' if len(unknown) > 10 else ''} appear in "
            f"{len(np.unique(np.asarray(lb.frame_index)[rows]))} frames but no segment defines them",
            value=float(len(unknown)),
            unit="ids",
            episode=job.ep.id,
            stream=job.stream,
            frame=first,
            file=job.entry["labels"],
        )


@check(
    "B011",
    group="binding",
    severity="warning",
    title="bound targets and segments name each other",
    quantity="bound targets without a label, segments naming no link or object",
    hint="give every link/object with Gaussians a segment row whose target is its name",
)
def _segment_targets(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    links: set[str] = set()
    if ctx.has_robot():
        try:
            links = set(ctx.chain().link_names)
        except (RobogsError, InputReported):
            links = set()
    assets = set(ctx.asset_names())
    bound = {str(t) for _o, e in _splat_owners(ctx) for t in (e.get("targets") or [])}
    for ep in ctx.episodes:
        try:
            seg = _segments(ctx, ep)
        except InputReported:
            continue
        rows = seg.to_pylist()
        named = {str(r.get("target") or "") for r in rows}
        for r in rows:
            tgt, kind = str(r.get("target") or ""), str(r.get("kind") or "")
            if kind == "robot_link" and links and tgt not in links:
                yield chk.finding(
                    f"segment {r.get('label_id')} names link {tgt!r}, which the URDF does not have",
                    episode=ep.id,
                    link=tgt,
                )
            elif kind == "object" and tgt not in assets:
                yield chk.finding(
                    f"segment {r.get('label_id')} names object {tgt!r}, which is not an asset",
                    episode=ep.id,
                    object=tgt,
                )
        missing = sorted(bound - named)
        if missing:
            yield chk.finding(
                f"bound targets {missing[:8]} have no segment, so their re-render cannot be checked",
                severity="info",
                episode=ep.id,
            )

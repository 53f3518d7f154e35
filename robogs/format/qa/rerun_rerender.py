"""Rerun layer ``rerender``: labels re-rendered from the bound splats next to the recorded ones.

For every ``stride``-th frame of each labelled camera stream, the bound Gaussians are posed at
the frame's stamp and rendered into the recorded camera with
:class:`robogs.format.rerender.SceneRerenderer` (label probabilities, argmax after bilinear
upsampling to the recorded resolution: the label image the binding checks compare). Logged on
the ``time`` timeline at the frame's ``t_ns``:

================================ ===========================================================
``rerender/<cam>/recorded``      recorded label image (``SegmentationImage``)
``rerender/<cam>/labels``        re-rendered label image (``SegmentationImage``, label ids)
``rerender/<cam>/diff``          difference (``Image`` RGB): black where the two agree, red
                                 where only the recording has a label (missed), green where
                                 only the re-render has one (extra), yellow where both have
                                 different labels
``plots/rerender/<cam>/disagree_pct``  share of pixels whose labels differ, %
================================ ===========================================================

Options (``layer_options={"rerender": {...}}``): ``stride`` (default 10), ``scale`` (render
resolution as a fraction of the camera's, default 1), ``backend`` (default ``torch``).
Rendering costs seconds per frame on a CPU, hence the stride.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..dataset import Dataset
from ..errors import RobogsError
from .rerun_log import RerunContext, _annotation_context, entity, log_scalar_series, register_layer

__all__ = ["DIFF_COLORS", "diff_image", "rerendered_labels", "layer_rerender"]

#: RGB of the difference image: agree, missed (recorded only), extra (re-render only), swapped
DIFF_COLORS = np.array([[0, 0, 0], [255, 0, 0], [0, 255, 0], [255, 255, 0]], np.uint8)


def rerendered_labels(
    prob: np.ndarray, label_ids: np.ndarray, width: int, height: int
) -> np.ndarray:
    """Label image [height, width] uint16 of a re-render.

    Args:
        prob: [h, w, C+1] soft labels on the render grid (channel 0: nothing).
        label_ids: [C] label id of channels 1..C.
        width, height: recorded resolution (px); bilinear upsampling, pixel centres aligned.
    """
    import cv2

    p = np.asarray(prob, np.float32)
    if p.shape[:2] != (height, width):
        p = cv2.resize(p, (width, height), interpolation=cv2.INTER_LINEAR).reshape(
            height, width, p.shape[-1]
        )
    lut = np.concatenate([[0], np.asarray(label_ids, np.int64)]).astype(np.uint16)
    return lut[p.argmax(-1)]


def diff_image(recorded: np.ndarray, rendered: np.ndarray) -> np.ndarray:
    """[H, W, 3] uint8 difference of two label images (colours :data:`DIFF_COLORS`)."""
    rec, ren = recorded > 0, rendered > 0
    code = np.zeros(recorded.shape, np.int64)
    code[rec & ~ren] = 1
    code[ren & ~rec] = 2
    code[rec & ren & (recorded != rendered)] = 3
    return DIFF_COLORS[code]


def _pose_of(ds: Dataset, stream: dict[str, Any]) -> Any:
    """``t -> T_world_cam`` from the stream's ``camera_extrinsics`` table."""
    import pyarrow.parquet as pq

    from ..rerender import pose_stream

    tab = pq.read_table(ds.resolve(stream["extrinsics"]))
    c = {k: tab.column(k).to_numpy() for k in ("t_ns", "x", "y", "z", "qw", "qx", "qy", "qz")}
    return pose_stream(
        c["t_ns"].astype(np.int64),
        np.stack([c["x"], c["y"], c["z"]], -1),
        np.stack([c["qw"], c["qx"], c["qy"], c["qz"]], -1),
    )


def layer_rerender(ctx: RerunContext) -> None:
    """Log re-rendered labels, recorded labels and their difference (see the module docstring)."""
    from ..binding import Binding
    from ..rerender import SceneRerenderer, label_channels, read_label_frames

    opts = ctx.options.get("rerender", {})
    stride = int(opts.get("stride", 10))
    if stride < 1:
        raise RobogsError(f"rerender stride must be >= 1, got {stride}", where="--rerender-stride")
    ep = ctx.episode
    segments = ctx.table("segments")
    streams = {
        c: s for c, s in (ep.camera_streams.items() if ep is not None else []) if "labels" in s
    }
    if not streams or segments is None:
        ctx.notes.append("rerender: no labelled camera stream with segments; layer skipped")
        return
    try:
        binding = Binding(ctx.ds, ep.id)  # type: ignore[union-attr]
    except RobogsError as exc:
        ctx.notes.append(f"rerender: no bound splats ({exc.message}); layer skipped")
        return
    channels = label_channels(binding, segments)
    ctx.rec.log("rerender", _annotation_context(segments), static=True)
    for cam_name, stream in sorted(streams.items()):
        model = ctx.ds.camera(cam_name)
        pose_of = _pose_of(ctx.ds, stream) if model.extrinsics == "time_varying" else None
        try:
            rr_ = SceneRerenderer(
                binding,
                model,
                channels,
                scale=float(opts.get("scale", 1.0)),
                backend=str(opts.get("backend", "torch")),
                pose_of=pose_of,
            )
        except RobogsError as exc:
            ctx.notes.append(f"rerender: camera {cam_name} skipped ({exc.message})")
            continue
        frames = ep.frames(cam_name)  # type: ignore[union-attr]
        fi = frames.column("frame_index").to_numpy().astype(np.int64)[::stride]
        ts = frames.column("t_ns").to_numpy().astype(np.int64)[::stride]
        stamp = dict(zip(fi.tolist(), ts.tolist(), strict=True))
        base = "rerender/" + entity(cam_name)
        done: list[tuple[int, float]] = []
        seen: set[int] = set()
        t0 = time.perf_counter()
        for i, lab in read_label_frames(ep.labels_path(cam_name), fi):  # type: ignore[union-attr]
            if i not in stamp or i in seen:
                continue
            seen.add(i)
            t = stamp[i]
            out = rr_.render(t)
            ren = rerendered_labels(
                rr_.probabilities(out), channels.label_ids, lab.shape[1], lab.shape[0]
            )
            ctx.time.set(ctx.rec, t)
            ctx.rec.log(base + "/recorded", rr.SegmentationImage(lab))
            ctx.rec.log(base + "/labels", rr.SegmentationImage(ren))
            ctx.rec.log(base + "/diff", rr.Image(diff_image(lab, ren), color_model="RGB"))
            done.append((i, 100.0 * float(np.mean(lab != ren))))
        ctx.rec.reset_time()
        if done:
            order = np.argsort([stamp[i] for i, _ in done])
            log_scalar_series(
                ctx,
                f"plots/rerender/{entity(cam_name)}/disagree_pct",
                np.array([stamp[done[k][0]] for k in order], np.int64),
                np.array([done[k][1] for k in order]),
                name=f"{cam_name} label disagreement %",
            )
        ctx.notes.append(
            f"rerender: {len(done)} frames of {cam_name} re-rendered (stride {stride}) in "
            f"{time.perf_counter() - t0:.1f} s"
        )


def _views(ds: Dataset) -> list[Any]:
    tabs = []
    for c in ds.camera_names:
        base = "rerender/" + entity(c)
        tabs.append(
            rrb.Horizontal(
                rrb.Spatial2DView(origin=base + "/recorded", name=f"{c} recorded labels"),
                rrb.Spatial2DView(origin=base + "/labels", name=f"{c} re-rendered labels"),
                rrb.Spatial2DView(origin=base + "/diff", name=f"{c} difference"),
                name=f"{c} re-render",
            )
        )
    return [rrb.Tabs(*tabs)] if tabs else []


register_layer("rerender", layer_rerender, views=_views)

"""Video files (``.mp4/.mkv/.mov/.avi``) and image folders -> one camera stream.

Frame stamps, in order of preference:

1. a sidecar CSV ``frame_index,t_ns`` (``--stamps``; for image folders also ``stamps.csv`` in the
   folder): ``stamp_source: sidecar``;
2. for videos, the container presentation time of each frame (OpenCV ``CAP_PROP_POS_MSEC``
   read after each decoded frame): ``stamp_source: container_pts``;
3. only when asked with ``--assume-fps``: ``offset + round(i * 1e9 / fps)``,
   ``stamp_source: derived``.

``--offset-ns`` is added to every stamp and recorded as the stream's ``offset_ns``. Intrinsics
come from ``--camera`` (ROS/OpenCV YAML or ROS INI). A joint log (``--joints``, CSV with
``t_ns`` and ``position.<joint>`` columns, optionally ``velocity.``/``effort.``) becomes the
episode's ``joint_states``; its stamps must already be on the dataset clock.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from robogs.format.errors import InputError

from ..registry import register_converter
from .calibration import read_calibration
from .context import IngestContext
from .roles import safe_name
from .sinks import CameraSink

__all__ = [
    "convert_video",
    "convert_image_folder",
    "detect_video",
    "detect_image_folder",
    "read_stamps_csv",
    "write_joints_csv",
    "VIDEO_SUFFIXES",
    "IMAGE_SUFFIXES",
]

VIDEO_SUFFIXES = frozenset({".mp4", ".mkv", ".mov", ".avi", ".webm"})
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})
_MAX_STAMP_BYTES = 256 << 20


def detect_video(path: Path) -> bool:
    """A video file, by suffix."""
    return path.is_file() and path.suffix.lower() in VIDEO_SUFFIXES


def _images_in(folder: Path) -> list[Path]:
    def natural(p: Path) -> list:
        return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", p.name)]

    return sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
        key=natural,
    )


def detect_image_folder(path: Path) -> bool:
    """A folder of image files (and no bag or capture metadata)."""
    return path.is_dir() and bool(_images_in(path))


def read_stamps_csv(path: Path) -> dict[int, int]:
    """``frame_index -> t_ns`` from a CSV with a ``frame_index,t_ns`` header.

    Raises:
        InputError: missing columns, non-integers, duplicate frame indices (naming the line).
    """
    try:
        if path.stat().st_size > _MAX_STAMP_BYTES:
            raise InputError("stamps CSV is too large", path=path)
        fh = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read stamps CSV ({exc.strerror})", path=path) from None
    out: dict[int, int] = {}
    n = 1
    with fh:
        try:
            reader = csv.DictReader(fh)
            if reader.fieldnames is None or not {"frame_index", "t_ns"} <= {
                f.strip() for f in reader.fieldnames
            }:
                raise InputError(
                    "stamps CSV needs a header with frame_index,t_ns", path=path, where="line 1"
                )
            for n, row in enumerate(reader, 2):
                row = {k.strip(): v for k, v in row.items() if k is not None}
                try:
                    i, t = int(row["frame_index"]), int(row["t_ns"])
                except (TypeError, ValueError):
                    raise InputError(
                        "frame_index and t_ns must be integers", path=path, where=f"line {n}"
                    ) from None
                if not (0 <= i < 2**63 and -(2**63) <= t < 2**63):
                    raise InputError(
                        "frame_index or t_ns is out of the int64 range",
                        path=path,
                        where=f"line {n}",
                        hint="frame_index counts from 0; t_ns is nanoseconds",
                    )
                if i in out:
                    raise InputError(f"frame_index {i} appears twice", path=path, where=f"line {n}")
                out[i] = t
        except UnicodeDecodeError:
            raise InputError(
                "stamps CSV is not UTF-8 text", path=path, where=f"after line {n}"
            ) from None
        except csv.Error as exc:
            raise InputError(
                f"stamps CSV is malformed ({exc})", path=path, where=f"line {n + 1}"
            ) from None
    return out


def _camera(ctx: IngestContext, default: str) -> tuple[str, tuple[int, int] | None]:
    opts = ctx.options
    if opts.camera_file is not None:
        cam = read_calibration(opts.camera_file, name=opts.camera_name)
        ctx.writer.set_camera(cam)
        ctx.provenance.note(
            f"intrinsics from {opts.camera_file.name}; T_world_cam not known (not written)"
        )
        return cam.name, (cam.width, cam.height)
    ctx.provenance.note(
        "no calibration given (--camera): the camera has no intrinsics in the dataset"
    )
    return safe_name(opts.camera_name or default), None


class _Stamper:
    """Frame stamps from a sidecar, the container, or an explicitly assumed rate."""

    def __init__(self, ctx: IngestContext, source: Path, *, has_pts: bool) -> None:
        opts = ctx.options
        self.offset = int(opts.offset_ns)
        self.sidecar: dict[int, int] | None = None
        self.fps = opts.assume_fps
        stamps = opts.stamps_csv
        if stamps is None and source.is_dir() and (source / "stamps.csv").is_file():
            stamps = source / "stamps.csv"
        if stamps is not None:
            self.sidecar = read_stamps_csv(stamps)
            self.kind = "sidecar"
            self.where = str(stamps)
        elif has_pts and self.fps is None:
            self.kind = "container_pts"
            self.where = str(source)
        elif self.fps is not None:
            if not self.fps > 0:
                raise InputError("--assume-fps must be positive", where="--assume-fps")
            self.kind = "derived"
            self.where = "--assume-fps"
            ctx.provenance.note(
                f"frame stamps derived as i / {self.fps:g} fps (asked with --assume-fps)"
            )
        else:
            raise InputError(
                "no frame stamps for an image folder",
                path=source,
                hint="add stamps.csv (frame_index,t_ns), pass --stamps, or --assume-fps FPS",
            )

    def stamp(self, i: int, pts_ms: float | None) -> int:
        if self.sidecar is not None:
            if i not in self.sidecar:
                raise InputError(
                    f"no stamp for frame {i}", path=self.where, hint="one row per frame"
                )
            return self.sidecar[i] + self.offset
        if self.kind == "container_pts":
            assert pts_ms is not None
            return int(round(pts_ms * 1e6)) + self.offset
        assert self.fps is not None
        return int(round(i * 1e9 / self.fps)) + self.offset

    def check_count(self, n: int) -> None:
        if self.sidecar is not None and len(self.sidecar) != n:
            raise InputError(
                f"stamps CSV has {len(self.sidecar)} rows for {n} frames", path=self.where
            )


def _video_frames(path: Path) -> Iterator[tuple[np.ndarray, float]]:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise InputError("video cannot be opened (unknown container or codec)", path=path)
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            yield frame, float(cap.get(cv2.CAP_PROP_POS_MSEC))
    finally:
        cap.release()


def _write_frames(
    ctx: IngestContext,
    src: Path,
    cam: str,
    frames: Iterator[tuple[np.ndarray | None, float | None]],
    stamper: _Stamper,
    total: int | None,
    fps_hint: float,
    size: tuple[int, int] | None,
) -> None:
    ep = ctx.episode_dir()
    w = ctx.writer
    sink = CameraSink(
        w.path(f"{ep}/cameras/{cam}/frames.parquet"),
        w.path(f"{ep}/cameras/{cam}/rgb.mp4"),
        topic=src.name,
        provenance=ctx.provenance,
        video=ctx.options.video,
        fps_hint=fps_hint,
    )
    rec = ctx.provenance.topic(
        src.name, "video" if src.is_file() else "image folder", f"camera_image:{cam}"
    )
    rec.stamp_source = stamper.kind
    ctx.clock = {
        "container_pts": "video container time (+ offset_ns)",
        "sidecar": "sidecar stamps (+ offset_ns)",
        "derived": "derived from --assume-fps (+ offset_ns)",
    }[stamper.kind]
    ctx.progress.start(f"reading {src.name}", total, unit="frames")
    n = 0
    prev_pts: float | None = None
    for bgr, pts in frames:
        if (
            stamper.kind == "container_pts"
            and n > 0
            and pts is not None
            and prev_pts is not None
            and pts <= prev_pts
        ):
            raise InputError(
                f"container time stamps do not increase (frame {n}: {pts} ms after {prev_pts} ms)",
                path=src,
                hint="pass --stamps CSV, or --assume-fps if the rate is truly constant",
            )
        prev_pts = pts
        if n == 0 and bgr is not None and size is not None and (bgr.shape[1], bgr.shape[0]) != size:
            raise InputError(
                f"the calibration is for {size[0]}x{size[1]} images but the frames are "
                f"{bgr.shape[1]}x{bgr.shape[0]}",
                path=src,
                where="frame 0",
                hint="pass the calibration made for this resolution",
            )
        t = stamper.stamp(n, pts)
        rec.messages += 1
        if sink.accepts(t):
            sink.add(
                t,
                cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                if (bgr is not None and ctx.options.video)
                else None,
            )
            rec.written += 1
        n += 1
        ctx.progress.advance()
    ctx.progress.stop()
    if n == 0:
        raise InputError("no frames could be decoded", path=src)
    stamper.check_count(n)
    st = sink.close()
    entry = {
        "kind": "camera",
        "camera": cam,
        "frames": f"{ep}/cameras/{cam}/frames.parquet",
        "stamp_source": stamper.kind,
        "offset_ns": int(ctx.options.offset_ns),
        "nominal_rate_hz": st.rate_hz,
        "source": src.name,
    }
    if ctx.options.video:
        entry["video"] = f"{ep}/cameras/{cam}/rgb.mp4"
    ctx.add_stream(f"camera/{cam}", entry, start_ns=st.start_ns, end_ns=st.end_ns)


def write_joints_csv(ctx: IngestContext, path: Path) -> None:
    """Stream a joint log CSV (``t_ns``, ``position.<joint>``, ...) into ``joint_states``.

    Raises:
        InputError: missing ``t_ns`` or positions, non-numeric values, stamps that do not increase.
    """
    try:
        reader = pacsv.open_csv(
            path, convert_options=pacsv.ConvertOptions(column_types={"t_ns": pa.int64()})
        )
    except (pa.ArrowInvalid, OSError) as exc:
        raise InputError(
            f"cannot read joint log ({str(exc).splitlines()[0][:200]})", path=path
        ) from None
    names = reader.schema.names
    cols = [c for c in names if c.startswith(("position.", "velocity.", "effort."))]
    if "t_ns" not in names or not any(c.startswith("position.") for c in cols):
        raise InputError(
            "joint log needs a t_ns column and position.<joint> columns", path=path, where="header"
        )
    ignored = [c for c in names if c != "t_ns" and c not in cols]
    if ignored:
        ctx.provenance.note(f"{path.name}: columns {ignored[:10]} not converted")
    schema = pa.schema(
        [pa.field("t_ns", pa.int64(), nullable=False)] + [pa.field(c, pa.float64()) for c in cols]
    )
    rel = f"{ctx.episode_dir()}/joint_states.parquet"
    out = ctx.writer.path(rel)
    rec = ctx.provenance.topic(path.name, "joint log CSV", "joint_states")
    rec.stamp_source = "sidecar"
    last, first, rows = None, None, 0
    stamps_head: list[int] = []
    with pq.ParquetWriter(out, schema, compression="zstd") as pw:
        try:
            for batch in reader:
                t = batch.column("t_ns")
                if t.null_count:
                    raise InputError("t_ns has empty cells", path=path, where=f"rows {rows + 2}..")
                tn = t.to_numpy(zero_copy_only=False)
                seq = tn if last is None else np.concatenate([[last], tn])
                bad = np.flatnonzero(np.diff(seq) <= 0)
                if bad.size:
                    row = rows + int(bad[0]) + (1 if last is None else 0) + 1
                    raise InputError(
                        "t_ns does not increase",
                        path=path,
                        where=f"data row {row}",
                        hint="sort the log by t_ns and remove duplicate stamps",
                    )
                arrays = [pa.array(tn, pa.int64())] + [
                    batch.column(c).cast(pa.float64()) for c in cols
                ]
                pw.write_table(pa.Table.from_arrays(arrays, schema=schema))
                first = int(tn[0]) if first is None and tn.size else first
                last = int(tn[-1]) if tn.size else last
                if len(stamps_head) < 2001:
                    stamps_head.extend(int(v) for v in tn[: 2001 - len(stamps_head)])
                rows += tn.size
        except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
            raise InputError(
                f"joint log has non-numeric values ({str(exc).splitlines()[0][:200]})", path=path
            ) from None
    if rows == 0:
        raise InputError("joint log has no rows", path=path)
    rec.messages = rec.written = rows
    from .sinks import median_rate_hz

    ctx.add_stream(
        "joint_states",
        {
            "kind": "joint_states",
            "path": rel,
            "stamp_source": "sidecar",
            "offset_ns": 0,
            "nominal_rate_hz": median_rate_hz(stamps_head),
            "source": path.name,
        },
        start_ns=first,
        end_ns=last,
    )


def convert_video(src: Path, ctx: IngestContext) -> None:
    """Convert a video file (+ optional calibration and joint log)."""
    cam, size = _camera(ctx, src.stem)
    cap = cv2.VideoCapture(str(src))
    if not cap.isOpened():
        raise InputError(
            "video cannot be opened (unknown container or codec)",
            path=src,
            hint="re-encode as mp4 (H.264 or mp4v) or mkv",
        )
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
    cap.release()
    stamper = _Stamper(ctx, src, has_pts=True)
    frames = ((f, p) for f, p in _video_frames(src))
    _write_frames(ctx, src, cam, frames, stamper, total, fps, size)
    if ctx.options.joints_csv is not None:
        write_joints_csv(ctx, ctx.options.joints_csv)


def convert_image_folder(src: Path, ctx: IngestContext) -> None:
    """Convert a folder of images (sorted by name, natural order) into a camera stream."""
    files = _images_in(src)
    cam, size = _camera(ctx, src.name)
    stamper = _Stamper(ctx, src, has_pts=False)

    def frames() -> Iterator[tuple[np.ndarray | None, float | None]]:
        for p in files:
            if not ctx.options.video:
                yield None, None
                continue
            img = cv2.imread(str(p), cv2.IMREAD_COLOR)
            if img is None:
                raise InputError("image cannot be decoded", path=p)
            yield img, None

    _write_frames(
        ctx, src, cam, frames(), stamper, len(files), ctx.options.assume_fps or 30.0, size
    )
    if ctx.options.joints_csv is not None:
        write_joints_csv(ctx, ctx.options.joints_csv)


register_converter(
    "video",
    detect_video,
    convert_video,
    description="video file (.mp4 .mkv .mov .avi)",
    priority=40,
)
register_converter(
    "images",
    detect_image_folder,
    convert_image_folder,
    description="folder of images (+ stamps.csv or --assume-fps)",
    priority=10,
)

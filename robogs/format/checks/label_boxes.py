"""Per-label bounding boxes of panoptic label images, computed in one streaming pass.

Label tables are read in batches (never all images at once) and the images are
processed on a small thread pool (zlib and OpenCV release the GIL). Boxes come
from run-length encoding: a run starts wherever the label changes or a row
begins, so the work per image is one comparison over the pixels plus a few
operations on the (few thousand) runs, instead of one mask per label.

PNGs as the writer stores them (16-bit grey, every row Sub-filtered) skip the
pixel decode altogether: the run starts are read off the inflated, still
filtered bytes (see :func:`_png_sub_runs`). Any other PNG is decoded by OpenCV.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import FormatError
from ..images import MAX_LABEL_PIXELS, decode_label_png

__all__ = ["LabelBoxes", "boxes_of_label_image", "scan_label_boxes"]


@dataclass(frozen=True)
class LabelBoxes:
    """Boxes of every non-zero label in every frame of one label table.

    All arrays have one entry per (frame, label) pair; coordinates are pixel
    edges with the maximum exclusive (the ``boxes2d`` convention).

    Attributes:
        frame_index: [M] int64.
        label_id: [M] int64.
        x_min, y_min, x_max, y_max: [M] int64 px.
        pixels: [M] int64 number of pixels of the label.
        frames: [F] int64 frame indices of the table, in table order.
        width, height: image size of the first frame (px).
        sizes_consistent: False if frames have different sizes.
    """

    frame_index: np.ndarray
    label_id: np.ndarray
    x_min: np.ndarray
    y_min: np.ndarray
    x_max: np.ndarray
    y_max: np.ndarray
    pixels: np.ndarray
    frames: np.ndarray
    width: int
    height: int
    sizes_consistent: bool


def boxes_of_label_image(img: np.ndarray) -> tuple[np.ndarray, ...]:
    """Boxes of the non-zero labels of one image.

    Args:
        img: [H, W] integer label ids (0 = unlabelled).

    Returns:
        ``(label_id, x_min, y_min, x_max, y_max, pixels)``, each [K] int64, sorted by
        label id; ``x_max``/``y_max`` exclusive.
    """
    H, W = img.shape
    flat = np.ascontiguousarray(img).ravel()
    if flat.size == 0:
        return _empty()
    start = np.empty(flat.size, bool)
    start[0] = True
    np.not_equal(flat[1:], flat[:-1], out=start[1:])
    start[::W] = True
    st = np.flatnonzero(start)
    return _boxes_from_runs(st, flat[st].astype(np.int64), W, flat.size)


def _empty() -> tuple[np.ndarray, ...]:
    empty = np.zeros(0, np.int64)
    return (empty,) * 6


def _boxes_from_runs(st: np.ndarray, lab: np.ndarray, W: int, size: int) -> tuple[np.ndarray, ...]:
    """Boxes from run starts (flat indices, every row start included) and their labels."""
    ends = np.append(st[1:], size)
    keep = lab != 0
    st, ends, lab = st[keep], ends[keep], lab[keep]
    if st.size == 0:
        return _empty()
    row = st // W
    c0 = st - row * W
    c1 = ends - row * W  # exclusive
    order = np.argsort(lab, kind="stable")
    lab, row, c0, c1, n = lab[order], row[order], c0[order], c1[order], (ends - st)[order]
    ids, first = np.unique(lab, return_index=True)
    return (
        ids,
        np.minimum.reduceat(c0, first),
        np.minimum.reduceat(row, first),
        np.maximum.reduceat(c1, first),
        np.maximum.reduceat(row, first) + 1,
        np.add.reduceat(n, first),
    )


def _png_sub_runs(blob: bytes) -> tuple[tuple[int, int], tuple[np.ndarray, ...]] | None:
    """Boxes straight from the filtered bytes of a 16-bit grey PNG whose rows use the Sub filter.

    With the Sub filter (PNG spec, W3C 2003, section 9.2) each stored pixel is its
    difference from its left neighbour, byte by byte modulo 256. A pixel starts a
    new run exactly where that difference is non-zero, and a run's label is the
    running sum of the differences at the run starts of its row. So the boxes come
    from the inflated bytes without undoing the filter pixel by pixel. Returns None
    (use a full decode) for any other kind of PNG.
    """
    if blob[:8] != b"\x89PNG\r\n\x1a\n":
        return None
    pos, idat, header = 8, [], None
    n = len(blob)
    while pos + 8 <= n:
        length = int.from_bytes(blob[pos : pos + 4], "big")
        ctype = blob[pos + 4 : pos + 8]
        body = blob[pos + 8 : pos + 8 + length]
        if ctype == b"IHDR" and len(body) == 13:
            header = body
        elif ctype == b"IDAT":
            idat.append(body)
        elif ctype == b"IEND":
            break
        pos += 12 + length
    if header is None or not idat:
        return None
    W, H = int.from_bytes(header[0:4], "big"), int.from_bytes(header[4:8], "big")
    if header[8:13] != bytes([16, 0, 0, 0, 0]) or W * H == 0 or W * H > MAX_LABEL_PIXELS:
        return None  # not 16-bit grey, or interlaced
    want = H * (1 + 2 * W)
    try:  # never inflate more than the header implies (a zlib bomb stops here)
        raw = zlib.decompressobj().decompress(b"".join(idat), want + 1)
    except zlib.error:
        return None
    if len(raw) != want:
        return None
    rows = np.frombuffer(raw, np.uint8).reshape(H, 1 + 2 * W)
    if np.any(rows[:, 0] != 1):
        return None  # None/Up/Average/Paeth rows: decode fully
    delta = np.ascontiguousarray(rows[:, 1:]).view(">u2")  # [H, W] bytewise deltas, as pairs
    start = delta != 0
    start[:, 0] = True
    st = np.flatnonzero(start)
    d = delta.ravel()[st].astype(np.int64)
    # per-lane running sums of the deltas at run starts, restarted at each row (mod 256)
    d_hi = np.cumsum(d >> 8)
    d_lo = np.cumsum(d & 255)
    row_first = np.flatnonzero(st % W == 0)
    per_row = np.diff(np.append(row_first, st.size))
    before_hi = np.repeat(np.concatenate([[0], d_hi[row_first[1:] - 1]]), per_row)
    before_lo = np.repeat(np.concatenate([[0], d_lo[row_first[1:] - 1]]), per_row)
    lab = ((d_hi - before_hi) % 256) * 256 + (d_lo - before_lo) % 256
    return (H, W), _boxes_from_runs(st, lab, W, H * W)


def _decode_boxes(
    item: tuple[int, bytes, Path],
) -> tuple[int, tuple[int, int], tuple[np.ndarray, ...]]:
    idx, blob, path = item
    fast = _png_sub_runs(blob) if blob else None
    if fast is not None:
        return idx, fast[0], fast[1]
    img = decode_label_png(blob, path=path, where=f"frame_index {idx}")
    return idx, img.shape, boxes_of_label_image(img)


def _iter_batches(path: Path, batch_rows: int) -> Iterator[pa.RecordBatch]:
    try:
        pf = pq.ParquetFile(path)
        yield from pf.iter_batches(batch_size=batch_rows, columns=["frame_index", "png"])
    except (pa.ArrowException, OSError) as exc:
        raise FormatError(
            f"unreadable label table ({str(exc).splitlines()[0][:200]})",
            path=path,
            hint="the file is truncated or not parquet; re-export it",
        ) from None


def scan_label_boxes(
    path: Path,
    *,
    batch_rows: int = 256,
    threads: int = 2,
    on_batch: Callable[[int], None] | None = None,
) -> LabelBoxes:
    """Boxes of every label in every frame of a ``labels.parquet`` table.

    Args:
        path: the camera's label table (``frame_index``, ``png``).
        batch_rows: rows decoded per batch (bounds memory).
        threads: decoder threads.
        on_batch: called with the number of rows after each batch (progress).

    Raises:
        FormatError: unreadable table or an undecodable image (naming its frame index).
    """
    cols: list[list[np.ndarray]] = [[] for _ in range(7)]
    frames: list[np.ndarray] = []
    shapes: set[tuple[int, int]] = set()
    first_shape: tuple[int, int] | None = None
    with ThreadPoolExecutor(max_workers=max(1, threads)) as pool:
        for batch in _iter_batches(path, batch_rows):
            if batch.column(0).null_count or batch.column(1).null_count:
                raise FormatError(
                    "label table holds null frame indices or images",
                    path=path,
                    hint="every row needs a frame_index and a PNG; re-export the labels",
                )
            idx = batch.column(0).to_numpy(zero_copy_only=False).astype(np.int64)
            blobs = batch.column(1).to_pylist()
            frames.append(idx)
            for i, shape, boxes in pool.map(
                _decode_boxes, [(int(i), b, path) for i, b in zip(idx, blobs, strict=True)]
            ):
                if first_shape is None:
                    first_shape = shape
                shapes.add(shape)
                k = boxes[0].size
                cols[0].append(np.full(k, i, np.int64))
                for j in range(6):
                    cols[j + 1].append(boxes[j].astype(np.int64, copy=False))
            if on_batch is not None:
                on_batch(len(idx))

    def cat(parts: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(parts) if parts else np.zeros(0, np.int64)

    h, w = first_shape if first_shape is not None else (0, 0)
    return LabelBoxes(
        frame_index=cat(cols[0]),
        label_id=cat(cols[1]),
        x_min=cat(cols[2]),
        y_min=cat(cols[3]),
        x_max=cat(cols[4]),
        y_max=cat(cols[5]),
        pixels=cat(cols[6]),
        frames=cat(frames),
        width=int(w),
        height=int(h),
        sizes_consistent=len(shapes) <= 1,
    )

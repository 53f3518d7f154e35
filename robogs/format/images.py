"""Image and video codecs: 16-bit label PNGs and colour videos (via OpenCV)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from .errors import FormatError

__all__ = [
    "encode_label_png",
    "decode_label_png",
    "MAX_LABEL_PIXELS",
    "iter_video_frames",
    "video_frame_count",
    "VideoWriter",
]

MAX_PIXELS = 100_000_000

#: largest label image decoded (pixels): 4096 x 4096. A 16-bit label image that size is 32 MiB
#: decoded; the box scan's working arrays stay a few times that. A PNG header claiming more is
#: refused before any inflation (a 50 kB PNG can claim 10,000 x 10,000 pixels).
MAX_LABEL_PIXELS = 4096 * 4096


def encode_label_png(labels: np.ndarray) -> bytes:
    """Encode an [H, W] array of label ids (0..65535) as a lossless 16-bit PNG."""
    if labels.ndim != 2 or labels.min(initial=0) < 0 or labels.max(initial=0) > 65535:
        raise FormatError(f"label image must be [H, W] with ids in 0..65535, got {labels.shape}")
    ok, buf = cv2.imencode(".png", labels.astype(np.uint16))
    if not ok:
        raise FormatError("PNG encoding failed")
    return buf.tobytes()


def decode_label_png(
    blob: bytes, *, path: str | Path | None = None, where: str | None = None
) -> np.ndarray:
    """Decode a label PNG into an [H, W] uint16 array."""
    if not blob:
        raise FormatError("empty label image", path=path, where=where)
    if blob[:8] == b"\x89PNG\r\n\x1a\n" and blob[12:16] == b"IHDR":
        w, h = int.from_bytes(blob[16:20], "big"), int.from_bytes(blob[20:24], "big")
        if w * h > MAX_LABEL_PIXELS:
            raise FormatError(
                f"label image claims {w}x{h} pixels, over the {MAX_LABEL_PIXELS}-pixel budget "
                f"({blob.__len__()} bytes compressed)",
                path=path,
                where=where,
                hint="label images have the camera's resolution; the PNG header is corrupt or "
                "the image is not a label image",
            )
    arr = np.frombuffer(blob, np.uint8)
    img = cv2.imdecode(arr, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FormatError(
            "label image is not a decodable PNG",
            path=path,
            where=where,
            hint="labels are 16-bit single-channel PNGs",
        )
    if img.ndim != 2:
        raise FormatError(
            f"label image must be single-channel, has shape {img.shape}", path=path, where=where
        )
    return img.astype(np.uint16, copy=False)


def _open_capture(path: Path) -> cv2.VideoCapture:
    if not Path(path).is_file():
        raise FormatError("video file is missing", path=path)
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise FormatError(
            "video cannot be opened (unknown container or codec)",
            path=path,
            hint="re-encode as mp4 (mp4v or H.264) or mkv",
        )
    return cap


def video_frame_count(path: str | Path, *, exact: bool = False) -> int:
    """Number of frames: from the container header, or by decoding every frame if ``exact``."""
    cap = _open_capture(Path(path))
    try:
        if not exact:
            return int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        n = 0
        while cap.grab():
            n += 1
        return n
    finally:
        cap.release()


def iter_video_frames(path: str | Path) -> Iterator[np.ndarray]:
    """Yield frames as RGB uint8 arrays [H, W, 3] in file order."""
    cap = _open_capture(Path(path))
    try:
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            yield cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
    finally:
        cap.release()


class VideoWriter:
    """Write RGB frames to an mp4 (MPEG-4 part 2, 'mp4v') file."""

    def __init__(self, path: str | Path, width: int, height: int, fps: float) -> None:
        if width * height > MAX_PIXELS or width <= 0 or height <= 0:
            raise FormatError(f"refusing video size {width}x{height}", path=path)
        self.path = Path(path)
        self._w = cv2.VideoWriter(
            str(path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (int(width), int(height))
        )
        if not self._w.isOpened():
            raise FormatError("cannot open video writer (OpenCV built without mp4v?)", path=path)
        self.count = 0

    def write(self, rgb: np.ndarray) -> None:
        self._w.write(cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.uint8), cv2.COLOR_RGB2BGR))
        self.count += 1

    def close(self) -> None:
        self._w.release()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

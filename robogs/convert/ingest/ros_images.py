"""Decode ``sensor_msgs/Image`` and ``sensor_msgs/CompressedImage`` payloads.

Colour images come out as RGB ``uint8 [H, W, 3]``; 16-bit single-channel images (label ids)
as ``uint16 [H, W]``. Raw images are checked against their declared ``height``, ``width``,
``step`` and ``encoding`` before any reshape: a mismatch is an
:class:`~robogs.format.errors.InputError` naming the topic and stamp.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from robogs.format.errors import InputError

__all__ = [
    "as_bytes",
    "decode_raw_image",
    "decode_compressed_image",
    "COLOUR_ENCODINGS",
    "MONO16_ENCODINGS",
]

#: encoding -> (channels, OpenCV conversion to RGB or None)
COLOUR_ENCODINGS: dict[str, tuple[int, int | None]] = {
    "rgb8": (3, None),
    "bgr8": (3, cv2.COLOR_BGR2RGB),
    "8uc3": (3, cv2.COLOR_BGR2RGB),
    "rgba8": (4, cv2.COLOR_RGBA2RGB),
    "bgra8": (4, cv2.COLOR_BGRA2RGB),
    "8uc4": (4, cv2.COLOR_BGRA2RGB),
    "mono8": (1, cv2.COLOR_GRAY2RGB),
    "8uc1": (1, cv2.COLOR_GRAY2RGB),
}
MONO16_ENCODINGS = ("mono16", "16uc1")
_MAX_PIXELS = 100_000_000


def as_bytes(data: Any) -> np.ndarray:
    """A message's ``uint8[]`` field (bytes, bytearray, list or numpy array) as a uint8 array."""
    if isinstance(data, np.ndarray):
        return (
            data.view(np.uint8).reshape(-1) if data.dtype.itemsize == 1 else data.astype(np.uint8)
        )
    if isinstance(data, (bytes, bytearray, memoryview)):
        return np.frombuffer(data, dtype=np.uint8)
    return np.asarray(data, dtype=np.uint8)


def decode_raw_image(msg: Any, *, topic: str, t_ns: int) -> tuple[str, np.ndarray]:
    """Decode a raw ``Image``.

    Returns:
        ``("rgb", [H, W, 3] uint8)`` or ``("mono16", [H, W] uint16)``.

    Raises:
        InputError: unknown encoding, or data that does not fit ``height x step``.
    """
    where = f"topic {topic} stamp {t_ns}"
    enc = str(msg.encoding).strip().lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = as_bytes(msg.data)
    if h <= 0 or w <= 0 or h * w > _MAX_PIXELS:
        raise InputError(f"invalid image size {w}x{h}", where=where)
    if enc in COLOUR_ENCODINGS:
        ch, conv = COLOUR_ENCODINGS[enc]
        bpp = ch
    elif enc in MONO16_ENCODINGS:
        ch, conv, bpp = 1, None, 2
    else:
        raise InputError(
            f"unsupported image encoding {msg.encoding!r}",
            where=where,
            hint="supported: rgb8, bgr8, rgba8, bgra8, mono8, mono16",
        )
    if step < w * bpp or data.size != step * h:
        raise InputError(
            f"image data has {data.size} bytes but {w}x{h} {enc} with step {step} needs {step * h}"
            + (f" (step must be >= {w * bpp})" if step < w * bpp else ""),
            where=where,
            hint="the message is corrupt or its header is wrong",
        )
    rows = data.reshape(h, step)[:, : w * bpp]
    if enc in MONO16_ENCODINGS:
        img16 = (
            rows.copy().view(">u2" if int(getattr(msg, "is_bigendian", 0)) else "<u2").reshape(h, w)
        )
        return "mono16", img16.astype(np.uint16)
    img = rows.reshape(h, w, ch) if ch > 1 else rows.reshape(h, w)
    if conv is not None:
        img = cv2.cvtColor(np.ascontiguousarray(img), conv)
    return "rgb", np.ascontiguousarray(img)


def decode_compressed_image(msg: Any, *, topic: str, t_ns: int) -> tuple[str, np.ndarray] | None:
    """Decode a ``CompressedImage`` (JPEG/PNG/...) with OpenCV.

    Returns:
        ``("rgb", [H, W, 3] uint8)``, ``("mono16", [H, W] uint16)``, or ``None`` when the payload
        is not a decodable still image (corrupt, or a video codec such as H.264).
    """
    data = as_bytes(msg.data)
    if data.size == 0:
        return None
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        return None
    if img.dtype == np.uint16:
        if img.ndim == 2:
            return "mono16", img
        img = (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8:
        return None
    if img.ndim == 2:
        return "rgb", cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 4:
        return "rgb", cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return "rgb", cv2.cvtColor(img, cv2.COLOR_BGR2RGB)

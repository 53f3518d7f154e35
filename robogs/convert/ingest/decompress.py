"""Caps on what one compressed chunk of a bag or MCAP may expand to in memory.

MCAP chunks (read by the ``mcap`` library, and by rosbags for ROS 2 bags with MCAP storage)
and ROS 1 bag chunks are compressed with zstd, lz4 or bz2. A few kilobytes can claim, or
really expand to, many gigabytes (a "decompression bomb"), and zstd's one-shot decompressor
allocates whatever size a frame header claims before it writes a byte. While a converter
reads, :func:`capped_decompression` sends those libraries' chunk decompression through
:func:`bounded_decompress`, which streams and stops at :data:`MAX_CHUNK_BYTES`: a bigger chunk
is refused with :class:`DecompressionLimitError` before it is allocated.

The libraries' module-level hooks are swapped for the duration of the ``with`` block and
restored afterwards (the converters read one source at a time, in one thread).
"""

from __future__ import annotations

import bz2
import contextlib
import io
import zlib
from collections.abc import Iterator
from typing import Any

from robogs.format.errors import InputError

__all__ = [
    "MAX_CHUNK_BYTES",
    "DecompressionLimitError",
    "bounded_decompress",
    "capped_decompression",
]

#: largest decompressed chunk, bytes (recorders write 1-4 MiB chunks; one raw 4K image is 25 MB)
MAX_CHUNK_BYTES = 256 * 1024 * 1024
_BLOCK = 1 << 20


class DecompressionLimitError(InputError):
    """A compressed chunk claims or expands to more than the limit."""


def _too_big(compression: str, size: int | str, limit: int) -> DecompressionLimitError:
    return DecompressionLimitError(
        f"a {compression} chunk decompresses to {size} bytes, over the {limit}-byte limit",
        hint="the file is corrupt or hostile; a real recording has chunks of a few MiB",
    )


def bounded_decompress(data: bytes, compression: str, limit: int = MAX_CHUNK_BYTES) -> bytes:
    """Decompress one zstd, lz4 (frame) or bz2 chunk, refusing more than ``limit`` bytes.

    Raises:
        DecompressionLimitError: the output would exceed ``limit``.
        ValueError: unknown compression, or a truncated stream.
    """
    if compression in ("", "none"):
        if len(data) > limit:
            raise _too_big("uncompressed", len(data), limit)
        return bytes(data)
    if compression == "zstd":
        import zstandard

        out = bytearray()
        reader = zstandard.ZstdDecompressor().stream_reader(
            io.BytesIO(data), read_across_frames=True
        )
        while True:
            block = reader.read(min(_BLOCK, limit + 1 - len(out)))
            if not block:
                return bytes(out)
            out += block
            if len(out) > limit:
                raise _too_big("zstd", f"more than {limit}", limit)
    if compression == "lz4":
        import lz4.frame

        d = lz4.frame.LZ4FrameDecompressor()
        out = d.decompress(data, max_length=limit + 1)
        if len(out) > limit:
            raise _too_big("lz4", f"more than {limit}", limit)
        if not d.eof:
            raise ValueError("truncated lz4 frame")
        return out
    if compression == "bz2":
        d = bz2.BZ2Decompressor()
        out = d.decompress(data, max_length=limit + 1)
        if len(out) > limit:
            raise _too_big("bz2", f"more than {limit}", limit)
        if not d.eof:
            raise ValueError("truncated bz2 stream")
        return out
    raise ValueError(f"unsupported chunk compression {compression!r}")


def _within_declared(data: bytes, compression: str, declared: int) -> bytes:
    """Decompress a chunk that declares its size (already checked against the limit)."""
    if compression in ("", "none"):
        return bytes(data)
    try:
        return bounded_decompress(data, compression, declared)
    except DecompressionLimitError:
        raise ValueError(
            f"{compression} chunk decompresses to more than its declared {declared} bytes"
        ) from None


def _mcap_chunk_stream(limit: int):
    """A replacement for ``mcap.stream_reader.get_chunk_data_stream`` that honours ``limit``."""
    from mcap.data_stream import ReadDataStream
    from mcap.exceptions import UnsupportedCompressionError
    from mcap.stream_reader import CRCValidationError

    def get_chunk_data_stream(chunk: Any, validate_crc: bool = False) -> tuple[Any, int]:
        if chunk.uncompressed_size > limit:
            raise _too_big(chunk.compression or "uncompressed", chunk.uncompressed_size, limit)
        if chunk.compression not in ("", "zstd", "lz4"):
            raise UnsupportedCompressionError(chunk.compression)
        data = _within_declared(chunk.data, chunk.compression, chunk.uncompressed_size)
        if validate_crc and chunk.uncompressed_crc != 0:
            crc = zlib.crc32(data)
            if crc != chunk.uncompressed_crc:
                raise CRCValidationError(expected=chunk.uncompressed_crc, actual=crc, record=chunk)
        return ReadDataStream(io.BytesIO(data)), len(data)

    return get_chunk_data_stream


@contextlib.contextmanager
def capped_decompression(limit: int = MAX_CHUNK_BYTES) -> Iterator[None]:
    """Within the block, MCAP and bag chunk decompression stops at ``limit`` bytes."""
    restore: list[tuple[Any, str, Any]] = []

    def swap(obj: Any, key: str, value: Any) -> None:
        if isinstance(obj, dict):
            restore.append((obj, key, obj.get(key)))
            obj[key] = value
        else:
            restore.append((obj, key, getattr(obj, key)))
            setattr(obj, key, value)

    try:
        import mcap.stream_reader as mcap_stream

        swap(mcap_stream, "get_chunk_data_stream", _mcap_chunk_stream(limit))
        try:
            from rosbags.rosbag1 import reader as r1
        except ImportError:  # pragma: no cover - rosbags is a dependency
            r1 = None
        if r1 is not None:
            for name in ("bz2", "lz4"):
                if name in r1.decompressors:
                    swap(
                        r1.decompressors, name, lambda x, _c=name: bounded_decompress(x, _c, limit)
                    )
        try:
            from rosbags.rosbag2 import storage_mcap as r2
        except ImportError:  # pragma: no cover
            r2 = None
        if r2 is not None:

            def r2_decompress(data: bytes, size: int, _c: str) -> bytes:
                if size > limit:
                    raise _too_big(_c, size, limit)
                return _within_declared(data, _c, size)

            for name in ("lz4", "zstd"):
                if name in r2.DECOMPRESSORS:
                    swap(r2.DECOMPRESSORS, name, lambda x, s, _c=name: r2_decompress(x, s, _c))
        yield
    finally:
        for obj, key, old in reversed(restore):
            if isinstance(obj, dict):
                obj[key] = old
            else:
                setattr(obj, key, old)

"""Plain MCAP files, read with the ``mcap`` library (https://mcap.dev/docs/python).

Decoders, chosen per channel from its message encoding and schema encoding:

* ``cdr`` + ``ros2msg``: ``mcap_ros2.decoder.DecoderFactory`` (JointState, Image and
  CompressedImage with the standard layout go through :mod:`robogs.convert.ingest.cdr_fast`);
* ``cdr`` + ``ros2idl`` and ``ros1`` + ``ros1msg``: rosbags' type system, built from the schema
  text stored in the file;
* ``json``: the standard library; Foxglove schemas are mapped to ROS shapes
  (:mod:`robogs.convert.ingest.foxglove`);
* ``protobuf``: message classes built from the schema's ``FileDescriptorSet``
  (:mod:`robogs.convert.ingest.protobuf_schema`); Foxglove schemas (``foxglove.CompressedImage``,
  ``RawImage``, ``CameraCalibration``, ``FrameTransform(s)``, ``PoseInFrame``) are mapped to
  ROS shapes like their JSON twins, other messages are listed as having no role.

A channel with no usable decoder is listed in ``provenance.undecodable`` with its message
count. Chunk CRCs are checked, so corrupt bytes stop the conversion with the topic and log time
of the last message read; a file without a summary (truncated while recording) is refused with
a hint to run ``mcap recover``.

Hostile files cannot make the reader allocate what they merely claim: reads never ask for more
bytes than the file has left (:class:`_ClampedFile`), a chunk index whose chunk lies outside the
file or claims more than :data:`~robogs.convert.ingest.decompress.MAX_CHUNK_BYTES` is refused up
front, and chunk decompression itself stops at that limit
(:func:`~robogs.convert.ingest.decompress.capped_decompression`).
"""

from __future__ import annotations

import contextlib
import io
import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError

from ..registry import register_converter
from . import cdr_fast, foxglove
from .bag_options import BAG_OPTIONS
from .context import IngestContext
from .decompress import MAX_CHUNK_BYTES, DecompressionLimitError, capped_decompression
from .messages import MessageIngest, TopicInfo
from .read_errors import corrupt_source

__all__ = ["convert_mcap", "detect_mcap", "channel_decoder"]

_MAGIC = b"\x89MCAP0\r\n"


def detect_mcap(path: Path) -> bool:
    """An MCAP file: ``.mcap`` suffix or the MCAP magic bytes."""
    if not path.is_file():
        return False
    if path.suffix.lower() == ".mcap":
        return True
    with open(path, "rb") as fh:
        return fh.read(8) == _MAGIC


class _ClampedFile:
    """A read-only binary file whose ``read(n)`` never asks for more than the bytes left.

    ``BufferedReader.read(n)`` allocates ``n`` bytes before reading, so a record length of
    2**62 read from a damaged file would be a MemoryError instead of a short read.
    """

    def __init__(self, fh: Any, size: int) -> None:
        self._fh = fh
        self._size = size

    def read(self, n: int | None = -1) -> bytes:
        left = max(self._size - self._fh.tell(), 0)
        return self._fh.read(left if n is None or n < 0 or n > left else n)

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def seekable(self) -> bool:
        return True

    def readable(self) -> bool:
        return True


def _check_chunk_indexes(summary: Any, size: int, src: Path) -> None:
    """Refuse chunk indexes that point outside the file or claim more than the chunk limit."""
    for ci in summary.chunk_indexes:
        where = f"chunk at byte {ci.chunk_start_offset}"
        if ci.chunk_start_offset + ci.chunk_length > size or ci.compressed_size > ci.chunk_length:
            raise InputError(
                "MCAP chunk index points past the end of the file",
                path=src,
                where=where,
                hint="the file is truncated or damaged; `mcap recover` may salvage it",
            )
        if ci.uncompressed_size > MAX_CHUNK_BYTES:
            raise DecompressionLimitError(
                f"MCAP chunk claims {ci.uncompressed_size} bytes uncompressed, over the "
                f"{MAX_CHUNK_BYTES}-byte limit",
                path=src,
                where=where,
                hint="the file is corrupt or hostile; real recorders write chunks of a few MiB",
            )


def _misfit(src: Path, topic: str, log_time: int, exc: Exception) -> InputError:
    """A decoded message that lacks the fields of its type (its stored schema is wrong)."""
    return InputError(
        f"message does not fit its type ({type(exc).__name__}: {str(exc)[:160]})",
        path=src,
        where=f"topic {topic} log time {log_time}",
        hint="the message definition stored in the file does not match the topic's type",
    )


def _mcap_errors() -> tuple[type[BaseException], ...]:
    from mcap.exceptions import McapError

    errs: list[type[BaseException]] = [
        McapError,
        struct.error,
        EOFError,
        ValueError,
        OSError,
        KeyError,
        IndexError,
        RuntimeError,
        OverflowError,
    ]
    try:
        from zstandard import ZstdError

        errs.append(ZstdError)
    except ImportError:  # pragma: no cover
        pass
    return tuple(errs)


def _rosbags_decoder(schema: Any, encoding: str) -> Callable[[bytes], Any]:
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    text = schema.data.decode("utf-8")
    store = get_typestore(Stores.EMPTY)
    if schema.encoding == "ros2idl":
        types: dict[str, Any] = {}
        sep = "=" * 80 + "\n"
        for part in text.split(sep):
            if part.strip():
                body = part.split("\n", 1)[1] if part.startswith("IDL: ") else part
                types.update(get_types_from_idl(body))
    else:
        types = get_types_from_msg(text, _rosbags_name(schema.name))
    store.register(types)
    name = _rosbags_name(schema.name)
    if encoding == "ros1":
        return lambda data: store.deserialize_ros1(data, name)
    return lambda data: store.deserialize_cdr(data, name)


def _rosbags_name(name: str) -> str:
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


def channel_decoder(
    message_encoding: str, schema: Any, ros2_factory: Any
) -> Callable[[bytes], Any] | None:
    """A ``bytes -> message`` function for one channel, or ``None`` when none is available."""
    enc = message_encoding.lower()
    senc = (schema.encoding if schema is not None else "").lower()
    if enc == "cdr" and senc == "ros2msg":
        generic = ros2_factory.decoder_for(message_encoding, schema)
        fast = cdr_fast.fast_decoder(schema.name, schema.data.decode("utf-8", errors="replace"))
        if fast is None or generic is None:
            return generic

        def decode(data: bytes) -> Any:
            try:
                return fast(data)
            except ValueError:  # big-endian or malformed: the generic decoder decides
                return generic(data)

        return decode
    if (enc == "cdr" and senc == "ros2idl") or (enc == "ros1" and senc == "ros1msg"):
        return _rosbags_decoder(schema, enc)
    if enc == "json":
        return lambda data: foxglove.to_namespace(json.loads(data))
    if enc == "protobuf" and senc == "protobuf":
        from .protobuf_schema import protobuf_decoder

        return protobuf_decoder(schema.name, schema.data)
    return None


def _message_type(schema: Any) -> str:
    if schema is None:
        return "(no schema)"
    return foxglove.ros_type_of(schema.name) or schema.name


def convert_mcap(src: Path, ctx: IngestContext) -> None:
    """Convert a plain MCAP file (ROS 2 CDR, ROS 1, JSON/Foxglove, protobuf when available)."""
    with capped_decompression():
        _convert_mcap(src, ctx)


def _convert_mcap(src: Path, ctx: IngestContext) -> None:
    """:func:`convert_mcap` with chunk decompression already capped."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    errors = _mcap_errors()
    prov = ctx.provenance
    where = "while reading the summary"
    try:
        fh = open(src, "rb")
        size = src.stat().st_size
    except OSError as exc:
        raise InputError(f"cannot open MCAP ({exc.strerror})", path=src) from None
    try:
        with corrupt_source(
            src,
            errors,
            where=lambda: where,
            what="MCAP",
            hint="the file is damaged; `mcap recover` may salvage it",
        ):
            reader = make_reader(_ClampedFile(fh, size), validate_crcs=True)
            try:
                header = reader.get_header()
                summary = reader.get_summary()
            except errors as exc:
                raise InputError(
                    f"not a readable MCAP file ({type(exc).__name__}: {exc})",
                    path=src,
                    hint="the file is empty, truncated or not MCAP; `mcap recover` rebuilds "
                    "a truncated recording",
                ) from None
            if summary is None:
                raise InputError(
                    "MCAP file has no summary section (truncated while recording?)",
                    path=src,
                    hint="run `mcap recover` on it, then convert the recovered file",
                )
            _check_chunk_indexes(summary, size, src)
            unknown = sorted({ci.compression for ci in summary.chunk_indexes} - {"", "zstd", "lz4"})
            if unknown:
                raise InputError(
                    f"unknown chunk compression {', '.join(map(repr, unknown))}",
                    path=src,
                    hint="MCAP chunks are uncompressed, zstd or lz4; re-write the file with one of them",
                )
            prov.extra["mcap_profile"] = header.profile
            prov.extra["mcap_library"] = header.library
            stats = summary.statistics
            counts: dict[int, int] = dict(stats.channel_message_counts) if stats is not None else {}
            if stats is None:
                prov.note("MCAP has no statistics record; counts taken by a first pass")
                for _, channel, _ in reader.iter_messages(log_time_order=False):
                    counts[channel.id] = counts.get(channel.id, 0) + 1
            ros2 = DecoderFactory()
            decoders: dict[int, Callable[[bytes], Any] | None] = {}
            by_topic: dict[str, list[int]] = {}
            schema_of: dict[int, Any] = {}
            for cid, ch in summary.channels.items():
                schema = summary.schemas.get(ch.schema_id) if ch.schema_id else None
                schema_of[cid] = schema
                try:  # the vendored ROS IDL parser prints its complaints; the note below says it
                    with contextlib.redirect_stderr(io.StringIO()):
                        decoders[cid] = channel_decoder(ch.message_encoding, schema, ros2)
                except Exception as exc:  # noqa: BLE001 - a schema we cannot parse is reported, not fatal
                    decoders[cid] = None
                    prov.note(
                        f"{ch.topic}: schema {getattr(schema, 'name', '?')} could not be parsed "
                        f"({type(exc).__name__}: {str(exc)[:120]})"
                    )
                by_topic.setdefault(ch.topic, []).append(cid)
            topics: list[TopicInfo] = []
            for topic, cids in sorted(by_topic.items()):
                types = {_message_type(schema_of[c]) for c in cids}
                n = sum(counts.get(c, 0) for c in cids)
                bad = [c for c in cids if decoders[c] is None]
                if bad or len(types) != 1:
                    ch = summary.channels[cids[0]]
                    sch = schema_of[cids[0]]
                    reason = (
                        "several message types on one topic"
                        if len(types) != 1
                        else "no decoder for this encoding"
                    )
                    prov.undecodable.append(
                        {
                            "topic": topic,
                            "schema": getattr(sch, "name", None),
                            "schema_encoding": getattr(sch, "encoding", None),
                            "message_encoding": ch.message_encoding,
                            "messages": n,
                            "reason": reason,
                        }
                    )
                    rec = prov.topic(topic, ", ".join(sorted(types)), "ignore")
                    rec.messages = n
                    if n:
                        prov.drop(topic, reason, n)
                    continue
                topics.append(TopicInfo(topic, types.pop(), n))
            start = stats.message_start_time if stats is not None else None
            end = stats.message_end_time if stats is not None else None
            time_range = (
                (start, end) if start is not None and end is not None and start <= end else None
            )
            ingest = MessageIngest(ctx, time_range=time_range)
            static, main = ingest.plan(topics)
            where = "before the first message"
            size_mb = src.stat().st_size / 1e6
            try:
                for group, label, probing in ingest.passes(static, main, src.name):
                    total = sum(ingest.counts[t] for t in group)
                    ctx.progress.start(f"reading {label} ({size_mb:.0f} MB)", total)
                    for schema, channel, message in reader.iter_messages(
                        topics=group, log_time_order=True
                    ):
                        where = f"after topic {channel.topic} log time {message.log_time}"
                        dec = decoders[channel.id]
                        assert dec is not None
                        try:
                            msg = dec(message.data)
                            if schema is not None and foxglove.ros_type_of(schema.name):
                                msg = foxglove.adapt(schema.name, msg)
                        except Exception as exc:  # noqa: BLE001 - any decoder failure is one bad message
                            if not probing:  # counted once, in the main pass
                                ingest.note_undecodable(
                                    channel.topic, message.log_time, f"{type(exc).__name__}: {exc}"
                                )
                            ctx.progress.advance()
                            continue
                        try:
                            if probing:
                                ingest.probe(channel.topic, message.log_time, msg)
                            else:
                                ingest.handle(channel.topic, message.log_time, msg)
                        except (AttributeError, TypeError) as exc:
                            if probing:  # the main pass reports it
                                continue
                            raise _misfit(src, channel.topic, message.log_time, exc) from None
                        ctx.progress.advance()
                    ctx.progress.stop()
                ingest.finish()
            except BaseException:
                ingest.abort()
                raise
    finally:
        ctx.progress.stop()
        fh.close()


register_converter(
    "mcap",
    detect_mcap,
    convert_mcap,
    description="MCAP file (ROS 2, ROS 1, JSON/Foxglove, protobuf/Foxglove)",
    options=BAG_OPTIONS,
    priority=60,
)

"""ROS 1 ``.bag`` files and ROS 2 bag folders, read with ``rosbags``.

``rosbags.highlevel.AnyReader`` (https://gitlab.com/ternaris/rosbags) reads both and registers
the message types from the definitions stored in the bag, so custom types decode without a
ROS installation. For a ROS 2 folder whose storage is not compressed, the storage files
(``.db3`` / ``.mcap``) named in ``metadata.yaml`` are opened directly: rosbags matches a
folder's connections to ``metadata.yaml`` including QoS, and real recorders write QoS there that
differs from the storage file, which would make the folder yield no messages at all. The
counts in ``metadata.yaml`` are compared with the storage's and differences are recorded.
"""

from __future__ import annotations

import sqlite3
import struct
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError, RobogsError

from ..registry import register_converter
from .bag_options import BAG_OPTIONS
from .context import IngestContext
from .decompress import capped_decompression
from .messages import MessageIngest, TopicInfo
from .read_errors import corrupt_source
from .yamlio import read_yaml

__all__ = [
    "convert_ros1",
    "convert_ros2",
    "detect_ros1",
    "detect_ros2",
    "ros2_storage_paths",
    "open_bag",
]

_MAX_META_BYTES = 8 << 20


def detect_ros1(path: Path) -> bool:
    """A ROS 1 bag: a ``.bag`` file."""
    return path.is_file() and path.suffix.lower() == ".bag"


def detect_ros2(path: Path) -> bool:
    """A ROS 2 bag: a folder with ``metadata.yaml`` (sqlite3 or mcap storage)."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def _reader_errors() -> tuple[type[BaseException], ...]:
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as R1
    from rosbags.rosbag2 import ReaderError as R2

    errs: list[type[BaseException]] = [
        AnyReaderError,
        R1,
        R2,
        OSError,
        ValueError,
        struct.error,
        EOFError,
        KeyError,
        IndexError,
        sqlite3.Error,
        RuntimeError,
        AssertionError,
        OverflowError,
    ]
    try:
        from rosbags.typesys import TypesysError

        errs.append(TypesysError)
    except ImportError:  # pragma: no cover - older rosbags
        pass
    try:  # rosbags reads sqlite3 storage through apsw where it is installed
        import apsw

        errs.append(apsw.Error)
    except ImportError:  # pragma: no cover - rosbags falls back to sqlite3
        pass
    return tuple(errs)


def _read_metadata(folder: Path) -> dict[str, Any]:
    meta = folder / "metadata.yaml"
    doc = read_yaml(meta, what="metadata.yaml", max_bytes=_MAX_META_BYTES)
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise InputError(
            "metadata.yaml has no rosbag2_bagfile_information",
            path=meta,
            hint="is this a ROS 2 bag folder?",
        )
    return info


def ros2_storage_paths(folder: Path) -> tuple[list[Path], dict[str, Any]]:
    """What to open for a ROS 2 bag folder, and facts from its ``metadata.yaml``.

    Returns:
        ``(paths, facts)``: the storage files themselves when the bag is not compressed (so
        that QoS differences between ``metadata.yaml`` and the storage do not hide messages),
        else the folder. ``facts`` has ``storage``, ``ros_distro``, ``direct`` and, when direct,
        ``metadata_counts`` (topic -> count as ``metadata.yaml`` says).

    Raises:
        InputError: unreadable metadata, no or missing storage files.
    """
    info = _read_metadata(folder)
    mode = str(info.get("compression_mode") or "").strip().lower()
    files = [folder / Path(str(f)).name for f in info.get("relative_file_paths") or []]
    facts: dict[str, Any] = {
        "storage": str(info.get("storage_identifier", "")),
        "ros_distro": str(info.get("ros_distro", "")) or None,
        "direct": False,
    }
    if not files:
        raise InputError("metadata.yaml lists no storage files", path=folder / "metadata.yaml")
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        raise InputError(
            f"storage files missing: {', '.join(missing)}",
            path=folder,
            hint="copy the whole bag folder",
        )
    if mode in ("", "none") and all(f.suffix in (".db3", ".mcap") for f in files):
        expected = {}
        for t in info.get("topics_with_message_count") or []:
            try:
                expected[str(t["topic_metadata"]["name"])] = int(t["message_count"])
            except (KeyError, TypeError, ValueError):
                continue
        facts.update(direct=True, metadata_counts=expected)
        return files, facts
    return [folder], facts


def _open(paths: list[Path]):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    return AnyReader(paths, default_typestore=get_typestore(Stores.ROS2_HUMBLE))


def _convert(paths: list[Path], src: Path, ctx: IngestContext) -> None:
    errors = _reader_errors()
    reader = None
    where = "while opening"
    try:
        reader = _open(paths)
        reader.open()
    except RobogsError:
        raise
    except errors as exc:
        raise InputError(
            f"cannot open bag ({type(exc).__name__}: {exc})",
            path=src,
            hint="the file is truncated, empty, not a bag, or uses an unknown compression",
        ) from None
    try:
        with corrupt_source(
            src,
            errors,
            where=lambda: where,
            what="bag",
            hint="the file may be truncated; re-record or reindex it",
        ):
            count = reader.message_count
            start, end = reader.start_time, reader.end_time
            time_range = (start, end) if count and start <= end else None
            topics = []
            for name, ti in reader.topics.items():
                if ti.msgtype is None:
                    ctx.provenance.note(f"{name}: several message types on one topic; skipped")
                    ctx.provenance.topic(name, "mixed", "ignore").messages = ti.msgcount
                    ctx.provenance.drop(name, "several message types on one topic", ti.msgcount)
                    continue
                topics.append(TopicInfo(name, ti.msgtype, ti.msgcount))
            expected = ctx.provenance.extra.get("metadata_counts")
            if expected:
                for t in topics:
                    if t.topic in expected and expected[t.topic] != t.count:
                        ctx.provenance.note(
                            f"{t.topic}: metadata.yaml says {expected[t.topic]} messages, "
                            f"the storage holds {t.count}"
                        )
            ingest = MessageIngest(ctx, time_range=time_range)
            static, main = ingest.plan(topics)
            where = "before the first message"
            try:
                for group, label, probing in ingest.passes(static, main, src.name):
                    conns = [c for c in reader.connections if c.topic in set(group)]
                    total = sum(ingest.counts[t] for t in group)
                    ctx.progress.start(f"reading {label}", total)
                    for conn, log_time, raw in reader.messages(connections=conns):
                        where = f"after topic {conn.topic} log time {log_time}"
                        try:
                            msg = reader.deserialize(raw, conn.msgtype)
                        except RobogsError:
                            raise
                        except errors + (TypeError, UnicodeDecodeError) as exc:
                            if not probing:  # counted once, in the main pass
                                ingest.note_undecodable(
                                    conn.topic, log_time, f"{type(exc).__name__}: {exc}"
                                )
                            ctx.progress.advance()
                            continue
                        try:
                            if probing:
                                ingest.probe(conn.topic, log_time, msg)
                            else:
                                ingest.handle(conn.topic, log_time, msg)
                        except (AttributeError, TypeError) as exc:
                            if probing:  # the main pass reports it
                                continue
                            raise InputError(
                                f"message does not fit its type ({type(exc).__name__}: "
                                f"{str(exc)[:160]})",
                                path=src,
                                where=f"topic {conn.topic} log time {log_time}",
                                hint="the message definition stored in the bag does not match "
                                "the topic's type",
                            ) from None
                        ctx.progress.advance()
                    ctx.progress.stop()
                ingest.finish()
            except BaseException:
                ingest.abort()
                raise
    finally:
        ctx.progress.stop()
        try:
            reader.close()
        except Exception:  # noqa: BLE001 - closing a broken reader must not hide the first error
            pass


def convert_ros1(src: Path, ctx: IngestContext) -> None:
    """Convert a ROS 1 bag (bz2/lz4 chunks handled by rosbags)."""
    try:
        with open(src, "rb") as fh:
            head = fh.read(13)
    except OSError as exc:
        raise InputError(f"cannot open bag ({exc.strerror})", path=src) from None
    if not head:
        raise InputError(
            "bag file is empty", path=src, hint="the recording did not start or was not copied"
        )
    if not head.startswith(b"#ROSBAG V2."):
        raise InputError(
            "not a ROS 1 bag (no '#ROSBAG V2.0' header)",
            path=src,
            hint="ROS 2 bags are folders with metadata.yaml; MCAP files use --from mcap",
        )
    ctx.provenance.extra["storage"] = "rosbag1"
    with capped_decompression():
        _convert([src], src, ctx)


def open_bag(paths: list[Path]) -> Any:
    """An (unopened) ``rosbags.highlevel.AnyReader`` over ``paths``, with a default type store
    for storages that carry no message definitions."""
    return _open(paths)


def convert_ros2(src: Path, ctx: IngestContext) -> None:
    """Convert a ROS 2 bag folder (sqlite3 or mcap storage, split files merged by time)."""
    paths, facts = ros2_storage_paths(src)
    prov = ctx.provenance
    prov.extra.update({"storage": facts["storage"], "ros_distro": facts["ros_distro"]})
    if facts["direct"]:
        prov.extra["metadata_counts"] = facts["metadata_counts"]
        prov.note("storage files read directly; metadata.yaml used for its listing only")
    with capped_decompression():
        _convert(paths, src, ctx)


register_converter(
    "ros1",
    detect_ros1,
    convert_ros1,
    description="ROS 1 .bag file (rosbags)",
    options=BAG_OPTIONS,
    priority=50,
)
register_converter(
    "ros2",
    detect_ros2,
    convert_ros2,
    description="ROS 2 bag folder with metadata.yaml (sqlite3 or mcap storage)",
    options=BAG_OPTIONS,
    priority=100,
)

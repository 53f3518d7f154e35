"""Hand-written MCAP files: one chunk, its payload and its size claims chosen by the test.

Records are serialised by the ``mcap`` library's record classes; the JointState payload is
CDR from rosbags. Nothing here uses robogs code.
"""

from __future__ import annotations

import numpy as np

__all__ = ["record", "craft_mcap", "one_message_records"]


def record(rec) -> bytes:
    from mcap.data_stream import RecordBuilder

    b = RecordBuilder()
    rec.write(b)
    return b.end()


def craft_mcap(payload: bytes, compression: str, chunk_claim: int, index_claim: int) -> bytes:
    """A one-chunk MCAP written record by record, its chunk payload and size claims chosen."""
    from mcap.records import Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, Schema, Statistics

    from .seeds import _msgdef

    magic = b"\x89MCAP0\r\n"
    typ = "sensor_msgs/msg/JointState"
    schema = Schema(id=1, name=typ, encoding="ros2msg", data=_msgdef(typ).encode())
    channel = Channel(id=1, topic="/joint_states", message_encoding="cdr", schema_id=1, metadata={})
    out = bytearray(magic)
    out += record(Header(profile="ros2", library="robogs-test"))
    chunk_start = len(out)
    out += record(Chunk(compression=compression, data=payload, message_start_time=1,
                         message_end_time=1, uncompressed_crc=0, uncompressed_size=chunk_claim))  # fmt: skip
    chunk_len = len(out) - chunk_start
    out += record(DataEnd(data_section_crc=0))
    summary = len(out)
    out += record(schema) + record(channel)
    out += record(Statistics(message_count=1, schema_count=1, channel_count=1, attachment_count=0,
                              metadata_count=0, chunk_count=1, message_start_time=1, message_end_time=1,
                              channel_message_counts={1: 1}))  # fmt: skip
    out += record(ChunkIndex(message_start_time=1, message_end_time=1, chunk_start_offset=chunk_start,
                              chunk_length=chunk_len, message_index_offsets={}, message_index_length=0,
                              compression=compression, compressed_size=len(payload),
                              uncompressed_size=index_claim))  # fmt: skip
    out += record(Footer(summary_start=summary, summary_offset_start=0, summary_crc=0))
    return bytes(out + magic)


def one_message_records() -> bytes:
    """One JointState (joints j1, j2 at 0.25 and -0.5 rad) as a Message record, CDR by rosbags."""
    from mcap.records import Message
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    M = ts.types
    msg = M["sensor_msgs/msg/JointState"](
        header=M["std_msgs/msg/Header"](
            stamp=M["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id=""
        ),
        name=["j1", "j2"],
        position=np.array([0.25, -0.5]),
        velocity=np.zeros(0),
        effort=np.zeros(0),
    )
    cdr = bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
    return record(Message(channel_id=1, sequence=0, log_time=1, publish_time=1, data=cdr))

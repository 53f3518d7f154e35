"""Protobuf channels of an MCAP file, decoded from the schema's own ``FileDescriptorSet``.

An MCAP protobuf schema (https://mcap.dev/spec/registry#protobuf) holds a serialized
``google.protobuf.FileDescriptorSet`` with every ``.proto`` file the message needs, and its
name is the fully qualified message name (``foxglove.CompressedImage``). The files are added to
a fresh ``DescriptorPool`` dependencies first; well-known imports a writer left out
(``google/protobuf/timestamp.proto`` ...) come from the protobuf runtime. The message class is
made with ``message_factory.GetMessageClass``, so no generated code is needed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["protobuf_decoder"]

_WELL_KNOWN = ("any", "duration", "empty", "struct", "timestamp", "wrappers", "field_mask")


def _well_known(name: str) -> Any:
    """FileDescriptorProto of a well-known ``google/protobuf/*.proto`` file, or None."""
    import importlib

    from google.protobuf import descriptor_pb2, descriptor_pool

    stem = name.rsplit("/", 1)[-1].removesuffix(".proto")
    if not name.startswith("google/protobuf/") or stem not in _WELL_KNOWN:
        return None
    importlib.import_module(f"google.protobuf.{stem}_pb2")
    proto = descriptor_pb2.FileDescriptorProto()
    descriptor_pool.Default().FindFileByName(name).CopyToProto(proto)
    return proto


def protobuf_decoder(schema_name: str, data: bytes) -> Callable[[bytes], Any]:
    """A ``bytes -> message`` decoder for message ``schema_name`` of a ``FileDescriptorSet``.

    Raises:
        ValueError: the set does not parse, misses a dependency, or lacks the message.
    """
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
    from google.protobuf.message import DecodeError

    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(bytes(data))
    except DecodeError as exc:
        raise ValueError(f"schema is not a FileDescriptorSet ({exc})") from None
    files = {f.name: f for f in fds.file}
    pool = descriptor_pool.DescriptorPool()
    added: set[str] = set()

    def add(name: str, stack: tuple[str, ...]) -> None:
        if name in added:
            return
        if name in stack:
            raise ValueError(f"import cycle through {name}")
        proto = files.get(name) or _well_known(name)
        if proto is None:
            raise ValueError(f"schema lacks the imported file {name!r}")
        for dep in proto.dependency:
            add(dep, (*stack, name))
        pool.Add(proto)
        added.add(name)

    for name in files:
        add(name, ())
    try:
        desc = pool.FindMessageTypeByName(schema_name)
    except KeyError:
        raise ValueError(f"schema has no message {schema_name!r}") from None
    cls = message_factory.GetMessageClass(desc)
    return cls.FromString

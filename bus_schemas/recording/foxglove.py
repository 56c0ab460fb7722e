"""The Foxglove protobuf channels' schemas both ways: the ``foxglove-schemas-protobuf``
class of a message name and its ``FileDescriptorSet`` (what an MCAP ``protobuf`` schema
record holds, written by the recorder), and a message class rebuilt from such a record
(what the reader decodes with). protobuf is imported only when one is needed.
"""

from __future__ import annotations

from typing import Any


def foxglove_message_class(name: str) -> type[Any]:
    """The ``foxglove-schemas-protobuf`` class of Foxglove message ``name``
    (e.g. ``foxglove.SceneUpdate``)."""
    import importlib

    pkg, _, short = name.partition(".")
    if pkg != "foxglove" or not short.isidentifier():
        raise KeyError(f"{name!r} is not a Foxglove message name")
    return getattr(importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2"), short)


def protobuf_descriptor_set(message_class: type[Any]) -> bytes:
    """The serialized ``FileDescriptorSet`` of a protobuf message class: its file and every
    file it imports, dependencies first (what an MCAP ``protobuf`` schema record holds)."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    fds, seen = FileDescriptorSet(), set()

    def add(fd: Any) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString()


def protobuf_class(name: str, descriptor_set: bytes) -> type[Any]:
    """The message class ``name`` of a serialized ``FileDescriptorSet``, in a pool of its
    own (so it is what the recording says, whatever this process has imported)."""
    from google.protobuf import descriptor_pool, message_factory
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    pool = descriptor_pool.DescriptorPool()
    for f in FileDescriptorSet.FromString(descriptor_set).file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


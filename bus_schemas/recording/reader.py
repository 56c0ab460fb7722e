"""Reading recordings: decoder factories for ``mcap.reader.make_reader`` (the mcap package
has no JSON or protobuf decoder) and :func:`read_messages`, which uses both.

JSON channels decode to dicts, protobuf channels (the Foxglove ones) to protobuf messages
whose classes are built from each channel's own schema record.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from typing import Any

from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap.records import Schema

from bus_schemas.recording.foxglove import protobuf_class
from bus_schemas.recording.schemas import MESSAGE_ENCODING, PROTOBUF_ENCODING


class JsonDecoderFactory(DecoderFactory):
    """Decodes channels with message encoding ``json`` (the mcap package has none)."""

    def decoder_for(self, message_encoding: str, schema: Schema | None):
        if message_encoding != MESSAGE_ENCODING:
            return None
        return _decode_json


def _decode_json(data: bytes) -> Any:
    return json.loads(data)


class ProtobufDecoderFactory(DecoderFactory):
    """Decodes channels with message encoding ``protobuf`` into protobuf messages, with the
    classes built from each channel's own schema record (its ``FileDescriptorSet``)."""

    def __init__(self) -> None:
        self._classes: dict[int, Any] = {}

    def decoder_for(self, message_encoding: str, schema: Schema | None):
        if (message_encoding != PROTOBUF_ENCODING or schema is None
                or schema.encoding != PROTOBUF_ENCODING):
            return None
        if schema.id not in self._classes:
            self._classes[schema.id] = protobuf_class(schema.name, schema.data)
        return self._classes[schema.id].FromString


def read_messages(path: str | os.PathLike[str], topics: Iterable[str] | None = None
                  ) -> Iterator[tuple[str, int, Any]]:
    """``(topic, log_time_ns, decoded message)`` of every message of an MCAP file (JSON
    channels as dicts, protobuf channels as protobuf messages)."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory(),
                                                   ProtobufDecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=list(topics) if topics is not None else None):
            yield channel.topic, message.log_time, decoded


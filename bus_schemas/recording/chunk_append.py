"""Appending messages to an mcap ``Writer``'s open chunk with one struct pack each.

``mcap.writer.Writer.add_message`` costs about 3 us of Python per message (a ``Message``
record object, six small packs into a ``BytesIO`` with a seek back for the length, the
statistics and the chunk's message index). A co-simulation records eight messages per
1 ms tick, so :func:`append_messages` does the same bookkeeping, in the same order, with
one pack per message, and the chunk's message indexes write their records with one pack each
(:class:`PackedMessageIndex`; mcap writes two 8-byte packs per message, about 1 us a message
at every chunk's end). It uses the internals of mcap 1.x's ``Writer`` (its statistics,
chunk builder and chunk finalization); :func:`supports` checks that they are there (the
:class:`bus_schemas.recording.recorder.Recorder` falls back to ``add_message`` otherwise), and
a test asserts the file bytes equal those ``add_message`` writes.

The writer also keeps every chunk's ``ChunkIndex`` (a record object with a dict of
offsets, about 1.3 KiB of Python objects each) until ``finish`` writes them into the
summary: about 20 000 chunks, 25 MiB, in an hour-long co-simulation.
:func:`pack_chunk_indexes` has it keep each as the bytes of its summary record instead
(about 200 bytes), in a temporary file spilled to disk past 1 MiB
(:class:`PackedChunkIndexes`): the same bytes written at the end, the memory bounded.
"""

from __future__ import annotations

import io
import struct
import tempfile
from collections.abc import Iterable
from itertools import chain
from typing import Any

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import ChunkIndex, MessageIndex
from mcap.writer import Writer

#: Message record: opcode, record length, channel id, sequence, log time, publish time
_MESSAGE = struct.Struct("<BQHIQQ")
_FIXED = _MESSAGE.size - 9  # record length = fixed fields + data


class PackedMessageIndex(MessageIndex):
    """A chunk's message index for one channel, its record written with one pack: the bytes
    of :meth:`MessageIndex.write`."""

    def write(self, stream: Any) -> None:
        n = len(self.records)
        stream.write(struct.pack(f"<BQHI{2 * n}Q", Opcode.MESSAGE_INDEX, 6 + 16 * n,
                                 self.channel_id, 16 * n, *chain.from_iterable(self.records)))


def supports(writer: Writer) -> bool:
    """True if ``writer`` (chunked) has the internals :func:`append_messages` uses."""
    cb = getattr(writer, "_Writer__chunk_builder", None)
    return (cb is not None and hasattr(writer, "_Writer__statistics")
            and hasattr(writer, "_Writer__chunk_size")
            and callable(getattr(writer, "_Writer__finalize_chunk", None))
            and isinstance(getattr(getattr(cb, "record_writer", None), "_buffer", None),
                           io.BytesIO)
            and all(hasattr(cb, a) for a in ("message_indices", "num_messages",
                                              "message_start_time", "message_end_time")))


def append_messages(writer: Writer, rows: Iterable[tuple[int, int, int, int, bytes]]) -> int:
    """Add ``(channel_id, sequence, log_time_ns, publish_time_ns, data)`` messages to
    ``writer`` exactly as ``writer.add_message`` would, one after the other (statistics,
    chunk message index, chunk finalized once over the chunk size). Returns how many."""
    # the writer's private state (name-mangled, so not in its type; supports() checked it)
    stats: Any = writer._Writer__statistics  # type: ignore[attr-defined]  # (see above)
    cb: Any = writer._Writer__chunk_builder  # type: ignore[attr-defined]  # (see above)
    size: int = writer._Writer__chunk_size  # type: ignore[attr-defined]  # (see above)
    pack = _MESSAGE.pack
    op = Opcode.MESSAGE
    counts = stats.channel_message_counts
    indices = cb.message_indices
    n = 0
    for cid, seq, log_time, publish_time, data in rows:
        if stats.message_count == 0 or log_time < stats.message_start_time:
            stats.message_start_time = log_time
        if log_time > stats.message_end_time:
            stats.message_end_time = log_time
        counts[cid] += 1
        stats.message_count += 1
        if cb.num_messages == 0 or log_time < cb.message_start_time:
            cb.message_start_time = log_time
        if log_time > cb.message_end_time:
            cb.message_end_time = log_time
        idx = indices.get(cid)
        if idx is None:
            idx = indices[cid] = PackedMessageIndex(channel_id=cid, records=[])
        buf = cb.record_writer._buffer
        idx.records.append((log_time, buf.tell()))
        cb.num_messages += 1
        buf.write(pack(op, _FIXED + len(data), cid, seq, log_time, publish_time))
        buf.write(data)
        n += 1
        if buf.tell() > size:
            writer._Writer__finalize_chunk()  # type: ignore[attr-defined]  # private, as above
    return n


class _PackedRecords:
    """Records already serialized, written as they are (what ``ChunkIndex.write`` wrote)."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, stream: RecordBuilder) -> None:
        stream.write(self.data)


class PackedChunkIndexes(list[Any]):
    """The writer's list of chunk indexes, each kept as the bytes of its summary record
    (``append`` serializes it) in a temporary file, in memory up to ``spool_bytes`` (about
    5000 chunks, a quarter of an hour of co-simulation) and on disk beyond (unnamed, gone
    with the process); iterated (by ``Writer.finish``), one record group that writes those
    bytes: the summary's bytes unchanged, the memory bounded."""

    def __init__(self, spool_bytes: int = 1 << 20) -> None:
        super().__init__()
        # as long as the writer (no with-block): closed when collected
        self._file = tempfile.SpooledTemporaryFile(max_size=spool_bytes)  # noqa: SIM115
        self._n = 0

    def append(self, index: ChunkIndex) -> None:
        b = RecordBuilder()
        index.write(b)
        self._file.write(b.end())
        self._n += 1

    def __iter__(self) -> Any:
        if not self._n:
            return iter([])
        f = self._file
        end = f.tell()
        f.seek(0)
        data = f.read()
        f.seek(end)
        return iter([_PackedRecords(data)])

    def __len__(self) -> int:
        return self._n


def pack_chunk_indexes(writer: Writer) -> bool:
    """Have ``writer`` keep its chunk indexes packed (:class:`PackedChunkIndexes`), before
    its first chunk; False (nothing changed) for a writer without the list, or whose list
    is not empty."""
    name = "_Writer__chunk_indices"
    if not isinstance(getattr(writer, name, None), list) or getattr(writer, name):
        return False
    setattr(writer, name, PackedChunkIndexes())
    return True

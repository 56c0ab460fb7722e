"""The :class:`Recorder` that writes a run to MCAP: chunked, compressed, every channel of
:mod:`bus_schemas.recording.schemas`, JSON by :func:`~.json_encoding.encode_json` appended
to the open chunk with one pack per message (:mod:`.chunk_append`), written to a locked
``.part`` file renamed once complete (:mod:`.part_file`), with deferred writes
(:class:`~.deferred.DeferredWrites`) and finishing on a signal
(:class:`~.signals.SignalFinish`).

Units: ``log_time`` of every message in ns (simulation time in lockstep runs, wall time
otherwise). Non-finite floats are written as ``null`` (JSON has no NaN); read a recording
with :func:`bus_schemas.recording.reader.read_messages`.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import IO, Any, cast

import can
from mcap.writer import CompressionType, Writer

from bus_schemas.recording.can_rates import CanRates
from bus_schemas.recording.chunk_append import append_messages, pack_chunk_indexes, supports
from bus_schemas.recording.deferred import DeferredWrites
from bus_schemas.recording.foxglove import foxglove_message_class, protobuf_descriptor_set
from bus_schemas.recording.json_encoding import encode_json
from bus_schemas.recording.part_file import (
    GuardedFile,
    UnsafePartFileError,
    error_naming,
    locked_part,
    same_file,
)
from bus_schemas.recording.schemas import (
    CHANNELS,
    FOXGLOVE_CHANNELS,
    MESSAGE_ENCODING,
    PROTOBUF_ENCODING,
    SCHEMA_ENCODING,
    can_frame_message,
)
from bus_schemas.recording.signals import SignalFinish

_CAN_TOPICS = frozenset(("/can/tx", "/can/rx"))


def _compression(name: str) -> CompressionType:
    if name == "zstd":
        try:
            import zstandard  # noqa: F401
            return CompressionType.ZSTD
        except ImportError:
            name = "lz4"
    if name == "lz4":
        try:
            import lz4.frame  # noqa: F401
            return CompressionType.LZ4
        except ImportError:
            return CompressionType.NONE
    if name == "none":
        return CompressionType.NONE
    raise ValueError(f"compression {name!r}: expected zstd, lz4 or none")


class Recorder(DeferredWrites, SignalFinish):
    """Writes a run to MCAP: chunked, zstd-compressed (lz4 or none when zstd is missing).

    The file is written as ``.<name>.part`` next to ``path`` and renamed to ``path`` by
    :meth:`finish` (also called by ``with`` on exit, normal or not): a file under ``path``
    is always complete, with summary and indexes, mode 0o666 less the umask. A symbolic
    link or another user's file under the ``.part`` name is refused, never written
    (:class:`~.part_file.UnsafePartFileError`). A process killed without a chance to
    finish (SIGKILL, power loss) leaves only the ``.part`` file, whose completed chunks
    ``mcap recover`` can usually salvage. :meth:`install_signal_handlers` makes SIGTERM and
    SIGINT finish the file (at the next safe point if a write is in progress) before the
    process exits. Use one thread per recorder (the main thread if handlers are installed).
    """

    def __init__(self, path: str | os.PathLike[str], *, compression: str = "zstd",
                 chunk_size: int = 512 * 1024, metadata: Mapping[str, Any] | None = None,
                 can_rates: float | None = None) -> None:
        self.path = Path(path)
        self.part_path = self.path.with_name(f".{self.path.name}.part")
        self.compression = _compression(compression)
        #: ``can_rates`` [s]: the CAN frames written are counted and ``/can/rates`` written
        #: every window of that much log time
        self._rates = None if can_rates is None else CanRates(can_rates)
        self._file = GuardedFile(locked_part(self.path, self.part_path), self.path)
        # the writer calls only write and tell, which GuardedFile has (mcap types it as IO)
        self._writer = Writer(cast(IO[bytes], self._file), chunk_size=chunk_size,
                              compression=self.compression)
        self._writer.start(profile="", library="hpcosim bus_schemas")
        self._append = supports(self._writer)  # the one-pack path (chunk_append)
        pack_chunk_indexes(self._writer)  # ~200 bytes kept per chunk (chunk_append)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self.message_count = 0
        self.dropped = 0  # writes after a signal finished the file (exit=False)
        self.finished = False
        DeferredWrites.__init__(self)
        SignalFinish.__init__(self)
        if metadata:
            self.add_metadata("run", metadata)

    # -- channels and records
    def add_channel(self, topic: str, schema: Mapping[str, Any] | None = None,
                    metadata: Mapping[str, str] | None = None) -> int:
        """Register ``topic`` (idempotent) with ``schema`` (default: ``CHANNELS[topic]``, or
        for a topic of :data:`FOXGLOVE_CHANNELS` its Foxglove protobuf schema)."""
        if topic in self._channels:
            return self._channels[topic]
        if schema is None and topic in FOXGLOVE_CHANNELS:
            return self.add_protobuf_channel(topic, FOXGLOVE_CHANNELS[topic], metadata)
        if schema is None:
            if topic not in CHANNELS:
                raise KeyError(f"no schema for topic {topic!r}; pass one")
            schema = CHANNELS[topic]
        name = str(schema.get("title", topic))
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(
                name=name, encoding=SCHEMA_ENCODING,
                data=json.dumps(schema, separators=(",", ":")).encode())
        cid = self._writer.register_channel(topic=topic, message_encoding=MESSAGE_ENCODING,
                                            schema_id=self._schemas[name],
                                            metadata=dict(metadata or {}))
        self._channels[topic] = cid
        self._sequence[cid] = 0
        return cid

    def add_protobuf_channel(self, topic: str, message: str,
                             metadata: Mapping[str, str] | None = None) -> int:
        """Register ``topic`` (idempotent) for the Foxglove protobuf message ``message``
        (e.g. ``foxglove.FrameTransforms``); its messages are written as serialized bytes."""
        if topic in self._channels:
            return self._channels[topic]
        if message not in self._schemas:
            self._schemas[message] = self._writer.register_schema(
                name=message, encoding=PROTOBUF_ENCODING,
                data=protobuf_descriptor_set(foxglove_message_class(message)))
        cid = self._writer.register_channel(topic=topic, message_encoding=PROTOBUF_ENCODING,
                                            schema_id=self._schemas[message],
                                            metadata=dict(metadata or {}))
        self._channels[topic] = cid
        self._sequence[cid] = 0
        return cid

    def register_all(self) -> None:
        """Register every channel of :data:`CHANNELS` and :data:`FOXGLOVE_CHANNELS` (so
        viewers list them all)."""
        for topic in (*CHANNELS, *FOXGLOVE_CHANNELS):
            self.add_channel(topic)

    def write(self, topic: str, message: Any, log_time_ns: int | None = None,
              publish_time_ns: int | None = None) -> None:
        """Write one message (a JSON-able object, or pre-encoded JSON bytes)."""
        if self.finished:
            if self.interrupted is not None:
                self.dropped += 1
                return
            raise RuntimeError(f"recorder {self.path} is finished")
        t = time.time_ns() if log_time_ns is None else int(log_time_ns)
        if self._rates is not None and topic in _CAN_TOPICS and isinstance(message, dict):
            for ns, rates in self._rates.add(message, t):
                self.write("/can/rates", rates, ns)
        data = message if isinstance(message, bytes) else encode_json(message)
        outer = self._busy
        self._busy = True
        try:
            cid = self._channels[topic] if topic in self._channels else self.add_channel(topic)
            seq = self._sequence[cid] = self._sequence[cid] + 1
            pub = t if publish_time_ns is None else int(publish_time_ns)
            if self._append:
                append_messages(self._writer, ((cid, seq, t, pub, data),))
            else:
                self._writer.add_message(channel_id=cid, log_time=t, data=data,
                                         publish_time=pub, sequence=seq)
            self.message_count += 1
        finally:
            self._busy = outer
        if not outer and self._pending is not None:
            self._handle_pending()

    def write_many(self, rows: Iterable[tuple[str, Any, int]]) -> int:
        """Write ``(topic, message, log time [ns])`` rows in order, each as :meth:`write`
        writes it (publish time = log time; the ``/can/rates`` windows a frame closes
        before it), with one append into the chunk for all of them: the same records, the
        same bytes.  Returns how many rows (``/can/rates`` records not counted)."""
        if not self._append:
            n = 0
            for topic, message, ns in rows:
                self.write(topic, message, ns)
                n += 1
            return n
        if self.finished:
            if self.interrupted is not None:
                k = sum(1 for _ in rows)
                self.dropped += k
                return k
            raise RuntimeError(f"recorder {self.path} is finished")
        out: list[tuple[int, int, int, int, bytes]] = []
        channels, sequence, rates = self._channels, self._sequence, self._rates

        def channel(topic: str) -> int:
            if topic in channels:
                return channels[topic]
            flush()  # a new channel's records go after the messages before it
            return self.add_channel(topic)

        def flush() -> None:
            append_messages(self._writer, out)
            self.message_count += len(out)
            out.clear()

        n = 0
        outer = self._busy
        self._busy = True
        try:
            for topic, message, ns in rows:
                t = int(ns)
                if rates is not None and topic in _CAN_TOPICS and isinstance(message, dict):
                    for rns, rate in rates.add(message, t):
                        rate_data = encode_json(rate)
                        cid = channel("/can/rates")
                        seq = sequence[cid] = sequence[cid] + 1
                        out.append((cid, seq, rns, rns, rate_data))
                data = message if isinstance(message, bytes) else encode_json(message)
                cid = channel(topic)
                seq = sequence[cid] = sequence[cid] + 1
                out.append((cid, seq, t, t, data))
                n += 1
        finally:  # what was built is written, as one write at a time would have
            try:
                flush()
            finally:
                self._busy = outer
        if not outer and self._pending is not None:
            self._handle_pending()
        return n

    def write_can(self, msg: can.Message, direction: str, log_time_ns: int | None = None,
                  *, name: str | None = None, status: str | None = None) -> None:
        """Write a frame to ``/can/tx`` or ``/can/rx``."""
        self.write(f"/can/{direction}", can_frame_message(msg, direction, name=name,
                                                           status=status), log_time_ns)


    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """A metadata record; values are stored as strings (JSON for non-strings)."""
        self._check_open()
        with self._critical():
            self._writer.add_metadata(name, {str(k): v if isinstance(v, str) else
                                             encode_json(v).decode()
                                             for k, v in data.items()})

    def add_attachment(self, name: str, data: bytes,
                       media_type: str = "application/octet-stream",
                       log_time_ns: int | None = None) -> None:
        """An attachment (e.g. the DBC, configs, the gait file)."""
        self._check_open()
        t = time.time_ns() if log_time_ns is None else int(log_time_ns)
        with self._critical():
            self._writer.add_attachment(create_time=t, log_time=t, name=name,
                                        media_type=media_type, data=bytes(data))

    def _check_open(self) -> None:
        if self.finished:
            raise RuntimeError(f"recorder {self.path} is finished")

    def flush(self) -> None:
        """Push completed chunks to the OS (the open chunk stays in memory until full)."""
        if not self.finished:
            self._file.flush()

    def finish(self) -> Path:
        """Write summary and indexes, close, rename to :attr:`path`. Idempotent."""
        if self.finished:
            return self.path
        with self._critical():
            self.write_deferred()
            self.finished = True
            try:
                self._writer.finish()
                self._file.flush()
                os.fsync(self._file.fileno())
                self._check_part()
                # renamed while still locked: no other run can take the part in between
                os.replace(self.part_path, self.path)
            except OSError as e:  # a full disk: no partial file, an error naming the file
                self._unlink_part()
                raise error_naming(e, self.path) from None
            finally:
                with contextlib.suppress(OSError):  # closing flushes: the disk may be full
                    self._file.close()
                self.restore_signal_handlers()
        return self.path

    def _check_part(self) -> None:
        """The part's name still holds this run's file (nothing renamed over it)."""
        if not same_file(self._file.fileno(), self.part_path):
            raise UnsafePartFileError(f"{self.part_path}: no longer this run's file (moved "
                                      f"or replaced while recording); {self.path} not written")

    def _unlink_part(self) -> None:
        """Remove the part file if its name still holds this run's file."""
        if same_file(self._file.fileno(), self.part_path):
            self.part_path.unlink(missing_ok=True)

    @property
    def write_failed(self) -> bool:
        """A write to the file failed (a full disk, a file-size limit): :meth:`abort`."""
        return self._file.error is not None

    def abort(self) -> None:
        """Close without finishing and delete the ``.part`` file (a write failed: the disk
        is full or the file too large); nothing is left under either name. Idempotent."""
        if self.finished:
            return
        self.finished = True
        self._unlink_part()
        with contextlib.suppress(OSError):
            self._file.close()
        self.restore_signal_handlers()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.write_failed:
            self.abort()  # finishing would fail the same way
        else:
            self.finish()


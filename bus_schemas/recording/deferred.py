"""Deferred writes of a :class:`~bus_schemas.recording.recorder.Recorder`: queue a record
now, serialize and write it when the caller has time (the co-simulation writes while it
waits for the controller's reply); :meth:`~DeferredWrites.write_deferred` writes the queue
in order, ``finish()`` what is left, also when a signal finishes the file. Records are
built only when written, so a hot path pays for a tuple, not for building the record."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

import can

from bus_schemas.recording.schemas import can_frame_message

#: a queue entry: (topic, build, args, log time [ns]); topic None: ``build(*args)`` gives
#: (topic, message) pairs (:meth:`DeferredWrites.defer_many`)
Entry = tuple[str | None, Callable[..., Any] | None, tuple[Any, ...], int]


def _can_record(msg: can.Message, direction: str, name: str | None, status: str | None
                ) -> dict[str, Any]:
    return can_frame_message(msg, direction, name=name, status=status)


class DeferredWrites:
    """The deferred writes of the recorder (a mixin: it writes through the recorder's
    ``write`` and ``write_many`` and stops queueing once the file is ``finished``)."""

    finished: bool

    if TYPE_CHECKING:
        def write(self, topic: str, message: Any, log_time_ns: int | None = None,
                  publish_time_ns: int | None = None) -> None: ...

        def write_many(self, rows: Iterable[tuple[str, Any, int]]) -> int: ...

    def __init__(self) -> None:
        self._deferred: deque[Entry] = deque()

    def defer(self, topic: str, message: Any, log_time_ns: int | None = None) -> None:
        """Queue one message (JSON-able or bytes; must not change afterwards) for
        :meth:`write_deferred`. ``log_time_ns`` None: the time of this call."""
        self.defer_call(topic, log_time_ns, None, message)

    def defer_call(self, topic: str, log_time_ns: int | None,
                   build: Callable[..., Any] | None, *args: Any) -> None:
        """Queue the message ``build(*args)``, built only when written (so the caller's
        hot path pays for a tuple, not for building the record); ``build`` None: the one
        argument is the message."""
        if self.finished:
            self.write(topic, build(*args) if build else args[0], log_time_ns)
            return
        self._deferred.append((topic, build, args, time.time_ns() if log_time_ns is None
                               else int(log_time_ns)))

    def defer_many(self, log_time_ns: int | None, build: Callable[..., Iterable[
            tuple[str, Any]]], *args: Any) -> None:
        """Queue the messages ``build(*args)`` gives as (topic, message) pairs, all at one
        log time, built only when written: one queue entry for the several records of one
        event (a cycle's frames and what they carry), so the caller's hot path pays for one
        tuple."""
        ns = time.time_ns() if log_time_ns is None else int(log_time_ns)
        if self.finished:
            for topic, message in build(*args):
                self.write(topic, message, ns)
            return
        self._deferred.append((None, build, args, ns))

    def defer_can(self, msg: can.Message, direction: str, log_time_ns: int | None = None,
                  *, name: str | None = None, status: str | None = None) -> None:
        """Queue a frame for ``/can/tx`` or ``/can/rx`` (see the recorder's
        ``write_can``)."""
        if direction not in ("tx", "rx"):
            raise ValueError(f"direction {direction!r}: expected 'tx' or 'rx'")
        self.defer_call(f"/can/{direction}", log_time_ns, _can_record, msg, direction, name,
                        status)

    @property
    def deferred(self) -> int:
        """Entries queued and not yet written (a :meth:`defer_many` entry counts once)."""
        return len(self._deferred)

    def write_deferred(self, stop: Callable[[], bool] | None = None) -> int:
        """Write the queued messages in queue order; returns how many. ``stop``: asked
        before each queue entry, True leaves the rest queued (for a later call or
        ``finish()``: the file's records and their order are the same either way)."""
        n = 0
        q = self._deferred
        while q and not self.finished:
            if stop is not None and stop():
                break
            topic, build, args, ns = q.popleft()
            if topic is None:  # one event's records (defer_many, whose build is given)
                rows = build(*args)  # type: ignore[misc]  # given with topic None
                n += self.write_many([(tp, message, ns) for tp, message in rows])
                continue
            self.write(topic, build(*args) if build else args[0], ns)
            n += 1
        return n

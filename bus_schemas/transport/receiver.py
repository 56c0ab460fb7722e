"""What a :class:`~bus_schemas.transport.zenoh_can.ZenohBus` receives through zenoh
subscribers: its frames (:class:`Receiver`, a blocking receive with a timeout in the
caller's thread) and the other node's liveliness token (:class:`PeerWatch`).

zenoh's Python handlers have no receive timeout, so a small waker thread puts an empty
sample on a private session-local key (``<receive key>/wake/<uuid>``, never sent to the
network) when a ``recv`` deadline passes. When the ring channel is full, the oldest frames
are dropped, as an overrun CAN receive buffer would.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

import zenoh


class Receiver:
    """Blocking receive with a timeout from one zenoh subscriber, in the caller's thread.

    Samples on keys outside ``accept`` (the wake-ups) make :meth:`recv` return None early;
    python-can's ``BusABC.recv`` then calls again with the time left. With ``poll`` > 0 s
    a receive that finds nothing polls the ring for up to that long, giving the CPU away
    between polls (``os.sched_yield``), before it blocks: a frame arriving meanwhile is
    taken without the sleep and wake-up of a blocked thread (lockstep co-simulation, where
    the reply is due within a fraction of a millisecond), for CPU time spent polling.
    """

    MAX_BLOCK = 0.25  # s; an indefinite wait is cut into slices so Python handles signals

    def __init__(self, session: zenoh.Session, sub_key: str, accept: frozenset[str],
                 capacity: int, poll: float = 0.0) -> None:
        self._session = session
        self.poll = max(0.0, float(poll))  # s of yielding busy-poll before blocking
        self._accept = accept
        self._wake_key = f"{sub_key.removesuffix('/**')}/wake/{uuid.uuid4().hex}"
        self._cond = threading.Condition()
        self._deadline: float | None = None  # armed by recv
        self._target: float | None = None  # what the waker currently waits for
        self._stop = False
        self._sub = session.declare_subscriber(sub_key, zenoh.handlers.RingChannel(capacity))
        self._thread = threading.Thread(target=self._waker, daemon=True,
                                        name=f"ZenohBus-waker {sub_key}")
        self._thread.start()

    def _waker(self) -> None:
        cond = self._cond
        while True:
            with cond:
                while True:
                    if self._stop:
                        return
                    d, now = self._deadline, time.monotonic()
                    if d is not None and d <= now:
                        self._deadline = None
                        break
                    self._target = d
                    cond.wait(None if d is None else d - now)
            if not self.wake():
                return

    def wake(self) -> bool:
        """Make a blocked :meth:`recv` return (False if the session is gone)."""
        try:
            self._session.put(self._wake_key, b"",
                              allowed_destination=zenoh.Locality.SESSION_LOCAL)
            return True
        except Exception:
            return False

    def try_recv(self) -> zenoh.Sample | None:
        """The next sample on an accepted key already received, or None (never waits)."""
        handler = self._sub.handler
        while (s := handler.try_recv()) is not None:
            if str(s.key_expr) in self._accept:
                return s
        return None

    def recv(self, timeout: float | None) -> zenoh.Sample | None:
        """The next sample on an accepted key, or None (timeout or wake-up). Raises
        ``zenoh.ZError`` once the subscriber or session is closed."""
        handler = self._sub.handler
        while (s := handler.try_recv()) is not None:
            if str(s.key_expr) in self._accept:
                return s
        if timeout is not None and timeout <= 0:
            return None
        if self.poll > 0:
            budget = self.poll if timeout is None else min(self.poll, timeout)
            end = time.perf_counter() + budget
            while True:
                os.sched_yield()
                s = handler.try_recv()
                if s is not None:
                    return s if str(s.key_expr) in self._accept else None
                if time.perf_counter() >= end:
                    break
            if timeout is not None:
                timeout -= budget
                if timeout <= 0:
                    return None
        wait = self.MAX_BLOCK if timeout is None else min(timeout, 1e6)
        deadline = time.monotonic() + wait
        with self._cond:
            self._deadline = deadline
            if self._target is None or deadline < self._target:
                self._cond.notify()
        try:
            s = handler.recv()
        finally:
            self._deadline = None
        return s if str(s.key_expr) in self._accept else None

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify()
        with contextlib.suppress(Exception):
            self._sub.undeclare()
        self._thread.join(timeout=1.0)


class PeerWatch:
    """The other node's liveliness token, watched
    (:meth:`~bus_schemas.transport.zenoh_can.ZenohBus.watch_peer`): with a callback it is
    called with True (alive) / False (gone) from zenoh's thread (it must not block); without
    one :meth:`poll` returns the changes seen since the last call (a
    :class:`~bus_schemas.transport.liveliness.PeerEvents`)."""

    def __init__(self, session: zenoh.Session, key: str,
                 callback: Callable[[bool], None] | None) -> None:
        # the subscriber that queues the changes for poll (None: the watch calls back)
        self._queue: zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]] | None = None
        self._sub: zenoh.Subscriber[Any]
        if callback is not None:
            cb = callback

            def on_sample(sample: zenoh.Sample) -> None:
                cb(sample.kind == zenoh.SampleKind.PUT)

            self._sub = session.liveliness().declare_subscriber(key, on_sample, history=True)
        else:
            self._queue = self._sub = session.liveliness().declare_subscriber(
                key, zenoh.handlers.FifoChannel(64), history=True)

    def poll(self) -> list[bool]:
        """The changes since the last call (True: alive, False: gone), oldest first."""
        if self._queue is None:
            raise RuntimeError("this watch calls back; it has nothing to poll")
        out = []
        s = self._queue.try_recv()
        while s is not None:
            out.append(s.kind == zenoh.SampleKind.PUT)
            s = self._queue.try_recv()
        return out

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()

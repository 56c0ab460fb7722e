"""A python-can interface that carries CAN frames between processes over zenoh.

Registered as the ``zenoh`` interface through the ``can.interface`` entry point, so
``can.Bus(interface="zenoh", channel="run42/ctrl", connect="tcp/127.0.0.1:7447")`` works
once the project is installed (``ZenohBus(...)`` directly works without installing).

``channel`` is ``<run_id>/<role>``: role ``plant`` sends on ``.../can/tx`` and receives
``.../can/rx``; ``ctrl`` the reverse; ``monitor`` receives both and cannot send. The
explicit pair forms ``<run_id>/tx:rx`` (= plant) and ``<run_id>/rx:tx`` (= ctrl) are
accepted too. Plant and controller buses also declare the liveliness token
``hpcosim/run/<run_id>/<plant|ctrl>/alive`` (see :mod:`bus_schemas.keys`).

Frames travel as a 15-byte header plus the data bytes (:func:`pack_message`); the received
message keeps the sender's ``timestamp`` as it was (seconds), so a lockstep plant can stamp
frames with simulation time; ``stamp=True`` makes the bus stamp wall time (``time.time()``)
at send instead. :meth:`ZenohBus.send_batch` sends the frames of one control cycle as one
zenoh sample (a *frame batch*, :func:`pack_batch`, like a CAN driver's bulk transfer: each
frame still individually encoded, counted and checked; the receiver's ``recv`` returns them
one by one, in order). Plain ``send`` sends one frame in the single-frame form.

Reception happens in the caller's thread, one hop from zenoh's network thread: ``recv``
blocks in the subscriber's ring channel (no Python callback, no reader thread). zenoh's
Python handlers have no receive timeout, so a small waker thread puts an empty sample on a
private session-local key (``<receive key>/wake/<uuid>``, never sent to the network) when a
``recv`` deadline passes. When the ring channel (``rx_queue_size`` frames) is full, the
oldest frames are dropped, as an overrun CAN receive buffer would; the protocol's rolling
counters (:class:`bus_schemas.codec.FrameChecker`) reveal such losses.
"""

from __future__ import annotations

import contextlib
import functools
import os
import struct
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import can
import zenoh

from bus_schemas import keys
from bus_schemas.frame import Frame
from bus_schemas.keys import Direction
from bus_schemas.zenoh_config import ZenohMode, make_config

WIRE_VERSION = 1
BATCH_VERSION = 2
MAX_BATCH = 255  # frames per batch sample (count byte)
_HEADER = struct.Struct("<BdIBB")  # version, timestamp [s], arbitration id, flags, dlc
_EXT, _REMOTE, _ERROR, _FD, _BRS, _ESI = 1, 2, 4, 8, 16, 32
_MAX_DATA = 64
ROLES: dict[str, tuple[Direction | None, tuple[Direction, ...]]] = {
    "plant": (Direction.TX, (Direction.RX,)),
    "ctrl": (Direction.RX, (Direction.TX,)),
    "monitor": (None, (Direction.TX, Direction.RX)),
}


def pack_message(msg: can.Message, timestamp: float | None = None) -> bytes:
    """Wire form of a frame: ``<BdIBB`` header (version, timestamp s, id, flags, dlc) and
    the data bytes. Flags: 1 extended id, 2 remote, 4 error, 8 FD, 16 BRS, 32 ESI.
    ``timestamp`` replaces ``msg.timestamp`` when given."""
    flags = ((_EXT if msg.is_extended_id else 0) | (_REMOTE if msg.is_remote_frame else 0)
             | (_ERROR if msg.is_error_frame else 0) | (_FD if msg.is_fd else 0)
             | (_BRS if msg.bitrate_switch else 0) | (_ESI if msg.error_state_indicator else 0))
    data = bytes(msg.data or b"")
    if len(data) > _MAX_DATA:
        raise ValueError(f"CAN frame with {len(data)} data bytes (max {_MAX_DATA})")
    ts = float(msg.timestamp if timestamp is None else timestamp)
    return _HEADER.pack(WIRE_VERSION, ts, msg.arbitration_id, flags, msg.dlc & 0xFF) + data


def unpack_message(payload: bytes, channel: Any = None) -> can.Message | None:
    """The frame in ``payload``, or None if it is not a valid wire form (never raises)."""
    if len(payload) < _HEADER.size or payload[0] != WIRE_VERSION:
        return None
    _, ts, aid, flags, dlc = _HEADER.unpack_from(payload)
    data = payload[_HEADER.size:]
    if len(data) > _MAX_DATA or aid > 0x1FFFFFFF or ts != ts:
        return None
    if not flags:  # a classic data frame with a standard id (the common case)
        return can.Message(timestamp=ts, arbitration_id=aid, is_extended_id=False,
                           channel=channel, dlc=dlc, data=data, is_rx=True)
    return can.Message(timestamp=ts, arbitration_id=aid, is_extended_id=bool(flags & _EXT),
                       is_remote_frame=bool(flags & _REMOTE),
                       is_error_frame=bool(flags & _ERROR), channel=channel, dlc=dlc,
                       data=data, is_fd=bool(flags & _FD), is_rx=True,
                       bitrate_switch=bool(flags & _BRS),
                       error_state_indicator=bool(flags & _ESI))


_CLASSIC = _HEADER.size + 8  # bytes of a classic 8-byte frame's wire form


@functools.cache
def _batch_struct(n: int) -> struct.Struct:
    """The layout of a batch of ``n`` classic 8-byte frames: version, count, then per
    frame its length (23) and its :func:`pack_message` form (``<BdIBB`` + 8 bytes)."""
    return struct.Struct("<BB" + "BBdIBB8s" * n)


def pack_batch(msgs: Sequence[can.Message | Frame], timestamp: float | None = None) -> bytes:
    """Wire form of a frame batch: version byte 2, frame count n (1..255), then per frame
    its length L (one byte) and its :func:`pack_message` form (L bytes; 23 for a classic
    8-byte frame, so four frames take 2 + 4 x 24 = 98 bytes). A batch of
    :class:`~bus_schemas.codec.Frame` s is packed in one ``struct`` call."""
    n = len(msgs)
    if not 1 <= n <= MAX_BATCH:
        raise ValueError(f"frame batch of {n} frames (1..{MAX_BATCH})")
    fields: list[Any] = [BATCH_VERSION, n]
    for m in msgs:  # a batch of classic Frames (the hot paths'): one struct call
        if type(m) is not Frame or len(m[2]) != 8:
            break
        fields += (_CLASSIC, WIRE_VERSION, float(m[0] if timestamp is None else timestamp),
                   m[1], 0, 8, m[2])
    else:
        return _batch_struct(n).pack(*fields)
    parts = [bytes((BATCH_VERSION, n))]
    for m in msgs:
        p = pack_message(m, timestamp)
        parts.append(bytes((len(p),)))
        parts.append(p)
    return b"".join(parts)


def unpack_payload(payload: bytes, channel: Any = None) -> tuple[list[can.Message], int]:
    """The frames of a sample (single frame or batch) and the number of malformed ones
    (a batch whose lengths do not add up counts as one). Never raises."""
    if payload[:1] != b"\x02":
        m = unpack_message(payload, channel)
        return ([m], 0) if m is not None else ([], 1)
    n, pos, end = (payload[1] if len(payload) > 1 else 0), 2, len(payload)
    spans = []
    for _ in range(n):
        size = payload[pos] if pos < end else end
        if pos + 1 + size > end:
            return [], 1
        spans.append((pos + 1, pos + 1 + size))
        pos += 1 + size
    if pos != end or n == 0:
        return [], 1
    out, bad = [], 0
    for a, b in spans:
        m = unpack_message(payload[a:b], channel)
        if m is None:
            bad += 1
        else:
            out.append(m)
    return out, bad


def unpack_frames(payload: bytes, channel: Any = None
                  ) -> tuple[list[can.Message | Frame], int]:
    """:func:`unpack_payload`, each classic 8-byte data frame with a standard id as a
    light :class:`~bus_schemas.codec.Frame` (the same fields) and the rest as
    ``can.Message``; a batch of classic frames is read in one ``struct`` call. Never
    raises."""
    n = payload[1] if len(payload) > 1 and payload[0] == BATCH_VERSION else 0
    if n and len(payload) == 2 + (_CLASSIC + 1) * n:
        f = _batch_struct(n).unpack(payload)
        # the common case checked column-wise (lengths, versions, flags, dlc, ids, no NaN
        # timestamp: a sum of floats is NaN if one is, and inf - inf only sends a good
        # batch the long way): every frame a classic Frame
        ts, ids = f[4::7], f[5::7]
        if (f[2::7].count(_CLASSIC) == n and f[3::7].count(WIRE_VERSION) == n
                and f[6::7].count(0) == n and f[7::7].count(8) == n and max(ids) <= 0x7FF
                and sum(ts) == sum(ts)):
            return list(map(Frame, ts, ids, f[8::7])), 0
        if not all(payload[2 + i * (_CLASSIC + 1)] == _CLASSIC for i in range(n)):
            msgs, bad = unpack_payload(payload, channel)
            return list(msgs), bad
        out: list[can.Message | Frame] = []
        bad = 0
        for i in range(2, len(f), 7):
            _, ver, ts, aid, flags, dlc, data = f[i:i + 7]
            if ver == WIRE_VERSION and not flags and dlc == 8 and aid <= 0x7FF and ts == ts:
                out.append(Frame(ts, aid, data))
                continue
            a = 3 + (i - 2) // 7 * (_CLASSIC + 1)
            m = unpack_message(payload[a:a + _CLASSIC], channel)
            if m is None:
                bad += 1
            else:
                out.append(m)
        return out, bad
    msgs, bad = unpack_payload(payload, channel)
    return list(msgs), bad


def publisher_matched(pub: zenoh.Publisher) -> bool:
    """True if a subscriber matches ``pub`` (zenoh 1.x returns a ``MatchingStatus`` object,
    which is always truthy, where its stub promises a bool)."""
    status = pub.matching_status
    return bool(getattr(status, "matching", status))


def parse_channel(channel: str) -> tuple[str, Direction | None, tuple[Direction, ...]]:
    """``(run_id, send direction or None, receive directions)`` of a bus channel."""
    run_id, sep, spec = str(channel).rpartition("/")
    if not sep:
        raise ValueError(f"channel {channel!r}: expected <run_id>/<plant|ctrl|monitor>")
    keys.validate_run_id(run_id)
    if spec in ROLES:
        send, recv = ROLES[spec]
    else:
        s, colon, r = spec.partition(":")
        try:
            send, recv = Direction(s), (Direction(r),)
        except ValueError:
            raise ValueError(f"channel {channel!r}: role must be plant, ctrl, monitor, tx:rx "
                             "or rx:tx") from None
        if not colon or send == recv[0]:
            raise ValueError(f"channel {channel!r}: send and receive directions must differ")
    return run_id, send, recv


class _Receiver:
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
    """The other node's liveliness token, watched (:meth:`ZenohBus.watch_peer`): with a
    callback it is called with True (alive) / False (gone) from zenoh's thread (it must
    not block); without one :meth:`poll` returns the changes seen since the last call."""

    def __init__(self, session: zenoh.Session, key: str,
                 callback: Callable[[bool], None] | None) -> None:
        if callback is not None:
            cb = callback

            def on_sample(sample: zenoh.Sample) -> None:
                cb(sample.kind == zenoh.SampleKind.PUT)

            self._sub = session.liveliness().declare_subscriber(key, on_sample, history=True)
            self._polled = False
        else:
            self._sub = session.liveliness().declare_subscriber(
                key, zenoh.handlers.FifoChannel(64), history=True)
            self._polled = True

    def poll(self) -> list[bool]:
        """The changes since the last call (True: alive, False: gone), oldest first."""
        if not self._polled:
            raise RuntimeError("this watch calls back; it has nothing to poll")
        out = []
        s = self._sub.try_recv()
        while s is not None:
            out.append(s.kind == zenoh.SampleKind.PUT)
            s = self._sub.try_recv()
        return out

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._sub.undeclare()


class ZenohBus(can.BusABC):
    """CAN over zenoh between processes (see the module docstring).

    :param channel: ``<run_id>/<plant|ctrl|monitor>`` or ``<run_id>/<tx:rx|rx:tx>``.
    :param listen: zenoh endpoints to listen on (list or comma-separated string).
    :param connect: zenoh endpoints to connect to.
    :param mode: zenoh mode, ``peer`` (default) or ``client``.
    :param allow_remote: allow non-loopback endpoints (default: loopback only).
    :param zenoh_options: further zenoh config settings (see ``make_config``).
    :param session: an open zenoh session to use instead of opening one; it stays open at
        :meth:`shutdown` (its owner closes it).
    :param receive_own_messages: also deliver sent frames to this bus's ``recv``.
    :param rx_queue_size: receive ring size (when full, the oldest frames are dropped).
    :param declare_alive: declare the plant/ctrl liveliness token.
    :param stamp: send ``time.time()`` as the frame timestamp instead of ``msg.timestamp``.
    :param low_latency: zenoh's low-latency transport (both peers must set it; see
        :func:`bus_schemas.zenoh_config.make_config`).
    :param poll_us: before a ``recv`` blocks, poll for up to this many microseconds,
        yielding the CPU between polls (default 0: block at once).
    """

    def __init__(self, channel: str, can_filters: Any = None, *,
                 listen: Any = None, connect: Any = None,
                 mode: ZenohMode | str = ZenohMode.PEER,
                 allow_remote: bool = False, zenoh_options: dict[str, Any] | None = None,
                 session: zenoh.Session | None = None, receive_own_messages: bool = False,
                 rx_queue_size: int = 10_000, declare_alive: bool = True,
                 stamp: bool = False, low_latency: bool = False, poll_us: float = 0.0,
                 **kwargs: Any) -> None:
        run_id, send, recv = parse_channel(channel)
        self.run_id = run_id
        self.channel = channel
        self.send_key = keys.can_key(run_id, send) if send else None
        self.recv_keys = tuple(keys.can_key(run_id, d) for d in recv)
        self.receive_own_messages = receive_own_messages
        self.stamp = stamp
        self.rx_queue_size = int(rx_queue_size)
        self.rx_malformed = 0
        self._own: deque[can.Message] = deque()
        self._pending: deque[can.Message] = deque()  # rest of a received batch
        self._owns_session = session is None
        self._pub: zenoh.Publisher | None = None
        self._rx: _Receiver | None = None
        self._token: zenoh.LivelinessToken | None = None
        cfg = None
        if session is None:
            cfg = make_config(listen=listen, connect=connect, mode=mode,
                              allow_remote=allow_remote, low_latency=low_latency,
                              options=zenoh_options)
        self.node = None if send is None else "plant" if send is Direction.TX else "ctrl"
        self.peer_node = {"plant": "ctrl", "ctrl": "plant"}.get(self.node or "")
        try:
            self._session = session if session is not None else zenoh.open(cfg)
            if declare_alive and self.node is not None:
                self._token = self._session.liveliness().declare_token(
                    keys.alive_key(run_id, self.node))
            if self.send_key:
                self._pub = self._session.declare_publisher(
                    self.send_key, congestion_control=zenoh.CongestionControl.BLOCK,
                    priority=zenoh.Priority.REAL_TIME, express=True,
                    reliability=zenoh.Reliability.RELIABLE)
            # one subscriber: the receive key (or both CAN keys for a monitor) and, below
            # it, this bus's private wake key
            sub_key = (f"{self.recv_keys[0]}/**" if len(self.recv_keys) == 1
                       else f"{keys.run_prefix(run_id)}/can/**")
            self._rx = _Receiver(self._session, sub_key, frozenset(self.recv_keys),
                                 self.rx_queue_size, float(poll_us) * 1e-6)
        except Exception as e:
            self._close()
            raise can.CanInitializationError(f"ZenohBus {channel!r}: {e}") from e
        self.channel_info = (f"zenoh send {self.send_key or '-'} "
                             f"recv {', '.join(self.recv_keys)}")
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    @property
    def session(self) -> zenoh.Session:
        """The zenoh session this bus uses."""
        return self._session

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Publish one frame (reliable, blocking congestion control; ``timeout`` is not
        supported by zenoh and ignored)."""
        self._publish(pack_message(msg, time.time() if self.stamp else None))

    def send_batch(self, msgs: Sequence[can.Message], timeout: float | None = None) -> None:
        """Publish the frames of one cycle as one zenoh sample (:func:`pack_batch`; more
        than 255 frames go as several, a single frame in the single-frame form). The
        receiver's ``recv`` returns them one by one in this order. Nothing for none."""
        if type(msgs) is list and 1 < len(msgs) <= MAX_BATCH and not self.stamp:
            self._publish(pack_batch(msgs))  # a cycle's frames (the hot paths)
            return
        msgs = list(msgs)
        ts = time.time() if self.stamp else None
        for i in range(0, len(msgs), MAX_BATCH):
            part = msgs[i:i + MAX_BATCH]
            self._publish(pack_message(part[0], ts) if len(part) == 1
                          else pack_batch(part, ts))

    def _publish(self, payload: bytes) -> None:
        if self._is_shutdown:
            raise can.CanOperationError("ZenohBus is shut down")
        if self._pub is None:
            raise can.CanOperationError(f"ZenohBus {self.channel!r} is a monitor: no send")
        try:
            self._pub.put(payload)
        except Exception as e:
            raise can.CanOperationError(f"ZenohBus send failed: {e}") from e
        if self.receive_own_messages and self._rx is not None:
            own, _ = unpack_payload(payload, self.channel)
            for m in own:
                m.is_rx = False
            self._own.extend(own)
            if own:
                self._rx.wake()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._is_shutdown or self._rx is None:
            raise can.CanOperationError("ZenohBus is shut down")
        if self._own:
            return self._own.popleft(), False
        if self._pending:
            return self._pending.popleft(), False
        try:
            sample = self._rx.recv(timeout)
        except zenoh.ZError as e:
            raise can.CanOperationError(f"ZenohBus {self.channel!r} closed: {e}") from e
        if sample is None:
            return (self._own.popleft() if self._own else None), False
        frames, bad = unpack_payload(sample.payload.to_bytes(), self.channel)
        self.rx_malformed += bad
        if not frames:
            return None, False
        self._pending.extend(frames[1:])
        return frames[0], False

    def recv_frames(self, timeout: float | None = None) -> list[can.Message | Frame]:
        """All frames of the next sample at once, waiting up to ``timeout`` s (None: no
        limit) as ``recv`` does; [] when none came. Frames a ``recv`` left queued, and own
        messages, come first; classic frames as light :class:`~bus_schemas.codec.Frame` s
        (:func:`unpack_frames`), the batch's order kept; the bus's ``can_filters`` apply.
        The hot-path form of ``recv`` for a node that handles a cycle's frames together."""
        if self._is_shutdown or self._rx is None:
            raise can.CanOperationError("ZenohBus is shut down")
        deadline = None if timeout is None else time.monotonic() + timeout
        left = timeout
        while True:
            out: list[can.Message | Frame] = []
            if not (self._own or self._pending):
                try:
                    sample = self._rx.recv(left)
                except zenoh.ZError as e:
                    raise can.CanOperationError(
                        f"ZenohBus {self.channel!r} closed: {e}") from e
                if sample is not None:
                    out, bad = unpack_frames(sample.payload.to_bytes(), self.channel)
                    self.rx_malformed += bad
            if self._own or self._pending:
                out = [*self._own, *self._pending, *out]
                self._own.clear()
                self._pending.clear()
            if self._filters:
                out = [m for m in out if self._matches_filters(m)]  # type: ignore[arg-type]
            if out:
                return out
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return []

    def poll_frames(self) -> list[can.Message | Frame]:
        """:meth:`recv_frames` without waiting: the frames of a sample already received
        (frames a ``recv`` left queued, and own messages, first), [] when there is none.
        Cheap enough to ask between two pieces of other work (the co-simulation asks it
        between two MCAP records while it waits for the controller's reply)."""
        if self._is_shutdown or self._rx is None:
            raise can.CanOperationError("ZenohBus is shut down")
        if self._own or self._pending:
            return self.recv_frames(0.0)
        try:
            sample = self._rx.try_recv()
        except zenoh.ZError as e:
            raise can.CanOperationError(f"ZenohBus {self.channel!r} closed: {e}") from e
        if sample is None:
            return []
        out, bad = unpack_frames(sample.payload.to_bytes(), self.channel)
        self.rx_malformed += bad
        if self._filters:
            out = [m for m in out if self._matches_filters(m)]  # type: ignore[arg-type]
        return out

    def wait_for_peer(self, timeout: float = 5.0, *, alive: bool = True) -> bool:
        """Wait until a subscriber matches what this bus sends and, if ``alive``, the other
        node's liveliness token is visible (True), or ``timeout`` s pass (False). A
        monitor bus returns True at once."""
        if self._pub is None:
            return True
        deadline = time.monotonic() + timeout
        while not publisher_matched(self._pub):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.002)
        while alive and self.peer_node is not None:
            left = deadline - time.monotonic()
            if self.peer_alive(self.peer_node, timeout=max(0.05, min(left, 0.5))):
                break
            if left <= 0:
                return False
            time.sleep(0.005)
        return True

    def watch_peer(self, callback: Callable[[bool], None] | None = None) -> PeerWatch:
        """Watch the other node's liveliness token (:class:`PeerWatch`; its current state
        first); a monitor bus has no peer (ValueError)."""
        if self.peer_node is None:
            raise ValueError(f"ZenohBus {self.channel!r}: a monitor has no peer to watch")
        return PeerWatch(self._session, keys.alive_key(self.run_id, self.peer_node), callback)

    def announce_alive(self) -> None:
        """Declare this node's liveliness token now (for a bus opened with
        ``declare_alive=False``: a node that first has to get ready); idempotent."""
        if self._token is None and self.node is not None:
            self._token = self._session.liveliness().declare_token(
                keys.alive_key(self.run_id, self.node))

    def peer_alive(self, node: str, timeout: float = 1.0) -> bool:
        """True if the liveliness token of ``node`` (``ctrl``/``plant``) of this run exists
        now (a liveliness query answered within ``timeout`` s)."""
        replies = self._session.liveliness().get(keys.alive_key(self.run_id, node),
                                                 timeout=timeout)
        return any(r.ok is not None for r in replies)

    def _close(self) -> None:
        if self._rx is not None:
            self._rx.close()  # a recv blocked in another thread raises CanOperationError
        for obj in (self._token, self._pub):
            if obj is not None:
                with contextlib.suppress(Exception):
                    obj.undeclare()
        if self._owns_session and getattr(self, "_session", None) is not None:
            with contextlib.suppress(Exception):
                self._session.close()

    def shutdown(self) -> None:
        """Undeclare, close the session if this bus opened it, stop the reader threads."""
        if self._is_shutdown:
            return
        super().shutdown()
        self._close()

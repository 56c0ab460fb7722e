"""A python-can interface that carries CAN frames between processes over zenoh.

Registered as the ``zenoh`` interface through the ``can.interface`` entry point, so
``can.Bus(interface="zenoh", channel="run42/ctrl", connect="tcp/127.0.0.1:7447")`` works
once the project is installed (``ZenohBus(...)`` directly works without installing).

``channel`` is ``<run_id>/<role>``: role ``plant`` sends on ``.../can/tx`` and receives
``.../can/rx``; ``ctrl`` the reverse; ``monitor`` receives both and cannot send. The
explicit pair forms ``<run_id>/tx:rx`` (= plant) and ``<run_id>/rx:tx`` (= ctrl) are
accepted too. Plant and controller buses also declare the liveliness token
``hpcosim/run/<run_id>/<plant|ctrl>/alive`` (see :mod:`bus_schemas.transport.keys`).

Frames travel in the wire form of :mod:`bus_schemas.transport.wire` (a 15-byte header
plus the data bytes); the received message keeps the sender's ``timestamp`` as it was
(seconds), so a lockstep plant can stamp frames with simulation time; ``stamp=True`` makes
the bus stamp wall time (``time.time()``) at send instead. :meth:`ZenohBus.send_batch`
sends the frames of one control cycle as one zenoh sample (a *frame batch*, like a CAN
driver's bulk transfer: each frame still individually encoded, counted and checked; the
receiver's ``recv`` returns them one by one, in order). Plain ``send`` sends one frame in
the single-frame form.

Reception happens in the caller's thread, one hop from zenoh's network thread: ``recv``
blocks in the subscriber's ring channel (no Python callback, no reader thread; a waker
thread implements timeouts: :class:`~bus_schemas.transport.receiver.Receiver`). When the
ring channel (``rx_queue_size`` frames) is full, the oldest frames are dropped, as an
overrun CAN receive buffer would; the protocol's rolling counters
(:class:`bus_schemas.transport.codec.FrameChecker`) reveal such losses. The bus has
liveliness (:class:`~bus_schemas.transport.liveliness.Liveliness`).
"""

from __future__ import annotations

import contextlib
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import can
import zenoh

from bus_schemas.transport import keys
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.keys import Direction
from bus_schemas.transport.receiver import PeerWatch, Receiver
from bus_schemas.transport.wire import (
    MAX_BATCH,
    pack_batch,
    pack_message,
    unpack_frames,
    unpack_payload,
)
from bus_schemas.transport.zenoh_config import ZenohMode, make_config

ROLES: dict[str, tuple[Direction | None, tuple[Direction, ...]]] = {
    "plant": (Direction.TX, (Direction.RX,)),
    "ctrl": (Direction.RX, (Direction.TX,)),
    "monitor": (None, (Direction.TX, Direction.RX)),
}


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
        :func:`bus_schemas.transport.zenoh_config.make_config`).
    :param poll_us: before a ``recv`` blocks, poll for up to this many microseconds,
        yielding the CPU between polls (default 0: block at once).
    """

    # PLR0913: python-can's interface: can.Bus(interface="zenoh", **config) passes each
    # option of a bus config as one keyword argument
    def __init__(self, channel: str, can_filters: Any = None, *,  # noqa: PLR0913
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
        self._rx: Receiver | None = None
        self._token: zenoh.LivelinessToken | None = None
        # the session given, or the config of the one to open (in the try below)
        source: zenoh.Session | zenoh.Config = session if session is not None else make_config(
            listen=listen, connect=connect, mode=mode, allow_remote=allow_remote,
            low_latency=low_latency, options=zenoh_options)
        self.node = None if send is None else "plant" if send is Direction.TX else "ctrl"
        self.peer_node = {"plant": "ctrl", "ctrl": "plant"}.get(self.node or "")
        try:
            self._session = zenoh.open(source) if isinstance(source, zenoh.Config) else source
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
            self._rx = Receiver(self._session, sub_key, frozenset(self.recv_keys),
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
        """Publish the frames of one cycle as one zenoh sample
        (:func:`~bus_schemas.transport.wire.pack_batch`; more than 255 frames go as several,
        a single frame in the single-frame form). The receiver's ``recv`` returns them one
        by one in this order. Nothing for none."""
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
        messages, come first; classic frames as light
        :class:`~bus_schemas.transport.frame.Frame` s
        (:func:`~bus_schemas.transport.wire.unpack_frames`), the batch's order kept; the
        bus's ``can_filters`` apply. The hot-path form of ``recv`` for a node that handles
        a cycle's frames together."""
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
            if self._filters:  # a Frame has the id fields python-can's filter reads
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
        if self._filters:  # as in recv_frames: a Frame has the fields the filter reads
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
        """Watch the other node's liveliness token
        (:class:`~bus_schemas.transport.receiver.PeerWatch`; its current state first); a
        monitor bus has no peer (ValueError)."""
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

"""Which CAN bus a node talks to: configuration, not code (DESIGN: python-can style).

A :class:`BusConfig` names a python-can interface and its arguments:

- ``zenoh`` (default): CAN over zenoh, ``run_id`` + ``listen``/``connect`` endpoints
  (loopback only unless ``allow_remote``); built as
  :class:`bus_schemas.transport.zenoh_can.ZenohBus` directly (no entry point needed);
- ``virtual``: python-can's in-process virtual bus (``channel``);
- anything else python-can knows (``socketcan`` with ``channel = "can0"`` for hardware in
  the loop, ``pcan``, ...), built with ``can.Bus(interface=..., channel=..., **options)``.

Files: TOML or JSON with the same keys, e.g.::

    interface = "zenoh"
    run_id = "run42"
    connect = ["tcp/127.0.0.1:7447"]
"""

from __future__ import annotations

import json
import tomllib
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import can

from bus_schemas.transport.frame import Frame

ROLES = ("plant", "ctrl", "monitor")
ZENOH = "zenoh"  # the interface of CAN over zenoh (ZenohBus)


class BusConfigError(ValueError):
    """A bus config that cannot be read or opened (the message names the file or field)."""


@dataclass(frozen=True)
class BusConfig:
    interface: str = ZENOH
    run_id: str = "cosim"
    channel: str | None = None  # non-zenoh interfaces; zenoh: derived from run_id + role
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    allow_remote: bool = False
    options: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["listen"], d["connect"] = list(self.listen), list(self.connect)
        return d

    @property
    def authenticates(self) -> bool:
        """Its sessions can be opened with a run's credentials
        (:mod:`bus_schemas.transport.run_auth`): CAN over zenoh. A physical CAN bus cannot
        (access to the bus is what protects the prosthesis)."""
        return self.interface == ZENOH

    def with_zenoh_options(self, **options: Any) -> BusConfig:
        """This config with zenoh bus options (``low_latency``, ``poll_us``,
        ``zenoh_options``, ...: :class:`~bus_schemas.transport.zenoh_can.ZenohBus`'s
        keywords) over its own, ``zenoh_options`` merged key by key; the same config for
        another interface, which takes none of them."""
        if self.interface != ZENOH:
            return self
        merged = {**self.options, **options}
        if "zenoh_options" in options:
            merged["zenoh_options"] = {**self.options.get("zenoh_options", {}),
                                       **options["zenoh_options"]}
        return replace(self, options=merged)


def bus_config_from_dict(d: dict[str, Any], src: str = "bus config") -> BusConfig:
    known = {"interface", "run_id", "channel", "listen", "connect", "allow_remote", "options"}
    extra = set(d) - known
    if extra:
        raise BusConfigError(f"{src}: unknown keys {sorted(extra)} (known: {sorted(known)})")

    def eps(v: Any) -> tuple[str, ...]:
        if v is None:
            return ()
        if isinstance(v, str):
            return tuple(x.strip() for x in v.split(",") if x.strip())
        return tuple(str(x) for x in v)

    return BusConfig(interface=str(d.get("interface", ZENOH)),
                     run_id=str(d.get("run_id", "cosim")),
                     channel=None if d.get("channel") is None else str(d["channel"]),
                     listen=eps(d.get("listen")), connect=eps(d.get("connect")),
                     allow_remote=bool(d.get("allow_remote", False)),
                     options=dict(d.get("options", {})))


def load_bus_config(path: str | Path) -> BusConfig:
    """Read a TOML (``.toml``) or JSON bus config file."""
    p = Path(path)
    try:
        text = p.read_text()
        d = tomllib.loads(text) if p.suffix == ".toml" else json.loads(text)
    except FileNotFoundError:
        raise
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, ValueError) as e:
        raise BusConfigError(f"{p}: {e}") from None
    if not isinstance(d, dict):
        raise BusConfigError(f"{p}: expected a table/object")
    return bus_config_from_dict(d, str(p))


def make_bus(cfg: BusConfig, role: str, *, declare_alive: bool = True,
             **extra: Any) -> can.BusABC:
    """Open the bus of ``cfg`` for ``role`` (plant / ctrl / monitor); ``extra``: further
    keyword arguments of the interface, over ``cfg.options``.

    ``declare_alive``: a bus with liveliness
    (:class:`~bus_schemas.transport.liveliness.Liveliness`, CAN over zenoh) says this node
    is alive at once; False leaves it to the node (``announce_alive()`` once it is ready).
    A bus without liveliness ignores it."""
    if role not in ROLES:
        raise ValueError(f"role {role!r}: expected one of {ROLES}")
    try:
        return _open_bus(cfg, role, declare_alive, extra)
    except can.CanError as e:
        raise BusConfigError(f"bus (interface {cfg.interface!r}, channel "
                             f"{cfg.channel or cfg.run_id!r}): {e}") from None


def _open_bus(cfg: BusConfig, role: str, declare_alive: bool, extra: dict[str, Any]
              ) -> can.BusABC:
    kw = {**cfg.options, **extra}
    if cfg.interface == ZENOH:
        from bus_schemas.transport.zenoh_can import ZenohBus

        kw["declare_alive"] = declare_alive
        return ZenohBus(f"{cfg.run_id}/{role}", listen=list(cfg.listen) or None,
                        connect=list(cfg.connect) or None, allow_remote=cfg.allow_remote,
                        **kw)
    return can.Bus(interface=cfg.interface, channel=cfg.channel or cfg.run_id, **kw)


def send_frames(bus: can.BusABC, msgs: Sequence[can.Message | Frame]) -> None:
    """Send the frames of one control cycle, in order: as one bulk transfer where the bus
    has ``send_batch`` (:class:`bus_schemas.transport.zenoh_can.ZenohBus`), else frame by frame
    (any python-can bus)."""
    if not msgs:
        return
    batch = getattr(bus, "send_batch", None)
    if batch is not None:
        batch(msgs)
    else:
        for m in msgs:
            bus.send(m.to_message() if isinstance(m, Frame) else m)


class FrameReader:
    """Receive frames one at a time from ``bus``, a cycle's frames taken together where
    the bus can (``recv_frames`` of :class:`bus_schemas.transport.zenoh_can.ZenohBus`: one call per
    sample, light frames), else frame by frame through python-can's ``recv``. The
    counterpart of :func:`send_frames`."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self._many = getattr(bus, "recv_frames", None)
        self._poll = getattr(bus, "poll_frames", None)
        self._queue: deque[Any] = deque()

    def recv(self, timeout: float | None = None) -> Any:
        """The next frame (a ``can.Message`` or a :class:`bus_schemas.transport.codec.Frame`), or
        None when none came within ``timeout`` s."""
        q = self._queue
        if q:
            return q.popleft()
        if self._many is None:
            return self.bus.recv(timeout)
        got = self._many(timeout)
        if not got:
            return None
        q.extend(got)
        return q.popleft()

    def recv_all(self, timeout: float | None = None) -> list[Any]:
        """The frames already taken and not yet returned, else those of the next sample
        (one frame from a bus without ``recv_frames``); [] when none came within
        ``timeout`` s. A cycle's frames in one call, for a caller that handles them
        together."""
        q = self._queue
        if q:
            out = list(q)
            q.clear()
            return out
        if self._many is None:
            m = self.bus.recv(timeout)
            return [] if m is None else [m]
        return self._many(timeout)

    def ready(self) -> bool:
        """True when a frame is here to be received without waiting (taken from the bus
        where it can tell, ``poll_frames``; a bus without it answers False: nothing
        interrupts the caller's other work)."""
        if self._queue:
            return True
        if self._poll is None:
            return False
        got = self._poll()
        if not got:
            return False
        self._queue.extend(got)
        return True

    def unread(self, frames: Sequence[Any]) -> None:
        """Put ``frames`` back (in this order) before anything else the next receive
        returns: the rest of a sample a caller did not need yet."""
        self._queue.extendleft(reversed(frames))

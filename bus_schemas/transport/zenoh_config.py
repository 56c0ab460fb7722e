"""Zenoh session configuration: loopback-only unless remote endpoints are allowed explicitly.

zenoh 1.x defaults listen on every interface (``tcp/[::]:0``) and scout over multicast
224.0.0.224:7446. :func:`make_config` always turns multicast and gossip scouting off and
sets the listen and connect endpoint lists explicitly (an empty list listens nowhere);
endpoints must be loopback (``127.0.0.0/8``, ``[::1]``, ``localhost``, or a unix socket)
unless ``allow_remote=True``. Typical wiring on one machine: the plant listens on
``tcp/127.0.0.1:<port>``, the controller connects to it, both in ``peer`` mode.
"""

from __future__ import annotations

import ipaddress
import json
import socket
from collections.abc import Iterable, Mapping
from enum import StrEnum
from typing import Any

import zenoh


class ZenohMode(StrEnum):
    """A zenoh session's role (:func:`make_config`); the value is zenoh's own word.  (A plain
    StrEnum: the bus stays free of the model package.)"""

    PEER = "peer"
    CLIENT = "client"  # needs connect endpoints, cannot listen

_LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe")
_GUARDED_KEYS = ("listen", "connect", "scouting", "mode")


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free on ``host`` a moment ago (bind to port 0, then release)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def loopback_endpoint(port: int | None = None, protocol: str = "tcp") -> str:
    """``tcp/127.0.0.1:<port>`` (a free port when ``port`` is None)."""
    return f"{protocol}/127.0.0.1:{free_tcp_port() if port is None else int(port)}"


def _host(endpoint: str) -> tuple[str, str]:
    """``(protocol, host)`` of a zenoh locator ``proto/host:port[?meta][#config]``."""
    proto, sep, rest = endpoint.partition("/")
    if not sep or not proto or not rest:
        raise ValueError(f"zenoh endpoint {endpoint!r}: expected <protocol>/<address>")
    addr = rest.split("#", 1)[0].split("?", 1)[0]
    if proto in _LOCAL_PROTOCOLS:
        return proto, addr
    host, colon, port = addr.rpartition(":")
    if not colon or not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"zenoh endpoint {endpoint!r}: expected <protocol>/<host>:<port> "
                         "(port 0-65535)")
    return proto, host.strip("[]")


def is_loopback_endpoint(endpoint: str) -> bool:
    """True if ``endpoint`` only reaches this machine (loopback address or local socket)."""
    proto, host = _host(endpoint)
    if proto in _LOCAL_PROTOCOLS or host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _endpoints(value: str | Iterable[str] | None, what: str, allow_remote: bool) -> list[str]:
    if value is None:
        return []
    items = [v.strip() for v in value.split(",")] if isinstance(value, str) else list(value)
    items = [str(v) for v in items if v]
    for ep in items:
        if not is_loopback_endpoint(ep) and not allow_remote:
            raise ValueError(f"zenoh {what} endpoint {ep!r} is not loopback; pass "
                             "allow_remote=True to use it")
    return items


def guarded_option(key: str) -> bool:
    """A zenoh config key that may open a session beyond loopback (listen, connect,
    scouting, mode): :func:`make_config` sets it only with ``allow_remote=True``."""
    return key.split("/", 1)[0] in _GUARDED_KEYS


#: zenoh's low-latency unicast transport: a sender writes to the link from its own thread
#: (no transmission pipeline and batching task), no QoS priorities; used only when both
#: peers set it (otherwise they agree on the normal transport)
LOW_LATENCY = {"transport/unicast/lowlatency": True, "transport/unicast/qos/enabled": False}


def make_config(*, listen: str | Iterable[str] | None = None,
                connect: str | Iterable[str] | None = None,
                mode: ZenohMode | str = ZenohMode.PEER,
                allow_remote: bool = False, low_latency: bool = False,
                options: Mapping[str, Any] | None = None) -> zenoh.Config:
    """A zenoh config with scouting off and explicit endpoints.

    ``listen``/``connect``: endpoints (a list, or one comma-separated string); empty means
    none (a session without endpoints still delivers within its own process).
    ``mode``: ``peer`` (default) or ``client`` (needs ``connect``, cannot listen).
    ``low_latency``: zenoh's low-latency transport (:data:`LOW_LATENCY`; used between two
    peers that both set it).
    ``options``: further ``{key: value}`` settings inserted last with ``insert_json5``;
    keys under listen, connect, scouting and mode need ``allow_remote=True``.
    """
    try:
        mode = ZenohMode(mode)
    except ValueError:
        raise ValueError(f"zenoh mode {mode!r}: expected one of {', '.join(ZenohMode)}"
                         ) from None
    lst = _endpoints(listen, "listen", allow_remote)
    con = _endpoints(connect, "connect", allow_remote)
    if mode == ZenohMode.CLIENT and (lst or not con):
        raise ValueError("zenoh client mode needs connect endpoints and no listen endpoints")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("scouting/gossip/enabled", "false")
    cfg.insert_json5("listen/endpoints", json.dumps(lst))
    cfg.insert_json5("connect/endpoints", json.dumps(con))
    for key, value in {**(LOW_LATENCY if low_latency else {}), **(options or {})}.items():
        if guarded_option(key) and not allow_remote:
            raise ValueError(f"zenoh option {key!r} may open the session beyond loopback; "
                             "pass allow_remote=True to set it")
        cfg.insert_json5(key, json.dumps(value))
    return cfg


def open_session(**kwargs: Any) -> zenoh.Session:
    """``zenoh.open(make_config(**kwargs))``. Close the session explicitly when done."""
    return zenoh.open(make_config(**kwargs))

"""Which CAN bus a node talks to: configuration, not code (DESIGN: python-can style).

A :class:`BusConfig` names a python-can interface and its arguments:

- ``zenoh`` (default): CAN over zenoh, ``run_id`` + ``listen``/``connect`` endpoints
  (loopback only unless ``allow_remote``), ``key_file``: the file of a shared secret both
  ends authenticate with (:func:`read_key`); built as
  :class:`bus_schemas.transport.zenoh_can.ZenohBus` directly (no entry point needed);
- ``virtual``: python-can's in-process virtual bus (``channel``);
- anything else python-can knows (``socketcan`` with ``channel = "can0"`` for hardware in
  the loop, ``pcan``, ...), built with ``can.Bus(interface=..., channel=..., **options)``;
  the interfaces that reach other machines over IP (:data:`NETWORK_INTERFACES`) need
  ``allow_remote = true`` as a zenoh endpoint beyond loopback does.

Files: TOML or JSON with the same keys, e.g.::

    interface = "zenoh"
    run_id = "run42"
    connect = ["tcp/127.0.0.1:7447"]
    key_file = "lab.key"          # relative to the config file's folder

Every field is strictly typed (:func:`bus_config_from_dict`): a string is not a boolean, a
number not a string; a field another interface has no use for is refused, not ignored;
each error is one line naming the file (or the command-line option) and the field.
"""

from __future__ import annotations

import json
import math
import os
import stat
import tomllib
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import can

from bus_schemas.transport.frame import Frame

ROLES = ("plant", "ctrl", "monitor")
ZENOH = "zenoh"  # the interface of CAN over zenoh (ZenohBus)
#: python-can interfaces that carry frames over IP to other machines: like a zenoh
#: endpoint beyond loopback, they need ``allow_remote = true``
NETWORK_INTERFACES = frozenset({"udp_multicast", "socketcand"})
#: fields only CAN over zenoh uses (``allow_remote`` also admits a network interface)
ZENOH_FIELDS = ("listen", "connect", "key_file")
#: the ZenohBus keywords a bus config's ``options`` may set, with their types
ZENOH_OPTIONS: dict[str, str] = {"mode": "str", "zenoh_options": "table",
                                 "receive_own_messages": "bool", "rx_queue_size": "count",
                                 "stamp": "bool", "low_latency": "bool", "poll_us": "number"}
#: a key file's secret: at least this many characters
KEY_MIN_CHARS = 16
_KEY_MAX_BYTES = 4096
_USRPWD = "transport/auth/usrpwd/password"  # zenoh's user/password authentication


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
    key_file: str | None = None  # zenoh: the shared secret's file (read_key)
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

    @property
    def authenticated(self) -> bool:
        """CAN over zenoh with a key: a key file, or zenoh's user/password authentication
        set in its zenoh options (a run's secret, :mod:`~bus_schemas.transport.run_auth`)."""
        return self.authenticates and (self.key_file is not None or _USRPWD in
                                       self.options.get("zenoh_options", {}))

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


# -- strict fields ------------------------------------------------------------------------------
_KNOWN = tuple(f.name for f in fields(BusConfig))


def _kind(v: Any) -> str:
    """What a TOML/JSON value is, in words."""
    for t, word in ((bool, "a boolean"), (int, "an integer"), (float, "a number"),
                    (str, "a string"), (list, "a list"), (tuple, "a list"),
                    (dict, "a table")):
        if isinstance(v, t):
            return word
    return "null" if v is None else type(v).__name__


class _Fields:
    """One-line errors naming where a field came from: ``SRC: field = value`` (a file) or
    ``--option value`` (``names``: the fields the command line set)."""

    def __init__(self, src: str, names: Mapping[str, str] | None = None) -> None:
        self.src, self.names = src, dict(names or {})

    def error(self, f: str, v: Any, problem: str) -> BusConfigError:
        field_ = f.replace(" ", ".").split(".", 1)[0]  # "listen endpoint", "options.mode"
        opt = self.names.get(field_)
        head = (f"{opt} {v!r}" if opt else
                f"{self.src}: {f} {v!r}" if " " in f else f"{self.src}: {f} = {v!r}")
        return BusConfigError(f"{head}: {problem}")

    def string(self, f: str, v: Any, *, empty: bool = False) -> str:
        if not isinstance(v, str):
            raise self.error(f, v, f"expected a string, not {_kind(v)}")
        if not empty and not v.strip():
            raise self.error(f, v, "expected a non-empty string")
        return v

    def boolean(self, f: str, v: Any) -> bool:
        if not isinstance(v, bool):
            raise self.error(f, v, f"expected true or false, not {_kind(v)}")
        return v

    def table(self, f: str, v: Any) -> dict[str, Any]:
        if not isinstance(v, dict) or not all(isinstance(k, str) for k in v):
            raise self.error(f, v, f"expected a table (keys: strings), not {_kind(v)}")
        return dict(v)

    def endpoints(self, f: str, v: Any) -> tuple[str, ...]:
        """A list of strings, or one comma-separated string."""
        if isinstance(v, str):
            return tuple(x.strip() for x in v.split(",") if x.strip())
        if not isinstance(v, list | tuple) or not all(isinstance(x, str) for x in v):
            raise self.error(f, v, f"expected a list of endpoint strings, not {_kind(v)}")
        return tuple(x.strip() for x in v if x.strip())

    def option(self, f: str, v: Any, kind: str) -> Any:
        """A ZenohBus keyword's value of ``kind`` (:data:`ZENOH_OPTIONS`)."""
        if kind == "bool":
            return self.boolean(f, v)
        if kind == "str":
            return self.string(f, v)
        if kind == "table":
            return self.table(f, v)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                or v < 0 or (kind == "count" and (not isinstance(v, int) or v < 1)):
            what = "a whole number >= 1" if kind == "count" else "a finite number >= 0"
            raise self.error(f, v, f"expected {what}, not {_kind(v)}")
        return v


def bus_config_from_dict(d: Mapping[str, Any], src: str = "bus config", *,
                         names: Mapping[str, str] | None = None,
                         base: Path | None = None) -> BusConfig:
    """The config of a TOML/JSON table ``d``, every field checked (module docstring);
    ``src`` names the table in errors (its file), ``names`` the command-line options that
    set fields (``{"listen": "--listen"}``), ``base`` the folder a relative ``key_file`` is
    relative to (the config file's)."""
    fx = _Fields(src, names)
    extra = set(d) - set(_KNOWN)
    if extra:
        raise BusConfigError(f"{src}: unknown keys {sorted(extra)} (known: {sorted(_KNOWN)})")
    v: dict[str, Any] = {}
    for f in ("interface", "run_id"):
        if f in d:
            v[f] = fx.string(f, d[f])
    for f in ("channel", "key_file"):
        if d.get(f) is not None:  # JSON null: not set
            v[f] = fx.string(f, d[f])
    for f in ("listen", "connect"):
        if d.get(f) is not None:
            v[f] = fx.endpoints(f, d[f])
    if "allow_remote" in d:
        v["allow_remote"] = fx.boolean("allow_remote", d["allow_remote"])
    if "options" in d:
        v["options"] = fx.table("options", d["options"])
    if "key_file" in v and base is not None and "key_file" not in fx.names:
        v["key_file"] = str(base / v["key_file"])
    cfg = BusConfig(**v)
    _check(cfg, fx)
    return cfg


def _check(cfg: BusConfig, fx: _Fields) -> None:
    """What one field means for another: the interface's fields, the run id, endpoints
    beyond this machine (module docstring)."""
    known = can.interfaces.VALID_INTERFACES | {ZENOH}
    if cfg.interface not in known:
        raise fx.error("interface", cfg.interface,
                       f"unknown; expected one of {', '.join(sorted(known))}")
    if cfg.interface == ZENOH:
        _check_zenoh(cfg, fx)
        return
    for f in ZENOH_FIELDS:
        if getattr(cfg, f):
            raise fx.error(f, getattr(cfg, f), f"only for the zenoh interface, not "
                           f"{cfg.interface!r}")
    remote = cfg.interface in NETWORK_INTERFACES
    if remote and not cfg.allow_remote:
        raise fx.error("interface", cfg.interface, "reaches other machines over IP; set "
                       "allow_remote = true in the bus config to use it")
    if cfg.allow_remote and not remote:
        raise fx.error("allow_remote", True, f"not for the {cfg.interface!r} interface (only "
                       f"zenoh and {', '.join(sorted(NETWORK_INTERFACES))})")
    clash = set(cfg.options) & set(_KNOWN)
    if clash:
        raise fx.error("options", cfg.options, f"{sorted(clash)} are fields of the bus "
                       "config, not options")


def _check_zenoh(cfg: BusConfig, fx: _Fields) -> None:
    from bus_schemas.transport import keys
    from bus_schemas.transport.zenoh_config import ZenohMode, guarded_option, is_loopback_endpoint

    try:
        keys.validate_run_id(cfg.run_id)
    except ValueError:
        raise fx.error("run_id", cfg.run_id, "use 1-128 characters of [A-Za-z0-9_.-]"
                       ) from None
    if cfg.channel is not None:
        raise fx.error("channel", cfg.channel, "not for the zenoh interface (its channel is "
                       "<run_id>/<role>); set run_id")
    for f in ("listen", "connect"):
        for ep in getattr(cfg, f):
            try:
                local = is_loopback_endpoint(ep)
            except ValueError as e:
                raise fx.error(f"{f} endpoint", ep, str(e).split(": ", 1)[-1]) from None
            if not local and not cfg.allow_remote:
                raise fx.error(f"{f} endpoint", ep, "not a loopback endpoint; set "
                               "allow_remote = true in the bus config to listen or connect "
                               "beyond this machine")
    for k, val in cfg.options.items():
        if k not in ZENOH_OPTIONS:
            raise fx.error(f"options.{k}", val, "not an option of the zenoh interface "
                           f"(options: {', '.join(ZENOH_OPTIONS)})")
        fx.option(f"options.{k}", val, ZENOH_OPTIONS[k])
    if "mode" in cfg.options and cfg.options["mode"] not in tuple(ZenohMode):
        raise fx.error("options.mode", cfg.options["mode"],
                       f"expected one of {', '.join(ZenohMode)}")
    for k in cfg.options.get("zenoh_options", {}):
        if guarded_option(k) and not cfg.allow_remote:
            raise fx.error(f"options.zenoh_options.{k}", cfg.options["zenoh_options"][k],
                           "may open the session beyond loopback; set allow_remote = true")


def check_bus_config(cfg: BusConfig, src: str = "bus config") -> BusConfig:
    """``cfg`` if every field holds (:func:`bus_config_from_dict`'s checks), else
    :class:`BusConfigError`: for a config built in code."""
    return bus_config_from_dict(cfg.to_dict(), src)


def load_bus_config(path: str | Path) -> BusConfig:
    """Read a TOML (``.toml``) or JSON bus config file (a relative ``key_file`` is relative
    to its folder)."""
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
    return bus_config_from_dict(d, str(p), base=p.parent)


def read_key(path: str | Path) -> str:
    """The shared secret of the key file ``path``: one line of at least
    :data:`KEY_MIN_CHARS` characters, no ``:`` or white space, in a regular file owned by
    this user (or root) that nobody else may read or write (mode 0600 or 0400).
    :class:`BusConfigError` naming the file otherwise."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | os.O_CLOEXEC)
    except OSError as e:
        raise BusConfigError(f"key file {p}: {e.strerror or e}") from None
    try:
        st = os.fstat(fd)  # the file opened, not whatever the name holds later
        if not stat.S_ISREG(st.st_mode):
            raise BusConfigError(f"key file {p}: not a regular file")
        if st.st_uid not in (os.geteuid(), 0):
            raise BusConfigError(f"key file {p}: owned by uid {st.st_uid}, not by this user "
                                 f"(uid {os.geteuid()}) or root")
        if st.st_mode & 0o077:
            raise BusConfigError(f"key file {p}: mode {stat.S_IMODE(st.st_mode):04o} lets "
                                 f"others read or change it; chmod 600 {p}")
        data = os.read(fd, _KEY_MAX_BYTES + 1)
    finally:
        os.close(fd)
    return _secret(p, data)


def _secret(p: Path, data: bytes) -> str:
    """The one line of a key file's bytes ``data``, checked (:func:`read_key`)."""
    if len(data) > _KEY_MAX_BYTES:
        raise BusConfigError(f"key file {p}: over {_KEY_MAX_BYTES} bytes; expected one line")
    try:
        lines = [x.strip() for x in data.decode().splitlines() if x.strip()]
    except UnicodeDecodeError:
        raise BusConfigError(f"key file {p}: not text (UTF-8)") from None
    if len(lines) != 1:
        raise BusConfigError(f"key file {p}: expected one line (the secret), found "
                             f"{len(lines)}")
    key = lines[0]
    if len(key) < KEY_MIN_CHARS or any(c in key for c in ": \t"):
        raise BusConfigError(
            f"key file {p}: the secret must be at least {KEY_MIN_CHARS} characters without "
            "':' or spaces (e.g. python -c 'import secrets; print(secrets.token_urlsafe(32))')")
    return key


def make_bus(cfg: BusConfig, role: str, *, declare_alive: bool = True,
             **extra: Any) -> can.BusABC:
    """Open the bus of ``cfg`` for ``role`` (plant / ctrl / monitor); ``extra``: further
    keyword arguments of the interface, over ``cfg.options``. ``cfg`` is checked first
    (:func:`check_bus_config`); with a ``key_file`` the zenoh session authenticates with
    its secret (a peer without it is refused at the transport).

    ``declare_alive``: a bus with liveliness
    (:class:`~bus_schemas.transport.liveliness.Liveliness`, CAN over zenoh) says this node
    is alive at once; False leaves it to the node (``announce_alive()`` once it is ready).
    A bus without liveliness ignores it."""
    if role not in ROLES:
        raise ValueError(f"role {role!r}: expected one of {ROLES}")
    check_bus_config(cfg)
    try:
        if cfg.key_file is not None:
            return _keyed(cfg, role, declare_alive, extra)
        return _open_bus(cfg, role, declare_alive, extra)
    except (can.CanError, ValueError, TypeError) as e:
        if isinstance(e, BusConfigError):
            raise
        raise BusConfigError(f"bus (interface {cfg.interface!r}, channel "
                             f"{cfg.channel or cfg.run_id!r}): {e}") from None


def _keyed(cfg: BusConfig, role: str, declare_alive: bool, extra: dict[str, Any]
           ) -> can.BusABC:
    """The zenoh bus of ``cfg`` authenticated with its key file's secret (zenoh reads the
    user/password dictionary when the session opens; it is gone once the bus is open)."""
    from bus_schemas.transport.run_auth import RunCredentials

    assert cfg.key_file is not None
    with RunCredentials(read_key(cfg.key_file)) as creds:
        auth = creds.zenoh_options("ctrl" if role == "ctrl" else "plant")
        cfg = cfg.with_zenoh_options(zenoh_options=auth)
        return _open_bus(cfg, role, declare_alive, extra)


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

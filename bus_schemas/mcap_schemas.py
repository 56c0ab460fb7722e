"""MCAP channel schemas (JSON Schema, Foxglove-readable), a JSON decoder factory, and the
:class:`Recorder` that writes a co-simulation run to MCAP.

Channels (schema encoding ``jsonschema``, message encoding ``json``), see :data:`CHANNELS`:

- ``/can/tx``, ``/can/rx``: ``hpcosim.CanFrame``, frames plant -> controller and back;
- ``/prosthesis/measurements``: ``hpcosim.ProsthesisMeasurements``, decoded feedback;
- ``/prosthesis/torque_command``: ``hpcosim.TorqueCommand``, decoded torque commands;
- ``/ground_truth``: ``hpcosim.GroundTruth``, plant state and socket force;
- ``/controller/diagnostics``: ``hpcosim.ControllerDiagnostics``, tau, V, rho, QP status;
- ``/controller/clf``: ``hpcosim.ControllerClf``, the controller's CLF value V and
  relaxation rho of every period (``CtrlClf`` frames; null when absent);
- ``/can/rates``: ``hpcosim.CanRates``, frames per second of each frame name and direction
  over windows of 100 ms log time (a recorder made with ``can_rates``);
- ``/walker/reference``: ``hpcosim.WalkerReference``, the gait's desired prosthesis angles
  and the force tube at the recorded phase (every 10 ms).

Foxglove channels (schema and message encoding ``protobuf``, the messages and schemas of the
``foxglove-schemas-protobuf`` package), see :data:`FOXGLOVE_CHANNELS`:

- ``/walker/tf``: ``foxglove.FrameTransforms``, the walker's frames (every 10 ms);
- ``/walker/scene``: ``foxglove.SceneUpdate``, the walker drawn with primitives.

Units: SI (s, rad, rad/s, N, N m); ``log_time`` of every message in ns (simulation time in
lockstep runs, wall time otherwise). Non-finite floats are written as ``null`` (JSON has no
NaN). The mcap package has no JSON or protobuf decoder: pass :class:`JsonDecoderFactory`
(and :class:`ProtobufDecoderFactory` for the Foxglove channels) to
``mcap.reader.make_reader(..., decoder_factories=[...])``; :func:`read_messages` does.
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import math
import os
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from types import FrameType
from typing import Any

import can
import orjson
from mcap.decoder import DecoderFactory
from mcap.reader import make_reader
from mcap.records import Schema
from mcap.writer import CompressionType, Writer

from bus_schemas.mcap_append import append_messages, supports

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
PROTOBUF_ENCODING = "protobuf"  # schema and message encoding of the Foxglove channels
#: generalized coordinates q of the 12-DOF model (= ``hp_model.COORDS``, tested)
COORDS = ("x_B", "z_B", "th_B", "th_lh", "th_lk", "th_la", "th_rh", "x_f", "z_f", "th_f",
          "th_pk", "th_pa")


def _num(desc: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": desc}


def _int(desc: str) -> dict[str, Any]:
    return {"type": "integer", "description": desc}


def _vec(n: int, desc: str) -> dict[str, Any]:
    return {"type": "array", "items": {"type": ["number", "null"]}, "minItems": n,
            "maxItems": n, "description": desc}


def _schema(title: str, desc: str, props: dict[str, Any], required: Iterable[str]
            ) -> dict[str, Any]:
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": title,
            "description": desc, "type": "object", "properties": props,
            "required": list(required)}


CAN_FRAME = _schema("hpcosim.CanFrame", "One CAN frame as seen by the plant side.", {
    "timestamp": _num("frame timestamp as sent [s]"),
    "id": _int("arbitration id"),
    "extended": {"type": "boolean", "description": "29-bit id"},
    "dlc": _int("data length code"),
    "data": {"type": "array", "items": {"type": "integer", "minimum": 0, "maximum": 255},
             "maxItems": 64, "description": "data bytes"},
    "direction": {"enum": ["tx", "rx"], "description": "tx: plant->ctrl, rx: ctrl->plant"},
    "name": {"type": ["string", "null"], "description": "frame name in ampro3.dbc"},
    "status": {"type": ["string", "null"],
               "description": "receiver's classification (ok, bad_checksum, ...)"},
}, ["timestamp", "id", "dlc", "data", "direction"])

PROSTHESIS_MEASUREMENTS = _schema(
    "hpcosim.ProsthesisMeasurements", "What the controller senses, as decoded from CAN.", {
        "knee_angle": _num("th_pk [rad]"), "knee_velocity": _num("d th_pk / dt [rad/s]"),
        "ankle_angle": _num("th_pa [rad]"), "ankle_velocity": _num("d th_pa / dt [rad/s]"),
        "foot_load": _num("foot normal load [N]"),
        "contact": {"type": "boolean", "description": "foot in contact"},
        "socket_pitch": _num("world pitch of the prosthesis top link from the IMU [rad]; "
                             "null: no valid IMU reading"),
        "sim_time_us": _int("plant sim time [us], mod 2^32"),
        "counter": _int("rolling counter of the frames"),
    }, ["knee_angle", "knee_velocity", "ankle_angle", "ankle_velocity", "foot_load",
        "contact"])

TORQUE_COMMAND = _schema("hpcosim.TorqueCommand", "Torque command as decoded from CAN.", {
    "knee": _num("knee motor torque [N m]"), "ankle": _num("ankle motor torque [N m]"),
    "knee_joint": _num("knee joint torque = gear ratio x motor torque [N m]"),
    "ankle_joint": _num("ankle joint torque [N m]"),
    "enable": {"type": "boolean", "description": "torque enable"},
    "counter": _int("rolling counter"),
}, ["knee", "ankle", "enable"])

GROUND_TRUTH = _schema("hpcosim.GroundTruth", "Plant state; recorded, never sent to the "
                       "controller.", {
    "t": _num("simulation time [s]"),
    "socket_force": {"type": "object", "description": "socket force F_s on the prosthesis",
                     "properties": {"Fx": _num("[N]"), "Fz": _num("[N]"),
                                    "My": _num("[N m]")},
                     "required": ["Fx", "Fz", "My"]},
    "q": _vec(12, "generalized coordinates " + ", ".join(COORDS) + " [m, rad]"),
    "qd": _vec(12, "generalized velocities [m/s, rad/s]"),
    "domain": {"enum": ["ps", "pns"], "description": "prosthesis stance / non-stance"},
    "tau": _num("phase variable tau(q) [1]"),
    "step": _int("step count"),
    "fallen": {"type": "boolean", "description": "fall detected"},
}, ["t", "socket_force", "q", "qd", "domain", "tau", "step", "fallen"])

CONTROLLER_DIAGNOSTICS = _schema(
    "hpcosim.ControllerDiagnostics", "Prosthesis controller internals per control period.", {
        "t": _num("controller time [s]"),
        "controller": {"type": "string", "description": "clf_qp, relaxed, pd, ..."},
        "domain": {"enum": ["ps", "pns", None], "description": "domain the controller uses"},
        "tau": _num("phase variable [1]"),
        "V": _num("CLF value V_eps"),
        "rho": _num("CLF relaxation rho"),
        "u": _vec(2, "joint torques u_p (knee, ankle) [N m]"),
        "qp_status": {"type": "string", "description": "QpStatus name"},
        "active_constraints": {"type": "array", "items": {"type": "string"},
                               "description": "names of active QP constraints"},
        "fallback_count": _int("control periods on the fallback controller"),
        "fault_flags": _int("FaultFlag bits"),
        "solve_time_us": _num("QP solve time [us]"),
        "coverage_flag": {"type": "boolean", "description": "the model-error estimate was "
                          "outside the characterised bound on the last tick"},
        "coverage_count": _int("ticks flagged by the coverage monitor (saturating, 127)"),
    }, ["t", "tau", "V", "rho", "u", "qp_status", "active_constraints", "fallback_count",
        "fault_flags"])

CONTROLLER_DISTURBANCE = _schema(
    "hpcosim.ControllerDisturbance", "The controller's online model-error estimate "
    "(CtrlDisturbance frame): d = nu - (a + A u) of the interaction-aware CLF-QP.", {
        "t": _num("controller time of the tick [s] (the frame's timestamp)"),
        "d": _vec(2, "estimated model error (dy1 [m/s^2], d2y2 [rad/s^2]), as on the bus"),
        "tau": _num("stance phase of the tick [1]"),
        "valid": {"type": "boolean", "description": "the estimate has settled"},
        "flag": {"type": "boolean",
                 "description": "outside the characterised bound (coverage monitor)"},
        "since_touchdown": _num("time since the switch to stance [s], saturating at 0.255"),
    }, ["t", "d", "tau", "valid", "flag", "since_touchdown"])

CONTROLLER_CLF = _schema(
    "hpcosim.ControllerClf", "The controller's CLF value and relaxation of one control "
    "period as the loop received them (CtrlClf frame in a co-simulation: V step 1e-5, rho "
    "step 1e-3).", {
        "t": _num("simulation time of the period [s]"),
        "V": _num("CLF value V_eps [1], >= 0 (0 in pns); null: not received or absent"),
        "rho": _num("CLF-QP relaxation rho [1], >= 0; null: absent (a controller without a "
                    "relaxation) or not received"),
    }, ["t", "V", "rho"])

PLANT_TIMING = _schema(
    "hpcosim.PlantTiming", "A realtime plant tick begun a period or more behind its "
    "wall-clock slot (an overrun), and the slots skipped to catch up.", {
        "t": _num("simulation time of the tick [s]"),
        "tick": _int("tick index"),
        "lag": _num("wall-clock lag behind the tick's slot at its start [s]"),
        "skipped": _int("wall-clock slots skipped at this tick (lag past max_lag), 0 if none"),
    }, ["t", "tick", "lag", "skipped"])

_RATES = {"type": "object", "additionalProperties": {"type": "number"}}

CAN_RATES = _schema(
    "hpcosim.CanRates", "CAN frames per second over one window of log time, by frame name "
    "(ampro3.dbc; 0x... for an id it does not name); every name seen so far is listed.", {
        "t": _num("end of the window [s] (log time)"),
        "window": _num("window length [s]"),
        "tx": {**_RATES, "description": "plant -> controller [1/s]"},
        "rx": {**_RATES, "description": "controller -> plant [1/s]"},
    }, ["t", "window", "tx", "rx"])

_FORCE = {"type": ["object", "null"], "properties": {"Fx": _num("[N]"), "Fz": _num("[N]"),
                                                    "My": _num("[N m]")}}

WALKER_REFERENCE = _schema(
    "hpcosim.WalkerReference", "The gait's desired prosthesis joint angles and the force "
    "tube at the plant's phase tau(q) (recorded every 10 ms with /walker/tf).", {
        "t": _num("simulation time [s]"),
        "domain": {"enum": ["ps", "pns"], "description": "prosthesis stance / non-stance"},
        "tau": _num("phase variable tau(q) [1]"),
        "knee": _num("desired th_pk (the gait's Bezier output at tau clipped to [0, 1]) "
                     "[rad]"),
        "ankle": _num("desired th_pa [rad]; null in ps (the stance ankle is not an output)"),
        "socket_lower": {**_FORCE, "description": "force tube's lower bound on the socket "
                         "force F_s at tau (ps only, else null)"},
        "socket_upper": {**_FORCE, "description": "force tube's upper bound (ps only)"},
    }, ["t", "domain", "tau", "knee", "ankle", "socket_lower", "socket_upper"])

#: topic -> JSON schema
CHANNELS: dict[str, dict[str, Any]] = {
    "/can/tx": CAN_FRAME,
    "/can/rx": CAN_FRAME,
    "/prosthesis/measurements": PROSTHESIS_MEASUREMENTS,
    "/prosthesis/torque_command": TORQUE_COMMAND,
    "/ground_truth": GROUND_TRUTH,
    "/controller/diagnostics": CONTROLLER_DIAGNOSTICS,
    "/controller/disturbance": CONTROLLER_DISTURBANCE,
    "/controller/clf": CONTROLLER_CLF,
    "/cosim/timing": PLANT_TIMING,
    "/can/rates": CAN_RATES,
    "/walker/reference": WALKER_REFERENCE,
}

#: topic -> Foxglove protobuf message (``foxglove-schemas-protobuf``)
FOXGLOVE_CHANNELS: dict[str, str] = {
    "/walker/tf": "foxglove.FrameTransforms",
    "/walker/scene": "foxglove.SceneUpdate",
}


def foxglove_message_class(name: str) -> type[Any]:
    """The ``foxglove-schemas-protobuf`` class of Foxglove message ``name``
    (e.g. ``foxglove.SceneUpdate``)."""
    import importlib

    pkg, _, short = name.partition(".")
    if pkg != "foxglove" or not short.isidentifier():
        raise KeyError(f"{name!r} is not a Foxglove message name")
    return getattr(importlib.import_module(f"foxglove_schemas_protobuf.{short}_pb2"), short)


def protobuf_descriptor_set(message_class: type[Any]) -> bytes:
    """The serialized ``FileDescriptorSet`` of a protobuf message class: its file and every
    file it imports, dependencies first (what an MCAP ``protobuf`` schema record holds)."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    fds, seen = FileDescriptorSet(), set()

    def add(fd: Any) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(fds.file.add())

    add(message_class.DESCRIPTOR.file)
    return fds.SerializeToString()


def can_frame_message(msg: can.Message, direction: str, *, name: str | None = None,
                      status: str | None = None) -> dict[str, Any]:
    """The ``hpcosim.CanFrame`` record of a python-can message."""
    if direction not in ("tx", "rx"):
        raise ValueError(f"direction {direction!r}: expected 'tx' or 'rx'")
    return {"timestamp": float(msg.timestamp), "id": int(msg.arbitration_id),
            "extended": bool(msg.is_extended_id), "dlc": int(msg.dlc),
            "data": list(msg.data or b""), "direction": direction, "name": name,
            "status": None if status is None else str(status)}


def _can_record(msg: can.Message, direction: str, name: str | None, status: str | None
                ) -> dict[str, Any]:
    return can_frame_message(msg, direction, name=name, status=status)


class CanRates:
    """Counts the CAN frames written and gives the ``/can/rates`` record of each window of
    ``period`` s of log time (the first starts at the first frame)."""

    def __init__(self, period: float = 0.1) -> None:
        if not period > 0:
            raise ValueError(f"CAN rate window {period} s: must be > 0")
        self.period = period
        self._period_ns = round(period * 1e9)
        self._end: int | None = None
        self._counts: dict[str, dict[str, int]] = {"tx": {}, "rx": {}}

    def add(self, message: Mapping[str, Any], ns: int) -> list[tuple[int, dict[str, Any]]]:
        """Count one ``hpcosim.CanFrame`` record logged at ``ns``; returns (log time [ns],
        record) of every window that ended before it."""
        out = []
        if self._end is None:
            self._end = ns + self._period_ns
        while ns >= self._end:
            out.append((self._end, self._close()))
            self._end += self._period_ns
        name = message.get("name") or f"0x{int(message['id']):03X}"
        c = self._counts[message["direction"]]
        c[name] = c.get(name, 0) + 1
        return out

    def _close(self) -> dict[str, Any]:
        assert self._end is not None
        rec: dict[str, Any] = {"t": self._end * 1e-9, "window": self.period}
        for d, c in self._counts.items():
            rec[d] = {n: k / self.period for n, k in c.items()}
            self._counts[d] = dict.fromkeys(c, 0)
        return rec


# --------------------------------------------------------------------------- JSON


def _default(o: Any) -> Any:
    """numpy scalars and arrays, enums, bytes -> JSON values."""
    if hasattr(o, "tolist"):
        return o.tolist()
    if hasattr(o, "item"):
        return o.item()
    if isinstance(o, bytes | bytearray):
        return base64.b64encode(o).decode()
    if isinstance(o, set | frozenset | tuple):
        return list(o)
    raise TypeError(f"{type(o).__name__} is not JSON serializable")


def _finite(o: Any) -> Any:
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, Mapping):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [_finite(v) for v in o]
    return o


_ORJSON_OPTIONS = orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS


def encode_json(obj: Any) -> bytes:
    """Compact JSON of ``obj``; numpy values become lists/numbers, NaN/inf become null.

    orjson (about 5x faster than the json module on these records) writes the same JSON
    values; what it cannot encode (integers beyond 64 bits) goes through the json module.
    """
    try:
        return orjson.dumps(obj, default=_default, option=_ORJSON_OPTIONS)
    except (orjson.JSONEncodeError, TypeError):
        pass
    try:
        return json.dumps(obj, separators=(",", ":"), allow_nan=False,
                          default=_default).encode()
    except ValueError:
        plain = json.loads(json.dumps(obj, default=_default))  # NaN -> float('nan')
        return json.dumps(_finite(plain), separators=(",", ":"), allow_nan=False).encode()


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


def protobuf_class(name: str, descriptor_set: bytes) -> type[Any]:
    """The message class ``name`` of a serialized ``FileDescriptorSet``, in a pool of its
    own (so it is what the recording says, whatever this process has imported)."""
    from google.protobuf import descriptor_pool, message_factory
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    pool = descriptor_pool.DescriptorPool()
    for f in FileDescriptorSet.FromString(descriptor_set).file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(name))


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


# --------------------------------------------------------------------------- recorder


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


def _naming(e: OSError, path: Path) -> OSError:
    """``e`` (same class and errno) naming the recording instead of whatever it named."""
    return type(e)(e.errno, e.strerror or str(e), str(path))


class _GuardedFile:
    """The recording's part file as the MCAP writer's stream: a failed write (a full disk,
    a file-size limit) is kept in :attr:`error` and raised naming the recording."""

    def __init__(self, f: Any, path: Path) -> None:
        self._f, self._path = f, path
        self.error: OSError | None = None

    def _guard(self, op: Callable[..., Any], *a: Any) -> Any:
        try:
            return op(*a)
        except OSError as e:
            self.error = self.error or e
            raise _naming(e, self._path) from None

    def write(self, data: Any) -> int:
        return self._guard(self._f.write, data)

    def flush(self) -> None:
        self._guard(self._f.flush)

    def tell(self) -> int:
        return self._f.tell()

    def fileno(self) -> int:
        return self._f.fileno()

    def close(self) -> None:
        self._f.close()


class RecordingInUseError(ValueError):
    """Another process is writing the same recording."""


def _locked_part(path: Path, part: Path) -> Any:
    """The ``.part`` file of ``path`` opened for writing under an exclusive lock (released
    when it is closed): a second run given the same recording path fails at once instead of
    writing into the first's file; a part left by a killed run (not locked) is reused."""
    fd = os.open(part, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RecordingInUseError(f"{path}: another run is writing this recording (its "
                                  f"{part.name} is locked)") from None
    except BaseException:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    return os.fdopen(fd, "wb")


class Recorder:
    """Writes a run to MCAP: chunked, zstd-compressed (lz4 or none when zstd is missing).

    The file is written as ``.<name>.part`` next to ``path`` and renamed to ``path`` by
    :meth:`finish` (also called by ``with`` on exit, normal or not): a file under ``path``
    is always complete, with summary and indexes. A process killed without a chance to
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
        self._file = _GuardedFile(_locked_part(self.path, self.part_path), self.path)
        self._writer = Writer(self._file, chunk_size=chunk_size, compression=self.compression)
        self._writer.start(profile="", library="hpcosim bus_schemas")
        self._append = supports(self._writer)  # the one-pack path (mcap_append)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[int, int] = {}
        self.message_count = 0
        self.dropped = 0  # writes after a signal finished the file (exit=False)
        self.finished = False
        self.interrupted: int | None = None  # the signal that finished the file
        self._busy = False
        self._pending: int | None = None
        self._exit_on_signal = True
        self._old_handlers: dict[int, Any] = {}
        #: (topic, build, args, log time); topic None: ``build(*args)`` gives (topic, message)
        #: pairs (:meth:`defer_many`)
        self._deferred: deque[tuple[str | None, Callable[..., Any] | None, tuple[Any, ...],
                                    int]] = deque()
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

    # -- deferred writes: queue now, serialize when the caller has time (e.g. while it
    #    waits for a reply); :meth:`finish` writes what is left, also on a signal
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
        """Queue a frame for ``/can/tx`` or ``/can/rx`` (see :meth:`write_can`)."""
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
        :meth:`finish`: the file's records and their order are the same either way)."""
        n = 0
        q = self._deferred
        while q and not self.finished:
            if stop is not None and stop():
                break
            topic, build, args, ns = q.popleft()
            if topic is None:  # one event's records: one append
                n += self.write_many([(tp, message, ns) for tp, message
                                      in build(*args)])  # type: ignore[misc]
                continue
            self.write(topic, build(*args) if build else args[0], ns)
            n += 1
        return n

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
                # renamed while still locked: no other run can take the part in between
                os.replace(self.part_path, self.path)
            except OSError as e:  # a full disk: no partial file, an error naming the file
                self.part_path.unlink(missing_ok=True)
                raise _naming(e, self.path) from None
            finally:
                with contextlib.suppress(OSError):  # closing flushes: the disk may be full
                    self._file.close()
                self.restore_signal_handlers()
        return self.path

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
        self.part_path.unlink(missing_ok=True)
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

    # -- signals
    def install_signal_handlers(self, signals: Iterable[int] = (signal.SIGTERM,
                                                                signal.SIGINT),
                                *, exit: bool = True) -> None:
        """On any of ``signals``: record a ``signal`` metadata entry and finish the file,
        then (``exit=True``) raise ``SystemExit(128 + signum)`` (``KeyboardInterrupt`` for
        SIGINT) so the program unwinds; with ``exit=False`` set :attr:`interrupted` and
        drop further writes, for a caller that polls it. Main thread only."""
        self._exit_on_signal = exit
        for s in signals:
            self._old_handlers[s] = signal.signal(s, self._on_signal)

    def restore_signal_handlers(self) -> None:
        """Put back the handlers replaced by :meth:`install_signal_handlers`."""
        for s, h in self._old_handlers.items():
            signal.signal(s, h)
        self._old_handlers.clear()

    @contextlib.contextmanager
    def _critical(self) -> Iterator[None]:
        """Defer signal handling until the MCAP writer is in a consistent state."""
        outer = self._busy
        self._busy = True
        try:
            yield
        finally:
            self._busy = outer
        if not outer and self._pending is not None:
            self._handle_pending()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        self._pending = signum
        if not self._busy:
            self._handle_pending()

    def _handle_pending(self) -> None:
        signum, self._pending = self._pending, None
        if signum is None:
            return
        if not self.finished:
            self.write_deferred()  # what was queued before the signal is part of the run
            self.interrupted = signum
            self.add_metadata("signal", {"signal": signal.Signals(signum).name,
                                         "messages": str(self.message_count)})
            self.finish()
        if self._exit_on_signal:
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            raise SystemExit(128 + signum)

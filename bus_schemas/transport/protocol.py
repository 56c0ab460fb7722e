"""The AMPRO3-style protocol as data: the DBC (loaded once), frame ids, enums, layouts.

``database()`` parses ``ampro3.dbc`` once per process (``functools.cache``; no other module
state). ``frame_specs()`` turns it into precomputed bit layouts (:class:`FrameSpec`) that
the fast codec path in :mod:`bus_schemas.transport.codec` packs with integer shifts; the layouts are
derived from the DBC, never written a second time by hand.

Units: angles rad, velocities rad/s, torques N m on the motor side (joint torque = gear
ratio x motor torque, gear ratios in the device config), loads N, sim time us.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import cantools
from cantools.database.can import Database

from bus_schemas.transport.crc8 import id_prefix_state

DBC_PATH = Path(__file__).parents[1] / "ampro3.dbc"  # bus_schemas/: transport and recording

BITRATE = 500_000  # bit/s, classic CAN 2.0A
FRAME_LENGTH = 8  # bytes; every frame of the protocol is 8 bytes
COUNTER_SIGNAL = "Counter"  # bits 48..51 of protected frames
CHECKSUM_SIGNAL = "Checksum"  # byte 7 of protected frames
COUNTER_MODULO = 16


class FrameId(enum.IntEnum):
    """11-bit frame ids (lower id = higher bus priority)."""

    TORQUE_CMD = 0x010
    CTRL_HEARTBEAT = 0x020
    SIM_TIME = 0x080
    KNEE_FEEDBACK = 0x101
    ANKLE_FEEDBACK = 0x102
    FOOT_LOAD = 0x110
    SOCKET_IMU = 0x111
    CTRL_STATUS = 0x300
    CTRL_REJECTS = 0x301
    CTRL_DISTURBANCE = 0x302
    CTRL_CLF = 0x303


#: frames the plant (prosthesis hardware side) sends and the controller receives
PLANT_TO_CTRL = frozenset({FrameId.SIM_TIME, FrameId.KNEE_FEEDBACK, FrameId.ANKLE_FEEDBACK,
                           FrameId.FOOT_LOAD, FrameId.SOCKET_IMU})
#: frames the controller sends and the plant receives
CTRL_TO_PLANT = frozenset({FrameId.TORQUE_CMD, FrameId.CTRL_HEARTBEAT, FrameId.CTRL_STATUS,
                           FrameId.CTRL_REJECTS, FrameId.CTRL_DISTURBANCE, FrameId.CTRL_CLF})


class CtrlState(enum.IntEnum):
    """Controller state machine (``CtrlHeartbeat.CtrlState``)."""

    INIT = 0
    RUNNING = 1
    SAFE = 2
    FAULT = 3


class QpStatus(enum.IntEnum):
    """Status of the controller's last QP solve (``CtrlStatus.QpStatus``)."""

    SOLVED = 0
    SOLVED_CLOSED_FORM = 1
    MAX_ITER = 2
    PRIMAL_INFEASIBLE = 3
    DUAL_INFEASIBLE = 4
    NUMERICS = 5
    UNSOLVED = 6
    NOT_RUN = 7
    UNKNOWN = 255


class FaultFlag(enum.IntFlag):
    """Controller fault bits (``CtrlStatus.FaultFlags``)."""

    NONE = 0
    STALE_FEEDBACK = 1 << 0
    BAD_FRAMES = 1 << 1
    QP_FAILED = 1 << 2
    TORQUE_SATURATED = 1 << 3
    JOINT_LIMIT = 1 << 4
    DEADLINE_MISS = 1 << 5
    PLANT_LOST = 1 << 6
    CONFIG_ERROR = 1 << 7


class ActiveConstraint(enum.IntFlag):
    """Active QP constraint bits (``CtrlStatus.ActiveConstraints``)."""

    NONE = 0
    KNEE_TORQUE = 1 << 0
    ANKLE_TORQUE = 1 << 1
    KNEE_RATE = 1 << 2
    ANKLE_RATE = 1 << 3
    RELAXATION = 1 << 4


# Quantization steps and ranges: the DBC scale factors and [min|max] (a test asserts they
# match the DBC). A decoded value is round((clamp(x) - offset) / step) * step + offset.
ANGLE_STEP = 1e-5  # rad, KneeAngle / AnkleAngle
ANGLE_RANGE = (-3.2, 3.2)  # rad
VELOCITY_STEP = 1e-4  # rad/s, KneeVelocity / AnkleVelocity
VELOCITY_RANGE = (-50.0, 50.0)  # rad/s
TORQUE_STEP = 1e-6  # N m motor side, KneeTorqueCmd / AnkleTorqueCmd
TORQUE_RANGE = (-5.0, 5.0)  # N m motor side
LOAD_STEP = 0.1  # N, FootNormalLoad
LOAD_RANGE = (-1000.0, 3000.0)  # N
CLF_V_STEP = 1e-5  # CtrlClf.ClfV, CLF value V_eps (dimensionless)
CLF_V_RANGE = (0.0, 167.77215)  # the full 24-bit unsigned range
CLF_RHO_STEP = 1e-3  # CtrlClf.ClfRho, CLF-QP relaxation (dimensionless)
CLF_RHO_RANGE = (0.0, 16777.215)  # the full 24-bit unsigned range (default rho_max 1e4)


@functools.cache
def database() -> Database:
    """The parsed DBC (cached: parsed once per process)."""
    db = cantools.database.load_file(str(DBC_PATH), strict=True)
    assert isinstance(db, Database)
    return db


@dataclass(frozen=True, slots=True)
class SignalSpec:
    """One signal's bit layout and scaling (little-endian, integer raw value)."""

    name: str
    start: int  # first bit (little-endian numbering)
    length: int  # bits
    signed: bool
    scale: float
    offset: float
    minimum: float
    maximum: float
    linear: bool  # False: identity (raw == physical, an int)

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1


@dataclass(frozen=True, slots=True)
class FrameSpec:
    """One frame: id, name, payload signals (DBC order, without Counter/Checksum)."""

    frame_id: int
    name: str
    sender: str
    cycle_time_ms: int | None
    payload: tuple[SignalSpec, ...]
    protected: bool  # carries Counter (bits 48..51) and Checksum (byte 7)
    crc_state: int  # CRC register after the id bytes (protected frames)
    # Flat per-signal tuples for the codec's hot loops (derived from ``payload``):
    # encode: (start, mask, minimum, maximum, scale, offset, linear)
    enc_plan: tuple[tuple[int, int, float, float, float, float, bool], ...]
    # decode: (start, mask, sign bit or 0, 2**length, scale, offset, linear)
    dec_plan: tuple[tuple[int, int, int, int, float, float, bool], ...]

    def signal(self, name: str) -> SignalSpec:
        for s in self.payload:
            if s.name == name:
                return s
        raise KeyError(f"{self.name} has no payload signal {name!r}")


def _signal_spec(sig) -> SignalSpec:
    if sig.byte_order != "little_endian" or sig.is_float or sig.is_multiplexer:
        raise ValueError(f"signal {sig.name}: the fast codec supports little-endian integer "
                         "signals only")
    linear = not (sig.scale == 1 and sig.offset == 0)
    lo = sig.minimum if sig.minimum is not None else -float("inf")
    hi = sig.maximum if sig.maximum is not None else float("inf")
    return SignalSpec(sig.name, sig.start, sig.length, sig.is_signed, sig.scale, sig.offset,
                      lo, hi, linear)


@functools.cache
def frame_specs() -> Mapping[int, FrameSpec]:
    """Frame layouts by id, derived once from :func:`database`."""
    out: dict[int, FrameSpec] = {}
    for m in database().messages:
        if m.length != FRAME_LENGTH or m.is_extended_frame or m.is_fd or m.is_multiplexed():
            raise ValueError(f"{m.name}: every frame must be a classic 8-byte standard frame")
        names = {s.name: s for s in m.signals}
        protected = COUNTER_SIGNAL in names
        if protected:
            c, k = names[COUNTER_SIGNAL], names[CHECKSUM_SIGNAL]
            if (c.start, c.length, k.start, k.length) != (48, 4, 56, 8):
                raise ValueError(f"{m.name}: Counter must be bits 48..51, Checksum byte 7")
        payload = tuple(_signal_spec(s) for s in m.signals
                        if s.name not in (COUNTER_SIGNAL, CHECKSUM_SIGNAL))
        out[m.frame_id] = FrameSpec(
            frame_id=m.frame_id, name=m.name, sender=m.senders[0] if m.senders else "",
            cycle_time_ms=m.cycle_time, payload=payload, protected=protected,
            crc_state=id_prefix_state(m.frame_id),
            enc_plan=tuple((s.start, s.mask, s.minimum, s.maximum, s.scale, s.offset,
                            s.linear) for s in payload),
            dec_plan=tuple((s.start, s.mask, 1 << (s.length - 1) if s.signed else 0,
                            1 << s.length, s.scale, s.offset, s.linear) for s in payload))
    return out


@functools.cache
def _by_name() -> Mapping[str, FrameSpec]:
    return {s.name: s for s in frame_specs().values()}


def frame_spec(frame: int | str) -> FrameSpec:
    """The layout of a frame given its id or DBC name."""
    try:
        return _by_name()[frame] if isinstance(frame, str) else frame_specs()[int(frame)]
    except KeyError:
        raise KeyError(f"no frame {frame!r} in {DBC_PATH.name}") from None


def frame_bits(dlc: int = FRAME_LENGTH, *, worst_case: bool = False) -> int:
    """Bits on the wire for one classic CAN standard-id data frame, including the 3-bit
    interframe space; ``worst_case`` adds the maximum number of stuff bits."""
    bits = 47 + 8 * dlc
    if worst_case:
        bits += (34 + 8 * dlc - 1) // 4
    return bits


def bus_load(rates_hz: Mapping[int, float] | None = None, *, bitrate: int = BITRATE,
             worst_case: bool = False) -> float:
    """Bus load (fraction of ``bitrate``) of frames sent at ``rates_hz`` (frame id -> Hz;
    default: every frame at its DBC cycle time)."""
    if rates_hz is None:
        rates_hz = {i: 1000.0 / s.cycle_time_ms for i, s in frame_specs().items()
                    if s.cycle_time_ms}
    per_frame = frame_bits(worst_case=worst_case)
    return sum(rates_hz.values()) * per_frame / bitrate

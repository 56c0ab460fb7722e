"""Decoding received frames: :func:`decode` (a ``can.Message``) and :func:`decode_frame`
(a light :class:`~bus_schemas.transport.frame.Frame`) check the id, the length and the
checksum and give the typed payload in a :class:`~.payloads.Verdict`; they never raise (a
frame the protocol does not allow comes back rejected).  The rolling counter is reported,
not checked (:class:`~.checker.FrameChecker` does).  The payloads come from one
straight-line decoder per frame generated from the DBC (:func:`decoders`,
:mod:`bus_schemas.transport.codec.fastcodec`).
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Callable
from typing import Any

import can

from bus_schemas.transport.codec import fastcodec
from bus_schemas.transport.codec.payloads import PAYLOAD_TYPES, FrameStatus, Verdict
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.protocol import (
    FRAME_LENGTH,
    ActiveConstraint,
    CtrlState,
    FaultFlag,
    FrameId,
    FrameSpec,
    QpStatus,
    frame_specs,
)

# hot-path constants (enum attribute lookups cost more than a global)
_OK, _BAD_CHECKSUM, _BAD_LENGTH, _UNKNOWN_ID = (
    FrameStatus.OK, FrameStatus.BAD_CHECKSUM, FrameStatus.BAD_LENGTH, FrameStatus.UNKNOWN_ID)
_HEARTBEAT, _STATUS = int(FrameId.CTRL_HEARTBEAT), int(FrameId.CTRL_STATUS)


def decode(msg: can.Message | Frame) -> Verdict:
    """Stateless decode: id, length and checksum checks, then the typed payload. The
    rolling counter is reported, not checked (see :class:`~.checker.FrameChecker`). Never
    raises (anything without a CAN frame's attributes is rejected)."""
    try:
        ts = float(msg.timestamp)
    except (AttributeError, TypeError, ValueError):
        ts = 0.0
    try:
        fid = int(msg.arbitration_id)
        ext, err = bool(msg.is_extended_id), bool(msg.is_error_frame)
        remote, fd = bool(msg.is_remote_frame), bool(msg.is_fd)
        data, dlc = msg.data, msg.dlc
    except (AttributeError, TypeError, ValueError):
        return Verdict(_UNKNOWN_ID, None, timestamp=ts, detail="not a CAN message")
    spec = None if (ext or err) else frame_specs().get(fid)
    if spec is None:
        return Verdict(_UNKNOWN_ID, fid, timestamp=ts,
                       detail="extended id" if ext else "error frame" if err else "id")
    if isinstance(data, memoryview):
        data = data.tobytes()
    n = len(data) if isinstance(data, bytes | bytearray) else -1
    if remote or fd or dlc != FRAME_LENGTH or n != FRAME_LENGTH:
        return Verdict(_BAD_LENGTH, fid, spec.name, timestamp=ts,
                       detail=f"dlc {dlc}, {n} data bytes" + (", remote" if remote else "")
                       + (", fd" if fd else ""))
    return _checked(spec, data, ts)


def decode_frame(f: Frame) -> Verdict:
    """:func:`decode` of a :class:`Frame` (the same verdict, without the attribute checks
    a Frame makes needless; fields of other types than the declared: :func:`decode`)."""
    fid, data, ts = f.arbitration_id, f.data, f.timestamp
    if type(data) is not bytes or type(ts) is not float or type(fid) is not int:
        return decode(f)
    dec = decoders().get(fid)
    if dec is None:
        return Verdict(_UNKNOWN_ID, fid, timestamp=ts, detail="id")
    if len(data) != FRAME_LENGTH:
        return Verdict(_BAD_LENGTH, fid, frame_specs()[fid].name, timestamp=ts,
                       detail=f"dlc {FRAME_LENGTH}, {len(data)} data bytes")
    return dec(data, ts)


def _checked(spec: FrameSpec, data: bytes | bytearray, ts: float) -> Verdict:
    """Checksum check and typed payload of 8 data bytes of a known frame (the frame's
    generated decoder, :mod:`~bus_schemas.transport.codec.fastcodec`)."""
    return decoders()[spec.frame_id](data, ts)


def _fix_heartbeat(vals: list[Any]) -> None:
    vals[0] = _member(CtrlState, vals[0])


def _fix_status(vals: list[Any]) -> None:
    vals[0], vals[1] = FaultFlag(vals[0]), _member(QpStatus, vals[1])
    vals[4] = ActiveConstraint(vals[4])


@functools.cache
def decoders() -> dict[int, Callable[[bytes | bytearray, float], Verdict]]:
    """The generated decoder of each frame id (built once per process): 8 data bytes and a
    timestamp -> the checked :class:`~.payloads.Verdict`."""
    fixes = {_HEARTBEAT: _fix_heartbeat, _STATUS: _fix_status}
    return {fid: fastcodec.decoder(spec, Verdict, PAYLOAD_TYPES[fid], _OK, _BAD_CHECKSUM,
                                   fixes.get(fid))
            for fid, spec in frame_specs().items()}


def _member(enum_type: type[enum.IntEnum], raw: int) -> int:
    """The enum member for ``raw``, or ``raw`` itself when it is not a member."""
    # the map's values are typed Enum; an IntEnum's members are ints
    return enum_type._value2member_map_.get(raw, raw)  # type: ignore[return-value]


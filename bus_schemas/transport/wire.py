"""The wire form of CAN frames over zenoh: one frame per sample (:func:`pack_message`) or
the frames of one control cycle as one sample (a *frame batch*, :func:`pack_batch`), and
back (:func:`unpack_payload`, :func:`unpack_frames`; never raising on garbage).

Single frame: a 15-byte header ``<BdIBB`` (version 1, timestamp s as float64, arbitration
id, flags: 1 extended, 2 remote, 4 error, 8 FD, 16 BRS, 32 ESI; DLC) and the data bytes
(23 bytes for an 8-byte frame). The receiver gets the sender's timestamp unchanged.
Batch: version byte 2, frame count n (1..255), then per frame its length (one byte) and
its single-frame form. Batches of classic 8-byte frames go through one ``struct`` call
each way.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from typing import Any

import can

from bus_schemas.transport.frame import Frame

WIRE_VERSION = 1
BATCH_VERSION = 2
MAX_BATCH = 255  # frames per batch sample (count byte)
_HEADER = struct.Struct("<BdIBB")  # version, timestamp [s], arbitration id, flags, dlc
_EXT, _REMOTE, _ERROR, _FD, _BRS, _ESI = 1, 2, 4, 8, 16, 32
_MAX_DATA = 64


def pack_message(msg: can.Message | Frame, timestamp: float | None = None) -> bytes:
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
    :class:`~bus_schemas.transport.codec.Frame` s is packed in one ``struct`` call."""
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
    light :class:`~bus_schemas.transport.codec.Frame` (the same fields) and the rest as
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

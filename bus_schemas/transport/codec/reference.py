"""The reference paths the fast codec is tested against (bit for bit): cantools' encoder
and decoder (:func:`encode_cantools`, :func:`decode_cantools`) and the decode loop over the
DBC's bit layouts (:func:`decode_signals`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import can

from bus_schemas.transport.crc8 import XOROUT, crc8_update
from bus_schemas.transport.protocol import (
    CHECKSUM_SIGNAL,
    COUNTER_SIGNAL,
    FRAME_LENGTH,
    FrameSpec,
    database,
    frame_spec,
)


def encode_cantools(frame: int | str, values: Mapping[str, Any],
                    counter: int | None = None) -> can.Message:
    """Reference encoder through cantools (``strict=True``). Values are clamped to the DBC
    ranges first (as the fast path does), NaN rejected; the checksum is filled in after."""
    spec = frame_spec(frame)
    data = {}
    for s in spec.payload:
        v = values[s.name]
        if isinstance(v, float) and math.isnan(v):
            raise ValueError(f"{spec.name}.{s.name}: NaN cannot be encoded")
        data[s.name] = min(max(v, s.minimum), s.maximum)
    if spec.protected:
        data[COUNTER_SIGNAL] = int(counter or 0) % 16
        data[CHECKSUM_SIGNAL] = 0
    raw = bytearray(database().encode_message(spec.frame_id, data, strict=True))
    if spec.protected:
        raw[7] = crc8_update(spec.crc_state, raw[:7]) ^ XOROUT
    return can.Message(arbitration_id=spec.frame_id, is_extended_id=False,
                       dlc=FRAME_LENGTH, data=raw)


def decode_cantools(msg: can.Message) -> dict[str, Any]:
    """Reference decoder through cantools (no choice names, exact length required)."""
    m = database().get_message_by_frame_id(msg.arbitration_id)
    return dict(m.decode_simple(bytes(msg.data), decode_choices=False, allow_truncated=False,
                                allow_excess=False))


def _values(spec: FrameSpec, data: bytes | bytearray) -> list[Any]:
    """The payload values of 8 data bytes, signal by signal from the layout."""
    w = int.from_bytes(data, "little")
    out: list[Any] = []
    for start, mask, sign, full, scale, offset, linear in spec.dec_plan:
        r = (w >> start) & mask
        if r & sign:
            r -= full
        out.append(r * scale + offset if linear else r)
    return out


def decode_signals(msg: can.Message) -> dict[str, Any]:
    """Layout decode to a ``{signal: value}`` dict with the same keys and values as
    :func:`decode_cantools` (Counter/Checksum included). Raises on a frame the protocol
    does not allow; use :func:`~.decode.decode` for untrusted input."""
    spec = frame_spec(msg.arbitration_id)
    if len(msg.data) != FRAME_LENGTH:
        raise ValueError(f"{spec.name}: {len(msg.data)} bytes")
    out = dict(zip((s.name for s in spec.payload), _values(spec, msg.data), strict=True))
    if spec.protected:
        out[COUNTER_SIGNAL] = msg.data[6] & 0x0F
        out[CHECKSUM_SIGNAL] = msg.data[7]
    return out


"""CRC-8/SAE-J1850 and the frame checksum of the AMPRO3-style protocol.

CRC-8/SAE-J1850: width 8, polynomial 0x1D, initial value 0xFF, input and output not
reflected, final XOR 0xFF; check value ``crc8(b"123456789") == 0x4B``.

Frame checksum (byte 7 of every protected frame): the CRC over the 11-bit frame id as two
bytes little-endian (``id & 0xFF``, ``id >> 8``) followed by data bytes 0..6. Including
the id means a payload that lands on the wrong id fails the check (AUTOSAR E2E style).
"""

from __future__ import annotations

from collections.abc import Iterable

POLY = 0x1D
INIT = 0xFF
XOROUT = 0xFF


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


TABLE: tuple[int, ...] = _make_table()


def crc8_update(state: int, data: Iterable[int]) -> int:
    """Advance a raw (not yet final-XORed) CRC register over ``data`` bytes."""
    t = TABLE
    for b in data:
        state = t[state ^ b]
    return state


def crc8(data: Iterable[int]) -> int:
    """CRC-8/SAE-J1850 of ``data`` (bytes or an iterable of ints 0..255)."""
    return crc8_update(INIT, data) ^ XOROUT


def id_prefix_state(frame_id: int) -> int:
    """The CRC register after the two id bytes of ``frame_id`` (precomputed per frame)."""
    return crc8_update(INIT, (frame_id & 0xFF, (frame_id >> 8) & 0xFF))


def frame_checksum(frame_id: int, data: bytes | bytearray) -> int:
    """Checksum byte of a protected frame: CRC over id (2 bytes, LE) + ``data[0:7]``."""
    return crc8_update(id_prefix_state(frame_id), data[:7]) ^ XOROUT

"""The light CAN frame of the co-simulation's hot paths (no dependency beyond python-can,
so the bus modules can use it without the codec's)."""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import can

FRAME_LENGTH = 8  # bytes (= bus_schemas.transport.protocol.FRAME_LENGTH)


class _FrameFields(NamedTuple):
    """The three fields of a :class:`Frame` (a NamedTuple holds fields only)."""

    timestamp: float  # s
    arbitration_id: int
    data: bytes  # 8 bytes


class Frame(_FrameFields):
    """A classic CAN data frame with a standard id: the light stand-in for a
    ``can.Message`` on the co-simulation's hot paths (the ``*_frames`` encoders, the batch
    wire form), built in a fraction of a ``can.Message``'s time. It has the attributes
    :func:`bus_schemas.transport.codec.decode`, :func:`bus_schemas.transport.wire.pack_message`
    and the recorder read; a ``data`` of a length other than 8 bytes is ``bad_length`` as for a
    ``can.Message``. Also exported by :mod:`bus_schemas.transport.codec`."""

    __slots__ = ()
    # class attributes, not fields: what a Frame always is
    dlc: ClassVar[int] = FRAME_LENGTH
    is_extended_id: ClassVar[bool] = False
    is_remote_frame: ClassVar[bool] = False
    is_error_frame: ClassVar[bool] = False
    is_fd: ClassVar[bool] = False
    bitrate_switch: ClassVar[bool] = False
    error_state_indicator: ClassVar[bool] = False

    def to_message(self) -> can.Message:
        """The same frame as a ``can.Message`` (for a bus that needs one)."""
        return can.Message(timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                           is_extended_id=False, dlc=FRAME_LENGTH, data=bytearray(self.data))

"""The light CAN frame of the co-simulation's hot paths (no dependency beyond python-can,
so the bus modules can use it without the codec's)."""

from __future__ import annotations

from typing import NamedTuple

import can

FRAME_LENGTH = 8  # bytes (= bus_schemas.protocol.FRAME_LENGTH)


class Frame(NamedTuple):
    """A classic CAN data frame with a standard id: the light stand-in for a
    ``can.Message`` on the co-simulation's hot paths (the ``*_frames`` encoders, the batch
    wire form), built in a fraction of a ``can.Message``'s time. It has the attributes
    :func:`bus_schemas.codec.decode`, :func:`bus_schemas.zenoh_can.pack_message` and the
    recorder read; a ``data`` of a length other than 8 bytes is ``bad_length`` as for a
    ``can.Message``. Also exported by :mod:`bus_schemas.codec`."""

    timestamp: float  # s
    arbitration_id: int
    data: bytes  # 8 bytes
    # class attributes, not fields: what a Frame always is
    dlc = FRAME_LENGTH
    is_extended_id = False
    is_remote_frame = False
    is_error_frame = False
    is_fd = False
    bitrate_switch = False
    error_state_indicator = False

    def to_message(self) -> can.Message:
        """The same frame as a ``can.Message`` (for a bus that needs one)."""
        return can.Message(timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                           is_extended_id=False, dlc=FRAME_LENGTH, data=bytearray(self.data))

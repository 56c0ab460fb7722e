"""Encode and decode AMPRO3-style frames; quantization helpers: the codec's API, used as
``from bus_schemas.transport import codec`` then ``codec.encode_torque(...)``.

Two paths produce the same bytes and the same decoded floats (tested bit for bit):

- the fast path (default): layouts precomputed from the DBC
  (:func:`~bus_schemas.transport.protocol.frame_specs`), turned into one straight-line
  encoder and decoder per frame (:mod:`.fastcodec`); encoding about 3x faster than the same
  work through cantools, decoding with all checks about as fast as cantools' bare decode
  plus a CRC check (see ``benchmarks/bench_bus.py``); :class:`Frame` and the ``*_frame(s)``
  encoders skip the ``can.Message``;
- the cantools path (:func:`encode_cantools`, :func:`decode_cantools`), the reference.

Encoding clamps every value to its DBC ``[min|max]`` (a torque beyond +-5 N m is sent as
+-5 N m; +-inf saturates likewise) and rejects NaN with ``ValueError``. ``quantize_*``
return exactly the value a decoder will see for an input (scalars or numpy arrays).
Decoding (:func:`decode`) never raises: a frame that is not what the protocol allows comes
back as a rejected :class:`Verdict`; :class:`FrameChecker` adds the per-id rolling-counter
check and counts every class.

Modules: :mod:`.payloads` (:class:`FrameStatus`, the typed payloads, :class:`Verdict`),
:mod:`.encode`, :mod:`.decode`, :mod:`.checker` (:class:`FrameChecker`), :mod:`.quantize`,
:mod:`.reference` (the cantools path and the layout loop), :mod:`.fastcodec` (the generated
per-frame code).

Units: angles rad, velocities rad/s, torques N m (motor side), load N, sim time us.
"""

from bus_schemas.transport.codec.checker import FrameChecker
from bus_schemas.transport.codec.decode import decode, decode_frame
from bus_schemas.transport.codec.encode import (
    clf_frame,
    disturbance_frame,
    encode_clf,
    encode_disturbance,
    encode_feedback,
    encode_frame,
    encode_heartbeat,
    encode_sim_time,
    encode_status,
    encode_torque,
    feedback_frames,
    heartbeat_frame,
    torque_frame,
)
from bus_schemas.transport.codec.payloads import (
    PAYLOAD_TYPES,
    AnkleFeedback,
    CtrlClf,
    CtrlDisturbance,
    CtrlHeartbeat,
    CtrlRejects,
    CtrlStatus,
    FootLoad,
    FrameStatus,
    KneeFeedback,
    SimTime,
    SocketImu,
    TorqueCmd,
    Verdict,
)
from bus_schemas.transport.codec.quantize import (
    quantize,
    quantize_angle,
    quantize_clf_rho,
    quantize_clf_v,
    quantize_load,
    quantize_pitch,
    quantize_torque,
    quantize_velocity,
    scalar_quantizer,
)
from bus_schemas.transport.codec.reference import decode_cantools, decode_signals, encode_cantools
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.protocol import database

__all__ = [
    "PAYLOAD_TYPES",
    "AnkleFeedback",
    "CtrlClf",
    "CtrlDisturbance",
    "CtrlHeartbeat",
    "CtrlRejects",
    "CtrlStatus",
    "FootLoad",
    "Frame",
    "FrameChecker",
    "FrameStatus",
    "KneeFeedback",
    "SimTime",
    "SocketImu",
    "TorqueCmd",
    "Verdict",
    "clf_frame",
    "database",
    "decode",
    "decode_cantools",
    "decode_frame",
    "decode_signals",
    "disturbance_frame",
    "encode_cantools",
    "encode_clf",
    "encode_disturbance",
    "encode_feedback",
    "encode_frame",
    "encode_heartbeat",
    "encode_sim_time",
    "encode_status",
    "encode_torque",
    "feedback_frames",
    "heartbeat_frame",
    "quantize",
    "quantize_angle",
    "quantize_clf_rho",
    "quantize_clf_v",
    "quantize_load",
    "quantize_pitch",
    "quantize_torque",
    "quantize_velocity",
    "scalar_quantizer",
    "torque_frame",
]

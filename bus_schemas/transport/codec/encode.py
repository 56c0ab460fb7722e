"""Encoding frames from physical values: ``encode_*`` (``can.Message``) and the light
``*_frame(s)`` encoders (:class:`~bus_schemas.transport.frame.Frame`, the same bytes).

Every value is clamped to its DBC ``[min|max]`` (a torque beyond +-5 N m is sent as
+-5 N m; +-inf saturates likewise) and NaN raises ``ValueError`` naming the frame and
signal; counters are taken mod 16, ``Tick`` and ``SimTimeUs`` mod 2**32.  The bytes come
from one straight-line encoder per frame generated from the DBC
(:mod:`bus_schemas.transport.codec.fastcodec`).

Units: angles rad, velocities rad/s, torques N m (motor side), load N, sim time us.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import can

from bus_schemas.transport.codec import fastcodec
from bus_schemas.transport.codec.payloads import FrameStatus
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.protocol import (
    FRAME_LENGTH,
    CtrlState,
    FaultFlag,
    FrameId,
    FrameSpec,
    QpStatus,
    frame_spec,
    frame_specs,
)


def _nan(spec: FrameSpec, i: int) -> ValueError:
    return ValueError(f"{spec.name}.{spec.payload[i].name}: NaN cannot be encoded")


def _data(spec: FrameSpec, values: Sequence[Any], counter: int | None) -> bytes:
    """The 8 data bytes of ``values`` (payload order): clamp to [min, max], round half to
    even exactly as cantools does, mask and shift; then counter and checksum for
    protected frames (the frame's generated encoder, :mod:`.fastcodec`)."""
    if len(values) != len(spec.enc_plan):
        raise ValueError(f"{spec.name}: {len(spec.enc_plan)} values needed")
    return _encoders()[spec.frame_id](values, counter)


@functools.cache
def _encoders() -> dict[int, Callable[[Any, int | None], bytes]]:
    return {fid: fastcodec.encoder(spec) for fid, spec in frame_specs().items()}


def _frame(spec: FrameSpec, values: Sequence[Any], counter: int | None,
           timestamp: float) -> can.Message:
    """A ``can.Message`` of :func:`_data`."""
    return can.Message(timestamp=timestamp, arbitration_id=spec.frame_id,
                       is_extended_id=False, dlc=FRAME_LENGTH,
                       data=bytearray(_data(spec, values, counter)))


def encode_frame(frame: int | str, values: Mapping[str, Any], counter: int | None = None,
                 *, timestamp: float = 0.0) -> can.Message:
    """Encode any frame from physical values by signal name (all payload signals needed;
    Counter/Checksum are filled in). ``counter`` is taken mod 16."""
    spec = frame_spec(frame)
    missing = [s.name for s in spec.payload if s.name not in values]
    extra = set(values) - {s.name for s in spec.payload}
    if missing or extra:
        raise ValueError(f"{spec.name}: missing signals {missing}, unknown {sorted(extra)}")
    return _frame(spec, [values[s.name] for s in spec.payload], counter, timestamp)


_SPEC = frame_specs  # short alias for the hot helpers below


def _feedback_plan(knee_angle: float, knee_vel: float, ankle_angle: float,
                   ankle_vel: float, load: float, contact: bool, sim_time_us: int | None,
                   socket_pitch: float | None) -> list[tuple[FrameSpec, tuple[Any, ...]]]:
    """(spec, payload values) of each frame of the plant's cycle, in sending order."""
    specs = _SPEC()
    out: list[tuple[FrameSpec, tuple[Any, ...]]] = [
        (specs[FrameId.KNEE_FEEDBACK], (knee_angle, knee_vel)),
        (specs[FrameId.ANKLE_FEEDBACK], (ankle_angle, ankle_vel)),
        (specs[FrameId.FOOT_LOAD], (load, 1 if contact else 0))]
    if socket_pitch is not None:
        ok = math.isfinite(socket_pitch)
        out.append((specs[FrameId.SOCKET_IMU], (socket_pitch if ok else 0.0, 1 if ok else 0)))
    if sim_time_us is not None:
        out.append((specs[FrameId.SIM_TIME], (int(sim_time_us) % (1 << 32),)))
    return out


# PLR0913: one argument per DBC signal of the cycle's frames (an interface the DBC fixes)
def encode_feedback(knee_angle: float, knee_vel: float, ankle_angle: float,  # noqa: PLR0913
                    ankle_vel: float, load: float, contact: bool, counter: int, *,
                    sim_time_us: int | None = None, socket_pitch: float | None = None,
                    timestamp: float = 0.0) -> list[can.Message]:
    """The plant's frames of one cycle: KneeFeedback, AnkleFeedback, FootLoad, SocketImu
    if ``socket_pitch`` is given (a NaN pitch is sent with ImuValid 0) and, if
    ``sim_time_us`` is given, SimTime; all with the same rolling ``counter`` (mod 16).
    Angles rad, velocities rad/s, load N."""
    return [_frame(spec, vals, counter, timestamp) for spec, vals in _feedback_plan(
        knee_angle, knee_vel, ankle_angle, ankle_vel, load, contact, sim_time_us,
        socket_pitch)]


# PLR0913: one argument per DBC signal of the cycle's frames (an interface the DBC fixes)
def feedback_frames(knee_angle: float, knee_vel: float, ankle_angle: float,  # noqa: PLR0913
                    ankle_vel: float, load: float, contact: bool, counter: int, *,
                    sim_time_us: int | None = None, socket_pitch: float | None = None,
                    timestamp: float = 0.0) -> list[Frame]:
    """:func:`encode_feedback` as light :class:`Frame` s (the same bytes)."""
    enc, ts = _encoders(), float(timestamp)
    out = [Frame(ts, _KNEE, enc[_KNEE]((knee_angle, knee_vel), counter)),
           Frame(ts, _ANKLE, enc[_ANKLE]((ankle_angle, ankle_vel), counter)),
           Frame(ts, _LOAD, enc[_LOAD]((load, 1 if contact else 0), counter))]
    if socket_pitch is not None:
        ok = math.isfinite(socket_pitch)
        out.append(Frame(ts, _IMU, enc[_IMU]((socket_pitch if ok else 0.0, 1 if ok else 0),
                                             counter)))
    if sim_time_us is not None:
        out.append(Frame(ts, _SIMTIME, enc[_SIMTIME]((int(sim_time_us) % (1 << 32),),
                                                     counter)))
    return out


_TORQUE, _DISTURBANCE, _CLF, _HEARTBEAT = (
    int(FrameId.TORQUE_CMD), int(FrameId.CTRL_DISTURBANCE), int(FrameId.CTRL_CLF),
    int(FrameId.CTRL_HEARTBEAT))
_KNEE, _ANKLE, _LOAD, _IMU, _SIMTIME = (int(FrameId.KNEE_FEEDBACK), int(FrameId.ANKLE_FEEDBACK),
                                        int(FrameId.FOOT_LOAD), int(FrameId.SOCKET_IMU),
                                        int(FrameId.SIM_TIME))


def encode_sim_time(sim_time_us: int, counter: int, *, timestamp: float = 0.0) -> can.Message:
    """SimTime frame; ``sim_time_us`` is sent mod 2**32 (wraps after about 71.6 min)."""
    return _frame(_SPEC()[FrameId.SIM_TIME], (int(sim_time_us) % (1 << 32),), counter,
                  timestamp)


def encode_torque(knee: float, ankle: float, counter: int, *, enable: bool = True,
                  timestamp: float = 0.0) -> can.Message:
    """TorqueCmd frame: motor-side torques in N m, each clamped to +-5 N m."""
    return _frame(_SPEC()[FrameId.TORQUE_CMD], (knee, ankle, 1 if enable else 0), counter,
                  timestamp)


def encode_heartbeat(state: CtrlState | int, tick: int, counter: int, *,
                     timestamp: float = 0.0) -> can.Message:
    """CtrlHeartbeat frame; ``tick`` is sent mod 2**32."""
    s = int(state)
    if s not in CtrlState._value2member_map_:
        raise ValueError(f"CtrlHeartbeat.CtrlState: {state!r} is not a CtrlState")
    return _frame(_SPEC()[FrameId.CTRL_HEARTBEAT], (s, int(tick) % (1 << 32)), counter,
                  timestamp)


# PLR0913: one argument per DBC signal of CtrlStatus and CtrlRejects (the DBC fixes them)
def encode_status(fault_flags: FaultFlag | int = 0, qp_status: QpStatus | int = 0,  # noqa: PLR0913
                  qp_iterations: int = 0, fallback_count: int = 0,
                  active_constraints: int = 0,
                  rejects: Mapping[FrameStatus, int] | Mapping[str, int] | None = None, *,
                  coverage_flag: bool = False, coverage_count: int = 0,
                  timestamp: float = 0.0) -> list[can.Message]:
    """CtrlStatus and CtrlRejects frames (unprotected diagnostics). Counts saturate at the
    signal maximum (FallbackCount 65535, QpIterations 255, rejection counts 4095,
    CoverageCount 127); ``rejects`` maps a :class:`FrameStatus` (or its string) to a count;
    ``coverage_flag``/``coverage_count``: the model-error coverage monitor."""
    r = {FrameStatus(k): int(v) for k, v in (rejects or {}).items()}
    specs = _SPEC()
    status = _frame(specs[FrameId.CTRL_STATUS],
                    (int(fault_flags), int(qp_status), qp_iterations, fallback_count,
                     int(active_constraints), 1 if coverage_flag else 0,
                     max(0, int(coverage_count))), None, timestamp)
    rej = _frame(specs[FrameId.CTRL_REJECTS],
                 tuple(r.get(s, 0) for s in (FrameStatus.BAD_CHECKSUM,
                                             FrameStatus.BAD_COUNTER, FrameStatus.BAD_LENGTH,
                                             FrameStatus.DUPLICATE, FrameStatus.UNKNOWN_ID)),
                 None, timestamp)
    return [status, rej]


def encode_disturbance(dy1: float, d2y2: float, tau: float, valid: bool, flag: bool,
                       since_touchdown: float, *, timestamp: float = 0.0) -> can.Message:
    """CtrlDisturbance frame (unprotected diagnostic): the model-error estimate (m/s^2,
    rad/s^2), its phase, validity, coverage flag and the time since touchdown (s); values
    clamp to the signal ranges (a non-finite value raises, as every encoder)."""
    return _frame(_SPEC()[FrameId.CTRL_DISTURBANCE],
                  (dy1, d2y2, tau, 1 if valid else 0, 1 if flag else 0, since_touchdown),
                  None, timestamp)


def _clf_values(V: float | None, rho: float | None) -> tuple[float, float, int, int]:
    """CtrlClf payload: a None or non-finite value is sent absent (0 with its valid bit 0)."""
    v = V if V is not None and math.isfinite(V) else None
    r = rho if rho is not None and math.isfinite(rho) else None
    return (0.0 if v is None else v, 0.0 if r is None else r,
            0 if v is None else 1, 0 if r is None else 1)


def encode_clf(V: float | None, rho: float | None, counter: int, *,
               timestamp: float = 0.0) -> can.Message:
    """CtrlClf frame (protected): the CLF value V (step 1e-5, 0 .. 167.77215) and the
    relaxation rho (step 1e-3, 0 .. 16777.215), both dimensionless, clamped to their ranges;
    None or a non-finite value is sent absent (valid bit 0)."""
    return _frame(_SPEC()[FrameId.CTRL_CLF], _clf_values(V, rho), counter, timestamp)


def clf_frame(V: float | None, rho: float | None, counter: int, *,
              timestamp: float = 0.0) -> Frame:
    """:func:`encode_clf` as a light :class:`Frame` (the same bytes)."""
    return Frame(float(timestamp), _CLF, _encoders()[_CLF](_clf_values(V, rho), counter))


def torque_frame(knee: float, ankle: float, counter: int, *, enable: bool = True,
                 timestamp: float = 0.0) -> Frame:
    """:func:`encode_torque` as a light :class:`Frame` (the same bytes)."""
    return Frame(float(timestamp), _TORQUE,
                 _encoders()[_TORQUE]((knee, ankle, 1 if enable else 0), counter))


def heartbeat_frame(state: CtrlState | int, tick: int, counter: int, *,
                    timestamp: float = 0.0) -> Frame:
    """:func:`encode_heartbeat` as a light :class:`Frame` (the same bytes)."""
    s = int(state)
    if s not in CtrlState._value2member_map_:
        raise ValueError(f"CtrlHeartbeat.CtrlState: {state!r} is not a CtrlState")
    return Frame(float(timestamp), _HEARTBEAT,
                 _encoders()[_HEARTBEAT]((s, int(tick) % (1 << 32)), counter))


def disturbance_frame(dy1: float, d2y2: float, tau: float, valid: bool, flag: bool,
                      since_touchdown: float, *, timestamp: float = 0.0) -> Frame:
    """:func:`encode_disturbance` as a light :class:`Frame` (the same bytes)."""
    return Frame(float(timestamp), _DISTURBANCE, _encoders()[_DISTURBANCE](
        (dy1, d2y2, tau, 1 if valid else 0, 1 if flag else 0, since_touchdown), None))


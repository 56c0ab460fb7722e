"""What the co-simulation records of the CAN frames (MCAP channels, docs/cosim.md): each frame
on ``/can/tx`` or ``/can/rx``, and what the frames carry on the channels of the prosthesis
(``/prosthesis/measurements``, ``/prosthesis/torque_command``) and of the controller
(``/controller/disturbance``, ``/controller/diagnostics``).

The ``*_records`` functions are called when a deferred queue entry is written (the plant
queues them while it waits for the controller's reply)."""

from __future__ import annotations

import math
from typing import Any

from bus_schemas.transport import codec
from bus_schemas.transport.protocol import FrameId
from orchestrator.loop import Sensed

_TORQUE, _DISTURBANCE = int(FrameId.TORQUE_CMD), int(FrameId.CTRL_DISTURBANCE)
_OK = codec.FrameStatus.OK


def tx_records(frames: list[Any], names: dict[int, str], s: Sensed, t_us: int,
               counter: int) -> list[tuple[str, Any]]:
    """The records of one cycle's plant frames (as encoded, before any injected fault):
    each frame on ``/can/tx`` and the measurement they carry."""
    from bus_schemas.recording.schemas import can_frame_message  # the recorder's module, loaded

    out: list[tuple[str, Any]] = [
        ("/can/tx", can_frame_message(m, "tx", name=names[m.arbitration_id]))
        for m in frames]
    out.append(("/prosthesis/measurements", measurement_record(s, t_us, counter)))
    return out


def rx_records(items: list[tuple[Any, codec.Verdict]], ratio: tuple[float, float]
               ) -> list[tuple[str, Any]]:
    """The records of one received sample's controller frames: each on ``/can/rx`` with the
    plant's verdict, and a good ``TorqueCmd`` or ``CtrlDisturbance`` on its own channel."""
    from bus_schemas.recording.schemas import can_frame_message

    out: list[tuple[str, Any]] = []
    for m, v in items:
        out.append(("/can/rx", can_frame_message(m, "rx", name=v.name, status=str(v.status))))
        if v.status is not _OK:
            continue
        if v.frame_id == _TORQUE:
            out.append(("/prosthesis/torque_command",
                        torque_record(v.value, v.counter, m.timestamp, ratio)))
        elif v.frame_id == _DISTURBANCE:
            out.append(("/controller/disturbance", disturbance_record(v.value, m.timestamp)))
    return out


_Q_ANGLE = codec.scalar_quantizer(FrameId.KNEE_FEEDBACK, "KneeAngle")  # quantize_angle
_Q_VELOCITY = codec.scalar_quantizer(FrameId.KNEE_FEEDBACK, "KneeVelocity")
_Q_LOAD = codec.scalar_quantizer(FrameId.FOOT_LOAD, "FootNormalLoad")
_Q_PITCH = codec.scalar_quantizer(FrameId.SOCKET_IMU, "SocketPitch")


def measurement_record(s: Sensed, t_us: int, counter: int) -> dict[str, Any]:
    """``/prosthesis/measurements``: what AMPRO3 senses (``s``) as the controller decodes it
    (codec quantization: ``quantize_angle`` etc., their constants bound once)."""
    return {"knee_angle": _Q_ANGLE(s.knee_angle),
            "knee_velocity": _Q_VELOCITY(s.knee_velocity),
            "ankle_angle": _Q_ANGLE(s.ankle_angle),
            "ankle_velocity": _Q_VELOCITY(s.ankle_velocity),
            "foot_load": _Q_LOAD(s.foot_load), "contact": s.contact,
            "socket_pitch": (_Q_PITCH(s.socket_pitch)
                             if math.isfinite(s.socket_pitch) else None),
            "sim_time_us": t_us % (1 << 32), "counter": counter}


def torque_record(c: codec.TorqueCmd, counter: int | None, timestamp: float,
                  ratio: tuple[float, float]) -> dict[str, Any]:
    """``/prosthesis/torque_command``: motor torques [N m] and the joint torques they give
    (gear ``ratio``), for the cycle whose SimTime timestamp [s] the frame echoes."""
    return {"knee": c.knee, "ankle": c.ankle, "knee_joint": c.knee * ratio[0],
            "ankle_joint": c.ankle * ratio[1], "enable": bool(c.enable), "counter": counter,
            "cycle_time_us": round(timestamp * 1e6)}


def disturbance_record(e: codec.CtrlDisturbance, timestamp: float) -> dict[str, Any]:
    """``/controller/disturbance``: the controller's model-error estimate of the cycle
    whose SimTime timestamp [s] the frame echoes."""
    return {"t": timestamp, "d": [e.dy1, e.d2y2], "tau": e.tau, "valid": bool(e.valid),
            "flag": bool(e.flag), "since_touchdown": e.since_touchdown}


def diagnostics_record(st: Any, timestamp: float, controller: str, u_joint: list[float],
                       clf: tuple[float | None, float | None],
                       ctrl_rejects: dict[str, int]) -> dict[str, Any]:
    """``/controller/diagnostics`` of a ``CtrlStatus`` frame ``st`` (every 100 ticks): with
    the joint torques ``u_joint`` [N m] applied and the cycle's (V, rho) at that moment and
    the controller's reject counts; what the frame does not carry is None."""
    return {
        "t": timestamp, "controller": controller, "domain": None,
        "tau": None, "V": clf[0], "rho": clf[1], "u": u_joint,
        "qp_status": getattr(st.qp_status, "name", str(st.qp_status)),
        "active_constraints": [a.name for a in type(st.active_constraints)
                               if a in st.active_constraints and a.name],
        "fallback_count": st.fallback_count, "fault_flags": int(st.fault_flags),
        "coverage_flag": bool(st.coverage_flag), "coverage_count": st.coverage_count,
        "solve_time_us": None, "source": "CtrlStatus frame", "ctrl_rejects": ctrl_rejects}

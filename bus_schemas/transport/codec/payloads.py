"""What a decoded frame is: the receiver's classes (:class:`FrameStatus`), one typed payload
per frame (field order = the DBC's payload signal order) and the :class:`Verdict` that
carries them.

Units: angles rad, velocities rad/s, torques N m (motor side), load N, sim time us.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Any, NamedTuple

from bus_schemas.transport.protocol import FrameId


class FrameStatus(enum.StrEnum):
    """How a received frame was classified."""

    OK = "ok"
    BAD_CHECKSUM = "bad_checksum"
    BAD_COUNTER = "bad_counter"
    BAD_LENGTH = "bad_length"
    DUPLICATE = "duplicate"
    UNKNOWN_ID = "unknown_id"


# Typed payloads, one per frame (field order = DBC payload signal order).
class TorqueCmd(NamedTuple):
    knee: float  # N m, motor side
    ankle: float  # N m, motor side
    enable: int  # 1: apply torques, 0: zero torque


class CtrlHeartbeat(NamedTuple):
    state: int  # CtrlState (an int outside the enum is passed through: treat as fault)
    tick: int  # controller tick, mod 2**32


class SimTime(NamedTuple):
    us: int  # plant sim time, microseconds mod 2**32


class KneeFeedback(NamedTuple):
    angle: float  # rad
    velocity: float  # rad/s


class AnkleFeedback(NamedTuple):
    angle: float  # rad
    velocity: float  # rad/s


class FootLoad(NamedTuple):
    load: float  # N, normal load
    contact: int  # 1: in contact


class SocketImu(NamedTuple):
    pitch: float  # rad, world pitch of the prosthesis top link
    valid: int  # 1: a measurement


class CtrlStatus(NamedTuple):
    fault_flags: int  # FaultFlag
    qp_status: int  # QpStatus (an int outside the enum is passed through)
    qp_iterations: int
    fallback_count: int
    active_constraints: int  # ActiveConstraint
    coverage_flag: int  # 1: the model-error estimate left the characterised bound
    coverage_count: int  # flagged ticks, saturating at 127


class CtrlDisturbance(NamedTuple):
    dy1: float  # m/s^2, estimated model error of dy1
    d2y2: float  # rad/s^2, estimated model error of d2y2
    tau: float  # stance phase of the estimate
    valid: int  # 1: the estimate has settled
    flag: int  # 1: outside the characterised bound
    since_touchdown: float  # s, since the switch to stance, saturating at 0.255


class CtrlClf(NamedTuple):
    V: float  # CLF value V_eps (dimensionless, >= 0); 0 when absent
    rho: float  # CLF-QP relaxation (dimensionless, >= 0); 0 when absent
    v_valid: int  # 1: V is the controller's value, 0: absent
    rho_valid: int  # 1: rho is the controller's value, 0: absent (no relaxation)


class CtrlRejects(NamedTuple):
    bad_checksum: int
    bad_counter: int
    bad_length: int
    duplicate: int
    unknown_id: int


PAYLOAD_TYPES: Mapping[int, type[NamedTuple]] = {
    FrameId.TORQUE_CMD: TorqueCmd,
    FrameId.CTRL_HEARTBEAT: CtrlHeartbeat,
    FrameId.SIM_TIME: SimTime,
    FrameId.KNEE_FEEDBACK: KneeFeedback,
    FrameId.ANKLE_FEEDBACK: AnkleFeedback,
    FrameId.FOOT_LOAD: FootLoad,
    FrameId.SOCKET_IMU: SocketImu,
    FrameId.CTRL_STATUS: CtrlStatus,
    FrameId.CTRL_REJECTS: CtrlRejects,
    FrameId.CTRL_DISTURBANCE: CtrlDisturbance,
    FrameId.CTRL_CLF: CtrlClf,
}


class Verdict(NamedTuple):
    """A received frame, classified. ``value`` is the typed payload when ``status`` is ok."""

    status: FrameStatus
    frame_id: int | None
    name: str | None = None
    counter: int | None = None
    value: Any = None
    timestamp: float = 0.0
    detail: str = ""

    @property
    def ok(self) -> bool:
        return self.status is _OK


_OK = FrameStatus.OK  # a global: an enum attribute lookup costs more

"""The emulated AMPRO3 drives: their gear ratios and motor torque limits (:class:`Drives`), and
what the plant accepts from the controller (:class:`Plant`: frame checks, the controller's
state, the torque bound)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import can

from bus_schemas.transport import codec
from bus_schemas.transport.protocol import CTRL_TO_PLANT, TORQUE_STEP, FrameId
from hp_model.domains import PROSTHESIS

_STATUS, _HEARTBEAT, _REJECTS = (
    int(FrameId.CTRL_STATUS), int(FrameId.CTRL_HEARTBEAT), int(FrameId.CTRL_REJECTS))
_OK = codec.FrameStatus.OK


@dataclass(frozen=True)
class Drives:
    """The prosthesis drives (knee, ankle): motor -> joint torque ``ratio`` and the motor
    torque ``limits`` [N m]."""

    ratio: tuple[float, float]
    limits: tuple[float, float]

    @classmethod
    def of(cls, model: Any) -> Drives:
        """The drives of a :class:`~hp_model.human_prosthesis.HumanProsthesisModel` (its
        input matrix's prosthesis entries and motor torque limits)."""
        k, a = (model.coord_names.index(c) for c in PROSTHESIS)
        return cls((float(model.B[k, 4]), float(model.B[a, 5])),
                   (float(model.torque_limits[4]), float(model.torque_limits[5])))

    def joint(self, u: tuple[float, float]) -> list[float]:
        """Joint torques [N m] of motor torques ``u``."""
        return [u[0] * self.ratio[0], u[1] * self.ratio[1]]


class Plant:
    """The plant side of one run: rx frame checking, the controller state it implies, and
    the bound on what it applies: every torque command is clamped to the device's motor
    limits ``limits`` (knee, ankle; N m) whatever the sender computed or encoded (the DBC
    admits +-5 N m), and counted when it had to be."""

    def __init__(self, limits: tuple[float, float]) -> None:
        if not all(math.isfinite(x) and x > 0 for x in limits):
            raise ValueError(f"torque limits must be finite and > 0, got {limits}")
        self.limits = (float(limits[0]), float(limits[1]))
        self.checker = codec.FrameChecker(accept=CTRL_TO_PLANT)
        self.ctrl_state: int | None = None
        self.ctrl_rejects: dict[str, int] = {}
        self.last_status: Any = None
        self.torque_clamped = 0  # commands with a torque outside the limits

    def command(self, c: Any) -> tuple[float, float]:
        """The motor torques to apply for a decoded TorqueCmd ``c``: zero unless enabled,
        each clamped to +-limit (a non-finite value is applied as zero and counted)."""
        if not c.enable:
            return 0.0, 0.0
        (k, a), (lk, la) = (float(c.knee), float(c.ankle)), self.limits
        # a command at the limit decodes to within the signal's resolution of it
        if not (abs(k) <= lk + TORQUE_STEP and abs(a) <= la + TORQUE_STEP):
            self.torque_clamped += 1
        return (min(max(k, -lk), lk) if math.isfinite(k) else 0.0,
                min(max(a, -la), la) if math.isfinite(a) else 0.0)

    def on_rx(self, msg: can.Message | codec.Frame) -> codec.Verdict:
        """Classify one controller frame (never raises) and track heartbeat and status."""
        v = self.checker.check(msg)
        if v.status is _OK:
            fid = v.frame_id  # plain ints below: an IntEnum member's lookup is Python code
            if fid == _HEARTBEAT:
                self.ctrl_state = int(v.value.state)
            elif fid == _REJECTS:
                self.ctrl_rejects = {k: int(n) for k, n in v.value._asdict().items()}
            elif fid == _STATUS:
                self.last_status = v.value
        return v

    def rejects(self) -> dict[str, int]:
        """The checker's counts of rejected frames by reason."""
        return {str(s): n for s, n in self.checker.counts.items() if str(s) != "ok"}

"""The one controller interface and its output types.

A controller is built once (``make_controller``), then called once per control period:

    ctrl = make_controller("clfqp", gait, tube, model)
    ctrl.reset()
    out = ctrl.tick(ProsthesisMeasurement(t, qk, qa, vk, va, load, contact))
    out.torque          # (2,) motor torques (knee, ankle), N m, finite, within the limits
    out.diagnostics     # Diagnostics (below), every number finite

Controllers hold their own state (previous torque, domain with hysteresis, time of the
last domain switch, fallback count).  ``tick`` never raises on a bad measurement.
"""

from __future__ import annotations

from enum import IntFlag
from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np

from hp_model.choices import Choice
from hp_model.domains import Domain
from prosthesis_controller.measurement import ProsthesisMeasurement


class Active(IntFlag):
    """Constraints of the QP active at its solution (bits)."""

    NONE = 0
    CLF = 1  # the robust CLF row
    KNEE_LOWER = 2  # knee torque at its lower bound (torque limit or rate bound)
    KNEE_UPPER = 4
    ANKLE_LOWER = 8
    ANKLE_UPPER = 16
    RHO_MAX = 32  # relaxation at rho_max
    OUTPUT_CLAMP = 64  # not a QP constraint: the output clamp to the motor limits acted
    CONTACT = 128  # a stance-foot contact row (friction, normal force, CoP) of clfqp


class ControllerName(Choice):
    """The prosthesis controllers :func:`~prosthesis_controller.registry.make_controller`
    builds (:data:`~prosthesis_controller.registry.CONTROLLERS` says what each is)."""

    CLFQP = "clfqp"
    CLFQP_EXACT = "clfqp-exact"
    CLFQP_PAPER = "clfqp-paper"
    CLFQP_PAPER_EXACT = "clfqp-paper-exact"
    PD = "pd"
    PASSIVE = "passive"
    PHASE_PD = "phase-pd"

    @classmethod
    def label(cls) -> str:
        return "controller"


class QpOutcome(Choice):
    """What the tick's QP gave (``Diagnostics.qp_status``); the controller node reports it
    on the bus as :class:`bus_schemas.protocol.QpStatus` (``prosthesis_controller.node``)."""

    NOT_RUN = "not_run"  # no QP this tick (swing, baselines, fault)
    SOLVED = "solved"
    INFEASIBLE = "infeasible"  # exact feasibility test of the one row over the bounds failed
    FAILED = "failed"  # piqp did not report solved (max iterations, numerics, infeasible)
    NONFINITE = "nonfinite"  # non-finite model terms or solution

    @property
    def is_failure(self) -> bool:
        """A QP was due and gave no torque (the tick fell back)."""
        return self in (QpOutcome.INFEASIBLE, QpOutcome.FAILED, QpOutcome.NONFINITE)


class ControllerMode(Choice):
    """Which law made the tick's torque (``Diagnostics.mode``; counted per run as
    ``modes`` in the metrics)."""

    STANCE = "stance"  # the controller's own stance law
    SWING = "swing"  # the shared swing controller
    FALLBACK = "fallback"  # QP failure: previous torque rate-limited toward the PD torque
    FAULT = "fault"  # bad measurement: previous torque rate-limited toward zero
    #: no controller: the scenarios' oracle (full-state feedback linearization of the
    #: prosthesis, :data:`orchestrator.experiments.scenarios.ORACLE`)
    ORACLE = "oracle"


class Diagnostics(NamedTuple):
    """Per-tick diagnostics; every number is finite.  Immutable; a NamedTuple rather than a
    frozen dataclass because it is built every tick (0.4 us against 1.5 us for 14 fields).

    tau: phase (state-based in ps, the time-based estimate in pns); V: CLF value V_eps
    (evaluated for every controller in ps, 0 in pns); rho: relaxation (0 unless relaxed
    CLF-QP); qp_status, active: :class:`QpOutcome` and :class:`Active`; fallback_count:
    ticks since ``reset`` whose torque came from a fallback (QP failure, non-finite law
    output or a faulty measurement); fault: the
    :class:`~prosthesis_controller.measurement.Fault` bits of this tick's measurement;
    domain: the controller's :class:`~hp_model.domains.Domain` (``PS`` or ``PNS``); mode:
    :class:`ControllerMode`.

    Model-error estimate and coverage monitor (``clfqp``, ``clfqp-exact``;
    :mod:`prosthesis_controller.disturbance`; zero / False for the other controllers):
    disturbance: (dy1 [m/s^2], d2y2 [rad/s^2]), the filtered estimate of d = nu - (a + A u)
    (0 while not valid); disturbance_valid: the estimator has run long enough; coverage_flag:
    this tick's estimate is outside the tube's characterised bound (never without one);
    coverage_count: flagged ticks since ``reset``; since_touchdown: time since the switch to
    stance (s; 0 in swing and on a faulty tick)."""

    tau: float
    V: float
    rho: float
    qp_status: QpOutcome
    active: Active
    fallback_count: int
    fault: int
    domain: Domain
    mode: ControllerMode
    disturbance: tuple[float, float] = (0.0, 0.0)
    disturbance_valid: bool = False
    coverage_flag: bool = False
    coverage_count: int = 0
    since_touchdown: float = 0.0


class ControlOutput(NamedTuple):
    """Motor torques (knee, ankle) in N m and the diagnostics of the tick (immutable; a
    NamedTuple for the same reason as :class:`Diagnostics`)."""

    torque: np.ndarray
    diagnostics: Diagnostics


@runtime_checkable
class Controller(Protocol):
    """What every prosthesis controller provides."""

    name: str

    def reset(self, torque: tuple[float, float] | None = None) -> None:
        """Forget all state: previous torque ``torque`` (default 0), initial domain, no switch
        time, counts 0."""
        ...

    def tick(self, meas: ProsthesisMeasurement) -> ControlOutput:
        """One control period."""
        ...

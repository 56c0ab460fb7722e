"""The per-tick skeleton every controller shares (:class:`BaseController`) and what a stance
law returns (:class:`StanceResult`).

Per tick: validate the measurement (a fault -> the previous torque rate-limited toward
zero), update the domain (hysteresis on contact and foot load, minimum dwell), run the
controller's stance law in ``ps`` or the shared swing law (:mod:`prosthesis_controller.swing`)
in ``pns``, replace a non-finite torque by the fallback, clamp to the motor limits.  A
controller is a subclass that provides ``_stance``; see the package README.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from hp_model.domains import Domain
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import (
    Active,
    ControllerMode,
    ControlOutput,
    Diagnostics,
    QpOutcome,
)
from prosthesis_controller.measurement import ProsthesisMeasurement, read
from prosthesis_controller.swing import SwingLaw

#: the prosthesis state a law reads: (th_pk, th_pa, dth_pk, dth_pa), rad and rad/s
State = tuple[float, float, float, float]


class StanceResult(NamedTuple):
    """One tick of a stance law (a NamedTuple: built every tick).

    knee, ankle: motor torques (N m, before the output clamp); tau: the state-based ps
    phase; V: the CLF value V_eps; rho: the CLF relaxation (0 unless relaxed); qp_status,
    active: what the tick's QP gave and its active constraints; mode: which law made the
    torque."""

    knee: float
    ankle: float
    tau: float
    V: float
    rho: float = 0.0
    qp_status: QpOutcome = QpOutcome.NOT_RUN
    active: Active = Active.NONE
    mode: ControllerMode = ControllerMode.STANCE


class BaseController:
    """Shared tick logic; subclasses provide ``_stance``.  See the module docstring."""

    name = "base"

    def __init__(self, ctx: ControllerContext) -> None:
        self.ctx = ctx
        cfg = ctx.config
        s = cfg.safety
        self._limits = ctx.limits
        self._fallback_step = float(s.fallback_rate)
        self._checks = (s.knee_range, s.ankle_range, float(s.max_speed), s.load_range)
        d = cfg.domain
        self._load_on, self._load_off, self._dwell = d.load_on, d.load_off, d.min_dwell
        self._off_hold = d.off_hold
        ps = ctx.gait.params[Domain.PS]
        self._phase = ctx.terms.hip.phase_function(ps.p_min, ps.p_max)
        self._phase_rate = ps.nominal_rate
        num = ctx.terms.numeric
        self._clf = num["clf_qp"]
        self._clf.inputs[1][:] = ctx.clf_params
        #: the outputs of the generated ``clf_qp`` call by name (overwritten by every call)
        self._clf_out = dict(zip(self._clf.function.name_out(), self._clf.outputs,
                                 strict=True))
        self._stance_ref = num["stance_ref"]
        self._stance_ref.inputs[2][:] = ctx.stance_params
        self._pd_kp, self._pd_kd = np.array(cfg.pd.kp), np.array(cfg.pd.kd)
        self._gear = np.array(ctx.gear)
        #: the shared swing law (pns) with its thigh-lead state
        self.swing = SwingLaw(ctx)
        self.reset()

    # -- state ------------------------------------------------------------------------
    def reset(self, torque: tuple[float, float] | np.ndarray | None = None) -> None:
        """Forget all state.  ``torque``: the previous torque to assume (motor N m, clamped
        to the limits; default zero), e.g. when taking over from another controller."""
        u = (0.0, 0.0) if torque is None else (float(torque[0]), float(torque[1]))
        self._u = tuple(_clamp(v, lim) if math.isfinite(v) else 0.0
                        for v, lim in zip(u, self._limits, strict=True))
        self._domain = Domain(self.ctx.config.domain.initial)
        self._t_switch: float | None = None
        self._t_unloaded: float | None = None  # since when load <= load_off with contact
        self._t_prev = -math.inf
        self.fallback_count = 0
        self.swing.reset()
        self._reset_estimator()

    def _reset_estimator(self) -> None:
        """Model-error estimator state (controllers that have one)."""

    def _estimator_gap(self) -> None:
        """A tick without the stance law (fault, swing): no finite difference across it."""

    def _estimate(self) -> tuple[tuple[float, float], bool, bool, int]:
        """(disturbance, valid, coverage flag, coverage count) of this tick: none here."""
        return (0.0, 0.0), False, False, 0

    @property
    def domain(self) -> Domain:
        return self._domain

    @property
    def previous_torque(self) -> np.ndarray:
        return np.array(self._u)

    def _update_domain(self, t: float, contact: bool, load: float) -> Domain:
        stance = contact and load >= self._load_on
        if contact and load <= self._load_off:
            if self._t_unloaded is None:
                self._t_unloaded = t
            unloaded = t - self._t_unloaded >= self._off_hold
        else:
            self._t_unloaded = None
            unloaded = False
        swing = (not contact) or unloaded
        if self._t_switch is None:  # first valid sample: decide at once, start the clock
            if stance:
                self._domain = Domain.PS
            elif (not contact) or load <= self._load_off:
                self._domain = Domain.PNS
            self._t_switch = t
        elif t - self._t_switch >= self._dwell:
            if self._domain is Domain.PNS and stance:
                self._domain, self._t_switch = Domain.PS, t
            elif self._domain is Domain.PS and swing:
                self._domain, self._t_switch = Domain.PNS, t
                self.swing.reset()
        return self._domain

    # -- laws -------------------------------------------------------------------------
    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        """The controller's stance law at time t (s), ``since`` s after the switch to
        stance, at state x."""
        raise NotImplementedError

    def _clf_terms(self, x: State) -> tuple[float, float]:
        """Evaluate the generated ``clf_qp`` call at x (its outputs in ``self._clf_out``);
        (tau, V): the state-based phase and the CLF value."""
        self._clf.inputs[0][:] = x
        self._clf.call_inplace()
        return float(self._clf_out["tau"][0]), float(self._clf_out["V"][0])

    def _stance_phase(self, qk: float, qa: float) -> tuple[float, float]:
        """The state-based phase tau(th_pk, th_pa) of the gait's ps (the phase the paper's
        trajectories are functions of; :meth:`hp_model.outputs.HipProgress.phase`) and its
        nominal rate (``GaitParams.nominal_rate``)."""
        return self._phase(qk, qa), self._phase_rate

    def _pd_torque(self, x: State) -> tuple[float, float]:
        """Stance PD on the nominal trajectory at the state-based phase, the reference
        velocities at the nominal phase rate (motor N m)."""
        f = self._stance_ref
        f.inputs[0][0], f.inputs[1][0] = self._stance_phase(x[0], x[1])
        f.call_inplace()
        qd, vd = f.outputs[0], f.outputs[1]
        q, v = np.array(x[:2]), np.array(x[2:])
        u = (self._pd_kp * (qd - q) + self._pd_kd * (vd - v)) / self._gear
        return float(u[0]), float(u[1])

    def _fall_back(self, x: State, tau: float, V: float, outcome: QpOutcome
                   ) -> StanceResult:
        """The QP fallback: the previous torque moved by at most ``fallback_rate`` toward
        the stance PD torque."""
        self.fallback_count += 1
        pk, pa = self._pd_torque(x)
        if not (math.isfinite(pk) and math.isfinite(pa)):
            pk = pa = 0.0
        step = self._fallback_step
        return StanceResult(_toward(self._u[0], pk, step), _toward(self._u[1], pa, step), tau,
                            V, 0.0, outcome, Active.NONE, ControllerMode.FALLBACK)

    def _stop(self, law: StanceResult, mode: ControllerMode) -> StanceResult:
        """``law`` with the previous torque moved by at most ``fallback_rate`` toward zero
        (a faulty measurement, a non-finite torque)."""
        self.fallback_count += 1
        step = self._fallback_step
        return law._replace(knee=_toward(self._u[0], 0.0, step),
                            ankle=_toward(self._u[1], 0.0, step), mode=mode)

    # -- the tick ---------------------------------------------------------------------
    def tick(self, meas: ProsthesisMeasurement) -> ControlOutput:
        fault, t, qk, qa, vk, va, load, contact, pitch = read(meas, self._t_prev,
                                                               *self._checks)
        since = 0.0
        if fault:
            law = self._stop(StanceResult(0.0, 0.0, 0.0, 0.0), ControllerMode.FAULT)
            self._estimator_gap()
        else:
            self._t_prev = t
            x = (qk, qa, vk, va)
            domain = self._update_domain(t, contact, load)
            t_switch = self._t_switch
            assert t_switch is not None  # set by the first valid measurement
            if domain is Domain.PS:
                since = t - t_switch
                law = self._stance(t, since, x)
            else:
                knee, ankle, tau = self.swing.torque(t, t_switch, x, pitch)
                law = StanceResult(knee, ankle, tau, 0.0, mode=ControllerMode.SWING)
                self._estimator_gap()
            if not (math.isfinite(law.knee) and math.isfinite(law.ankle)):
                law = self._stop(law, ControllerMode.FALLBACK)
            if not (math.isfinite(law.tau) and math.isfinite(law.V) and math.isfinite(law.rho)):
                law = law._replace(tau=0.0, V=0.0, rho=0.0)
        knee, ankle = _clamp(law.knee, self._limits[0]), _clamp(law.ankle, self._limits[1])
        active = law.active
        if knee != law.knee or ankle != law.ankle:
            active |= Active.OUTPUT_CLAMP
        self._u = (knee, ankle)
        est, valid, flag, count = self._estimate()
        return ControlOutput(np.array(self._u), Diagnostics(
            law.tau, law.V, law.rho, law.qp_status, active, self.fallback_count, int(fault),
            self._domain, law.mode, est, valid, flag, count, since))


def _clamp(v: float, limit: float) -> float:
    """v within [-limit, limit]."""
    return min(max(v, -limit), limit)


def _toward(u: float, target: float, step: float) -> float:
    """u moved toward ``target`` by at most ``step``."""
    return u + min(max(target - u, -step), step)

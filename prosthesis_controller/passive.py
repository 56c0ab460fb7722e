"""The robust-passive baseline (``passive``): Spong's robust passivity-based law, the
stand-in for Azimi et al. 2017 (``terms.passive``); and ``passive`` on the multi-contact
graph (:class:`ContactPassive`: contact-pd's phase and swing, Spong's law in stance about the
gait's angles, rates and accelerations at the phase, ``terms.passive_ref``).  See the
package README, "Baselines and swing"."""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import medfilt

from hp_model.compiled import CompileBackend, FunctionSet
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.leg_kinematics import LegKinematics
from hp_model.prosthesis import ProsthesisSubsystem
from prosthesis_controller.base import BaseController, StanceResult, State
from prosthesis_controller.config import PassiveConfig
from prosthesis_controller.contact_phase_pd import (
    DEFAULT_SWING_PHASE,
    SWING_GAINS,
    ContactGaitTables,
    ContactPhasePD,
    PDGains,
    PhaseTable,
    blend_tables,
)
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import ControllerName
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.terms import passive_reference_function, standard_parameters

#: samples of the median filter on the reference accelerations (an impact's one-period spike)
ACCEL_FILTER = 5


class PassiveController(BaseController):
    """Spong's robust passivity-based law on the nominal stance trajectory at the
    state-based phase."""

    name = ControllerName.PASSIVE

    def __init__(self, ctx: ControllerContext) -> None:
        super().__init__(ctx)
        self._law = ctx.terms.numeric["passive"]
        self._law.inputs[3][:] = ctx.passive_params

    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        tau, V = self._clf_terms(x)
        f = self._law
        f.inputs[0][:] = x
        f.inputs[1][0], f.inputs[2][0] = self._stance_phase(x[0], x[1])
        f.call_inplace()
        u = f.outputs[0] / self._gear  # joint -> motor N m
        return StanceResult(float(u[0]), float(u[1]), tau, V)


def stance_accelerations(t: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """The knee's and the ankle's accelerations (n, 2; rad/s^2) along a stance sampled at
    times ``t`` (n,) s with joint rates ``rates`` (n, 2) rad/s: the rates' central
    differences, median-filtered over :data:`ACCEL_FILTER` samples (the other foot's heel
    strike steps the prosthesis's rates within one period: unfiltered, one sample of
    thousands of rad/s^2 in the reference)."""
    d = np.gradient(np.asarray(rates, float), np.asarray(t, float), axis=0)
    return np.column_stack([medfilt(col, ACCEL_FILTER) for col in d.T])


class PassiveLaw:
    """Spong's law of ``passive_ref`` compiled for one device (its prosthesis alone, foot
    flat): joint torques (N m) about a reference (q_d, qd_d, qdd_d) with the gains of
    ``config`` and the device's standard parameters as theta0."""

    def __init__(self, model: HumanProsthesisModel, config: PassiveConfig | None = None,
                 backend: CompileBackend | str = CompileBackend.AUTO) -> None:
        sub = ProsthesisSubsystem(model)
        layout, fn = passive_reference_function(sub)
        c = config or PassiveConfig()
        links = [b.name for b in sub.tree.bodies if b.name != "p_foot"]
        self.config = c
        self.params = layout.pack(lam=c.lam, k=c.k, rho_theta=c.rho_theta,
                                  boundary=c.boundary,
                                  theta0=standard_parameters(sub.tree, links))
        self._fn = FunctionSet([fn], f"{sub.name}_passive_ref", backend)["passive_ref"]
        self._fn.inputs[2][:] = self.params

    def __call__(self, x: tuple[float, float, float, float], ref: tuple[float, ...]
                 ) -> tuple[float, float]:
        f = self._fn
        f.inputs[0][:] = x
        f.inputs[1][:] = ref
        f.call_inplace()
        u = f.outputs[0]
        return float(u[0]), float(u[1])


class ContactPassive(ContactPhasePD):
    """The paper's robust-passive baseline on the multi-contact graph: contact-pd's phase
    and swing, and in stance Spong's law (:class:`PassiveLaw`, the frozen gains of
    :class:`PassiveController`) about the gait's knee and ankle at the phase (``accel``: the
    stance table's accelerations at its phases, :func:`stance_accelerations`).  Its model is
    the prosthesis alone with its foot flat, the socket's force ignored, as the paper's: on
    the heel (``ds_p``) and the toe (``ps_toe``, ``ds_h``) too."""

    name = "passive"

    def __init__(self, tables: ContactGaitTables, leg: LegKinematics,
                 gear: tuple[float, float], limits: tuple[float, float], law: PassiveLaw,
                 accel: PhaseTable, swing: PDGains = SWING_GAINS,
                 swing_phase: str = DEFAULT_SWING_PHASE) -> None:
        super().__init__(tables, leg, gear, limits, swing=swing, swing_phase=swing_phase)
        if accel.values.shape != (len(tables.stance.phase), 2):
            raise ValueError(f"accel: {accel.values.shape} values for a stance table of "
                             f"{len(tables.stance.phase)} phases (need one pair each)")
        self.law, self.accel = law, accel

    def blended(self, other: ContactPhasePD, w: float) -> ContactPassive:
        if not isinstance(other, ContactPassive):
            raise TypeError(f"passive blends with passive, not {type(other).__name__}")
        b = np.column_stack([np.interp(self.accel.phase, other.accel.phase, col)
                             for col in other.accel.values.T])
        accel = PhaseTable(self.accel.phase.copy(), (1.0 - w) * self.accel.values + w * b)
        return ContactPassive(blend_tables(self.tables, other.tables, w), self.leg,
                              self.gear, self.limits, self.law, accel, self.swing_gains,
                              self.swing_phase)

    def torque(self, m: ProsthesisMeasurement, ref: tuple[float, ...]) -> tuple[float, float]:
        if not m.contact:
            return super().torque(m, ref)
        ak, aa = self.accel.at(self.phase)
        uk, ua = self.law((m.knee_angle, m.ankle_angle, m.knee_vel, m.ankle_vel),
                          (*ref[:4], ak, aa))
        if not (math.isfinite(uk) and math.isfinite(ua)):  # never a NaN: contact-pd's law
            self.fallbacks += 1
            return super().torque(m, ref)
        (gk, ga), (lk, la) = self.gear, self.limits
        return min(max(uk / gk, -lk), lk), min(max(ua / ga, -la), la)

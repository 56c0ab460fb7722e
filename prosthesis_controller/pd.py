"""The PD family: joint PD on the nominal stance trajectory (``pd``) and the phase-PD
reference (``phase-pd``), both on the state-based phase; and ``pd`` on the multi-contact
graph (:class:`ContactJointPD`: contact-pd's phase and swing, the paper's joint PD in stance).
See the package README, "Baselines and swing"."""

from __future__ import annotations

from hp_model.leg_kinematics import LegKinematics
from prosthesis_controller.base import BaseController, StanceResult, State
from prosthesis_controller.config import PdConfig
from prosthesis_controller.contact_phase_pd import (
    DEFAULT_SWING_PHASE,
    SWING_GAINS,
    ContactGaitTables,
    ContactPhasePD,
    PDGains,
    blend_tables,
)
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import ControllerName
from prosthesis_controller.measurement import ProsthesisMeasurement


class PDController(BaseController):
    """Joint PD on the nominal stance trajectory at the state-based phase."""

    name = ControllerName.PD

    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        tau, V = self._clf_terms(x)
        knee, ankle = self._pd_torque(x)
        return StanceResult(knee, ankle, tau, V)


class PhasePdController(BaseController):
    """Phase-PD reference (``terms.phase_pd``): nominal torque + knee PD + hip-velocity
    feedback through the ankle, on the state-based phase.  Not one of the paper's
    controllers: the closed-loop experiments use it to show what a controller with the
    prosthesis's own measurements achieves when its feedback has the full loop's sign."""

    name = ControllerName.PHASE_PD

    def __init__(self, ctx: ControllerContext) -> None:
        super().__init__(ctx)
        self._law = ctx.terms.numeric["phase_pd"]
        self._law.inputs[1][:] = ctx.phase_pd_params

    def _stance(self, t: float, since: float, x: State) -> StanceResult:
        _, V = self._clf_terms(x)
        f = self._law
        f.inputs[0][:] = x
        f.call_inplace()
        feedforward, feedback, tau = f.outputs[0], f.outputs[1], f.outputs[2]
        u = feedforward + feedback / self._gear  # motor N m; the feedback is joint-side
        return StanceResult(float(u[0]), float(u[1]), float(tau[0]), V)


def paper_pd_gains(config: PdConfig | None = None) -> PDGains:
    """The paper's ``pd`` gains (joint side) as contact-pd's stance gains."""
    c = config or PdConfig()
    return PDGains((float(c.kp[0]), float(c.kp[1])), (float(c.kd[0]), float(c.kd[1])))


class ContactJointPD(ContactPhasePD):
    """The paper's ``pd`` on the multi-contact graph: contact-pd's phase (the hip's progress
    over the foot in stance, the clock in swing) and swing, and in stance the joint PD of
    :class:`PDController` (its frozen gains, :class:`~prosthesis_controller.config.PdConfig`)
    about the gait's knee and ankle at the phase, no torque of the gait's (the paper's
    controllers share one swing and differ in stance)."""

    name = "pd"

    def __init__(self, tables: ContactGaitTables, leg: LegKinematics,
                 gear: tuple[float, float], limits: tuple[float, float],
                 stance: PDGains | None = None, swing: PDGains = SWING_GAINS,
                 swing_phase: str = DEFAULT_SWING_PHASE) -> None:
        super().__init__(tables, leg, gear, limits, stance or paper_pd_gains(), swing,
                         swing_phase)

    def blended(self, other: ContactPhasePD, w: float) -> ContactJointPD:
        return ContactJointPD(blend_tables(self.tables, other.tables, w), self.leg,
                              self.gear, self.limits, self.stance_gains, self.swing_gains,
                              self.swing_phase)

    def torque(self, m: ProsthesisMeasurement, ref: tuple[float, ...]) -> tuple[float, float]:
        if m.contact:
            ref = (*ref[:4], 0.0, 0.0)
        return super().torque(m, ref)

"""The PD family: joint PD on the nominal stance trajectory (``pd``) and the phase-PD
reference (``phase-pd``), both on the state-based phase.  See the package README,
"Baselines and swing"."""

from __future__ import annotations

from prosthesis_controller.base import BaseController, StanceResult, State
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import ControllerName


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

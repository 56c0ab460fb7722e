"""The robust-passive baseline (``passive``): Spong's robust passivity-based law, the
stand-in for Azimi et al. 2017 (``terms.passive``).  See the package README, "Baselines and
swing"."""

from __future__ import annotations

from prosthesis_controller.base import BaseController, StanceResult, State
from prosthesis_controller.context import ControllerContext
from prosthesis_controller.interface import ControllerName


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

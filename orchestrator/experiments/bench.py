"""What every closed-loop run of the paper's experiments shares (:class:`Bench`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hp_model.closed_loop import ClosedLoop
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from orchestrator.experiments.scenarios import Scenario, ScenarioResult, run_scenario
from prosthesis_controller import ControllerContext


@dataclass(frozen=True)
class Bench:
    """The model, the gait and force tube, the controllers' context (built once) and the
    closed loop (compiled once) of a set of runs."""

    model: HumanProsthesisModel
    gait: Gait
    tube: ForceTube
    ctx: ControllerContext
    closed_loop: ClosedLoop

    @classmethod
    def of(cls, model: HumanProsthesisModel, gait: Gait, tube: ForceTube) -> Bench:
        ctx = ControllerContext(gait, tube, model, None)
        return cls(model, gait, tube, ctx, ClosedLoop(model, gait.degree))

    def run(self, scenario: Scenario, **kw: Any) -> ScenarioResult:
        """:func:`~orchestrator.experiments.scenarios.run_scenario` on this bench (``kw``:
        its other options, e.g. the start state ``start``)."""
        return run_scenario(self.model, self.gait, self.tube, scenario, context=self.ctx,
                            closed_loop=self.closed_loop, **kw)

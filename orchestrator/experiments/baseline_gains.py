"""The baselines' gains, chosen once by a documented procedure (issue: fair baselines).

PD and robust-passive track the nominal stance trajectory as a function of the state-based
phase, as the paper's trajectories are.  Their gains are chosen on the nominal run of one
gait (the default subject's, ``hpcosim demo``) and then frozen for every other case:

    for every pair (stiffness, damping) of the grid, the same values for knee and ankle
    (joint side: PD kp [N m/rad], kd [N m s/rad]; passive Lambda [1/s], K [N m s/rad]),
    run the nominal scenario (20 steps, the human on its gait, 1 kHz hold); keep the pairs
    that walk all 20 steps; choose the one with the lowest knee RMS in ps.

``python -m orchestrator.experiments.baseline_gains --gait G --tube T`` prints the whole
grid and the choice (markdown); the chosen values are the defaults of ``PdConfig`` and
``PassiveConfig``.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from collections.abc import Sequence
from dataclasses import dataclass

from hp_model.domains import Domain
from hp_model.falls import Fall
from hp_model.force_tube import ForceTube
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from prosthesis_controller.interface import ControllerName

#: the grids (joint side, same value for knee and ankle)
PD_GRID = ((1500.0, 3000.0, 6000.0, 12000.0), (20.0, 60.0, 150.0, 300.0))
PASSIVE_GRID = ((10.0, 30.0, 60.0), (40.0, 150.0, 400.0, 1000.0))


@dataclass(frozen=True)
class GainResult:
    stiffness: float
    damping: float
    steps: int
    walks: bool
    knee_rms: float
    fall: Fall | None

    @property
    def end(self) -> str:
        """How the run ended, for the table: walks, or the fall's reason and time."""
        if self.walks:
            return "walks"
        if self.fall is None:
            return f"stopped after {self.steps} steps"
        return f"{self.fall.reason.label} at t = {self.fall.t:.3f} s"


def _config(controller: str, stiffness: float, damping: float):
    from prosthesis_controller import ControllerConfig
    from prosthesis_controller.config import PassiveConfig, PdConfig

    if controller == ControllerName.PD:
        return ControllerConfig(pd=PdConfig(kp=(stiffness, stiffness), kd=(damping, damping)))
    return ControllerConfig(passive=PassiveConfig(lam=(stiffness, stiffness),
                                                  k=(damping, damping)))


def grid_search(model: HumanProsthesisModel, gait: Gait, tube: ForceTube, controller: str,
                grid: Sequence[Sequence[float]], steps: int = 20) -> list[GainResult]:
    """Every pair of the grid on the nominal run (module docstring)."""
    from hp_model.closed_loop import ClosedLoop
    from orchestrator.experiments.scenarios import NOMINAL, Scenario, run_scenario
    from prosthesis_controller import ControllerContext

    cl = ClosedLoop(model, gait.degree)
    out = []
    for kp, kd in itertools.product(*grid):
        ctx = ControllerContext(gait, tube, model, _config(controller, kp, kd))
        r = run_scenario(model, gait, tube, Scenario(controller, NOMINAL, steps), context=ctx,
                         closed_loop=cl)
        out.append(GainResult(kp, kd, r.steps, r.success, r.knee_rms(Domain.PS), r.fall))
    return out


def choose(results: Sequence[GainResult]) -> GainResult | None:
    """The walking pair with the lowest knee RMS (None if none walks)."""
    walking = [r for r in results if r.walks]
    return min(walking, key=lambda r: r.knee_rms) if walking else None


def main(argv: list[str] | None = None) -> int:
    import hp_model
    from hp_model.artifacts import ArtifactError
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import load_gait

    ap = argparse.ArgumentParser(prog="python -m orchestrator.experiments.baseline_gains",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--gait", required=True)
    ap.add_argument("--tube", required=True)
    a = ap.parse_args(argv)
    model = hp_model.load_model()
    try:
        gait = load_gait(a.gait, model.parameter_hash())
        tube = load_tube(a.tube, gait.hash())
    except (ArtifactError, FileNotFoundError) as e:
        print(f"baseline_gains: error: {e}", file=sys.stderr)
        return 2
    for controller, grid, names in ((ControllerName.PD, PD_GRID, ("kp", "kd")),
                                    (ControllerName.PASSIVE, PASSIVE_GRID, ("Lambda", "K"))):
        res = grid_search(model, gait, tube, controller, grid)
        print(f"\n{controller}: | {names[0]} | {names[1]} | steps | knee RMS (rad) | end |")
        for r in res:
            print(f"| {r.stiffness:g} | {r.damping:g} | {r.steps} | {r.knee_rms:.4f} | "
                  f"{r.end} |")
        best = choose(res)
        print(f"chosen: {best}" if best else "chosen: none walks")
    return 0


if __name__ == "__main__":
    sys.exit(main())

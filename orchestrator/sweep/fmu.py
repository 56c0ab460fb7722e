"""The FMU backend of a sweep run: the human FMU (fmpy, in the worker's process) as the
plant of the one closed loop (:func:`orchestrator.loop.run_loop`), the prosthesis
controller in the loop, no bus in between.

The FMU is instantiated once per worker (:func:`open_fmu`) and restarted for every run; the
human's gait (perturbed thetas) and the initial state are set as parameters, so a run on
the FMU starts exactly where the simulator's run of the same draw starts, and the loop logs
the same samples as the simulator's (README of ``human_fmu`` for the falls the FMU decides
before integrating a step).

The run ends on the FMU's standard status (fmi2Discard with fmi2Terminated: a fall) or at
the scenario's steps; :func:`period_bound` bounds it besides, so an FMU that neither falls
nor steps (or discards without a fall code) can never hold a worker forever.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from human_fmu.instance import HumanFmu
from orchestrator.experiments.scenarios import Scenario, ScenarioResult, scenario_result
from orchestrator.loop import (
    IDEAL_ENCODER,
    ControllerLink,
    Encoder,
    FmuEndError,
    FmuPlant,
    run_loop,
)
from prosthesis_controller import ControllerContext, make_controller


def open_fmu(path: Path, workdir: Path, gait: Gait) -> HumanFmu:
    """The worker's FMU instance, extracted into ``workdir``; refuses an FMU built for
    another gait."""
    fmu = HumanFmu(path, unzipdir=workdir / "fmu", instance="sweep")
    try:
        fmu.check_gait(gait.hash())
    except ValueError:
        fmu.free()
        raise
    return fmu


def period_bound(fmu: HumanFmu, steps: int, dt: float) -> int:
    """The most periods a run of ``steps`` steps can take: the FMU ends a step that has no
    touchdown within its ``max_step_time`` (s) as a fall (phase stalled), so ``steps`` + 1
    such intervals, plus one period."""
    return math.ceil((steps + 1) * fmu.start_value("max_step_time") / dt) + 1


def run_fmu_scenario(fmu: HumanFmu, model: HumanProsthesisModel, gait: Gait,
                     ctx: ControllerContext, scenario: Scenario,
                     start: tuple[np.ndarray, np.ndarray], dt: float = 1e-3,
                     encoder: Encoder = IDEAL_ENCODER) -> ScenarioResult:
    """One scenario on the FMU (module docstring): the human tracks the scenario's thetas
    (``scenario.perturbation.thetas``) from ``start`` = (q0, qd0) in ps; the controller's
    measurements go through ``encoder``."""
    fmu.start_walk(scenario.perturbation.thetas(gait), *start)
    ctrl = make_controller(scenario.controller, gait, ctx.tube, model, context=ctx)
    bound = period_bound(fmu, scenario.steps, dt)
    log = run_loop(FmuPlant(fmu, dt), ControllerLink(ctrl, encoder), steps=scenario.steps,
                   periods=bound)
    if log.fall is None and not log.fault and log.steps < scenario.steps:
        raise FmuEndError(f"the FMU run neither fell nor completed {scenario.steps} steps in "
                       f"{bound} periods")
    return scenario_result(model, gait, ctx.tube, scenario, log)

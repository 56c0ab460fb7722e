"""A fitted multi-contact gait walked by a prosthesis controller from its own sensors
(``clfqp``: :class:`prosthesis_controller.contact_clf_qp.ContactClfQp`, the verdict's; the
baseline ``contact-pd``: :class:`prosthesis_controller.contact_phase_pd.ContactPhasePD`) in
the in-process plant (:class:`orchestrator.loop.plant.SimulatorPlant`: what AMPRO3 senses,
the torque held each period and bounded at the motors), the simulated human on its feedback
linearization.  The controllers are made as a co-simulation makes them
(:mod:`orchestrator.cosim.contact_controllers`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from characterization.gait.contact_gait import (
    GAINS,
    ContactGait,
    ContactWalk,
    start_state,
)
from characterization.gait.multicontact import GRAPH
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.leg_kinematics import LegKinematics
from hp_model.simulator import GaitSchedule, HybridSimulator, SimResult
from orchestrator.cosim.contact_controllers import (
    LoopSetup,
    contact_clfqp,
    held_walk,
    loop_simulator,
    phase_law,
)
from orchestrator.loop.link import IDEAL_ENCODER, Encoder, measurement
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller.contact_clf_qp import (
    DEFAULT_CONFIG,
    ContactClfConfig,
)
from prosthesis_controller.contact_phase_pd import (
    STANCE_GAINS,
    SWING_GAINS,
    PDGains,
    tables_from_walk,
)
from prosthesis_controller.interface import Controller, ControlOutput

#: how :func:`walk_with_contact_pd` runs the prosthesis
CONTACT_PD = ("the human on feedback linearization of the fitted gait, the prosthesis on "
              "contact-pd: joint PD and the gait's torque at a phase from its own sensors")

#: how :func:`walk_with_contact_clfqp` runs the prosthesis
CLFQP = ("the human on feedback linearization of the fitted gait, the prosthesis on clfqp: "
         "the interaction-aware robust CLF-QP at a phase from its own sensors")


def controller_run(sim: HybridSimulator, trajectory: Mapping[Domain, Mapping[str, Any]],
                   controller: Controller, steps: int,
                   encoder: Encoder = IDEAL_ENCODER,
                   on_output: Callable[[ControlOutput], None] | None = None,
                   gaits: GaitSchedule | None = None,
                   start: tuple[np.ndarray, np.ndarray] | None = None) -> SimResult:
    """The plant ``sim`` from the fitted cycle's start with the prosthesis on
    ``controller``, its sensors read through ``encoder`` (its noise from its seed), until
    ``steps`` steps, a fall or 2 s per step: the simulator's log (``on_output`` sees each
    tick's output; ``gaits``: the gait the person tracks in each domain it enters, e.g. a
    speed profile on a gait library; ``start``: (q0, qd0) instead of the cycle's start)."""
    q0, qd0 = start_state(trajectory) if start is None else start
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0], gaits=gaits)
    rng = np.random.default_rng(encoder.seed)
    while True:
        obs = plant.observe()
        out = controller.tick(measurement(obs, encoder, rng))
        if on_output is not None:
            on_output(out)
        plant.actuate(out.torque)
        if plant.fall is not None or plant.run.steps >= steps or obs.t >= 2.0 * steps:
            break
        plant.advance()
    return plant.run.result()


def contact_walk_of(res: SimResult, steps: int, description: str) -> ContactWalk:
    """The :class:`ContactWalk` of a run of ``steps`` asked: its strides from the human
    foot's heel strikes."""
    strikes = [i for i in res.impacts if i.into == Domain.DS_H]
    ts = np.array([i.t for i in strikes])
    xs = np.array([float(i.q[0]) for i in strikes])
    return ContactWalk(res.steps, steps, None if res.fall is None else res.fall.message(),
                       np.diff(ts), np.diff(xs) / np.diff(ts) if ts.size > 1 else np.array([]),
                       description)


def walk_controller(sim: HybridSimulator, trajectory: Mapping[Domain, Mapping[str, Any]],
                    controller: Controller, steps: int, description: str,
                    encoder: Encoder = IDEAL_ENCODER) -> ContactWalk:
    """Walk ``steps`` steps of the plant ``sim`` from the fitted cycle's start with the
    prosthesis on ``controller`` (``description``: the verdict's words for it), its sensors
    read through ``encoder`` (:func:`controller_run`)."""
    return contact_walk_of(controller_run(sim, trajectory, controller, steps, encoder), steps,
                           description)


def walk_with_contact_pd(model: HumanProsthesisModel, gait: ContactGait,
                         trajectory: Mapping[Domain, Mapping[str, Any]], steps: int = 10,
                         gains: tuple[float, float, float] = GAINS,
                         stance: PDGains = STANCE_GAINS, swing: PDGains = SWING_GAINS, *,
                         setup: LoopSetup | None = None) -> ContactWalk:
    """Walk ``gait`` ``steps`` steps with the prosthesis on :class:`ContactPhasePD`
    (``stance``, ``swing``: its gains); ``gains``: the simulated human's; ``setup``: the
    simulator and the held walk when made already."""
    sim = setup.sim if setup else loop_simulator(model, gait, gains)
    leg = LegKinematics.of(model)
    try:
        w = (setup and setup.held) or held_walk(sim, trajectory)
        tables = tables_from_walk(leg, w.t, w.sensed, w.contact, w.torque)
    except ValueError as e:  # the verdict line says why, no walk
        return ContactWalk(0, steps, f"no tables: {e}", np.array([]), np.array([]),
                           CONTACT_PD)
    return walk_controller(sim, trajectory, phase_law(model, tables, leg, stance, swing),
                           steps, CONTACT_PD)


def walk_with_contact_clfqp(model: HumanProsthesisModel, gait: ContactGait,
                            trajectory: Mapping[Domain, Mapping[str, Any]], steps: int = 10,
                            gains: tuple[float, float, float] = GAINS,
                            config: ContactClfConfig = DEFAULT_CONFIG, *,
                            setup: LoopSetup | None = None) -> ContactWalk:
    """Walk ``gait`` ``steps`` steps with the prosthesis on :class:`ContactClfQp`
    (``setup``: as :func:`walk_with_contact_pd`)."""
    setup = setup or LoopSetup(loop_simulator(model, gait, gains), None)
    sim = setup.sim
    try:
        ctl = contact_clfqp(model, gait, trajectory, gains, config, setup=setup)
    except ValueError as e:
        return ContactWalk(0, steps, f"no tables: {e}", np.array([]), np.array([]), CLFQP)
    return walk_controller(sim, trajectory, ctl, steps, CLFQP)


def walk_prosthesis_controllers(model: HumanProsthesisModel, gait: ContactGait,
                                trajectory: Mapping[Domain, Mapping[str, Any]],
                                steps: int = 10) -> tuple[ContactWalk, ContactWalk]:
    """``clfqp``'s walk and contact-pd's, on one simulator and one held walk."""
    sim = loop_simulator(model, gait, GAINS)
    try:
        setup = LoopSetup(sim, held_walk(sim, trajectory))
    except ValueError:  # each walk then says why in its line
        setup = LoopSetup(sim, None)
    return (walk_with_contact_clfqp(model, gait, trajectory, steps, setup=setup),
            walk_with_contact_pd(model, gait, trajectory, steps, setup=setup))

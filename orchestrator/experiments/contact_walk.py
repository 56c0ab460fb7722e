"""A fitted multi-contact gait walked by a prosthesis controller from its own sensors
(:class:`prosthesis_controller.contact_phase_pd.ContactPhasePD`) in the in-process plant
(:class:`orchestrator.loop.plant.SimulatorPlant`: what AMPRO3 senses, the torque held each
period and bounded at the motors), the simulated human on its feedback linearization.

The controller's tables come from one stride of the same plant with the prosthesis holding
the full feedback linearization's torque (:func:`characterization.gait.contact_gait.held_oracle`),
sensed the same way: the gait as the model walks it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from characterization.gait.contact_gait import (
    GAINS,
    ContactGait,
    ContactWalk,
    held_oracle,
    start_state,
)
from characterization.gait.multicontact import GRAPH
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import HybridSimulator
from orchestrator.loop.link import measurement
from orchestrator.loop.plant import SimulatorPlant
from prosthesis_controller.contact_phase_pd import (
    STANCE_GAINS,
    SWING_GAINS,
    ContactGaitTables,
    ContactPhasePD,
    LegKinematics,
    PDGains,
    tables_from_walk,
)

#: how :func:`walk_with_contact_pd` runs the prosthesis
CONTACT_PD = ("the human on feedback linearization of the fitted gait, the prosthesis on "
              "contact-pd (joint PD and the gait's torque at a phase from its own sensors)")


def loop_simulator(model: HumanProsthesisModel, gait: ContactGait,
               gains: tuple[float, float, float]) -> HybridSimulator:
    """The in-process simulator of ``gait`` with the human's ``gains`` (eps, kp, kd)."""
    cl = ClosedLoop(model, gait.params[GRAPH.domains[0]].degree)
    return HybridSimulator(model, cl, gait.thetas(), np.array(gains))


def controller_tables(sim: HybridSimulator, leg: LegKinematics,
                      trajectory: Mapping[Domain, Mapping[str, Any]]) -> ContactGaitTables:
    """The tables of :func:`tables_from_walk` from two strides of the held oracle in the
    plant ``sim`` from the fitted cycle's start (a stride: the trajectory's domains' ends
    ``t``, s).  ValueError if it falls, or if the walk gives no tables."""
    stride = sum(float(np.asarray(trajectory[d]["t"])[-1]) for d in GRAPH.domains)
    q0, qd0 = start_state(trajectory)
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0])
    policy = held_oracle(sim.cl, {Domain(d): th for d, th in sim.thetas.items()}, sim.gains)
    t, x, c, u = [], [], [], []
    while plant.observe().t < 2.0 * stride + 0.1:
        obs = plant.observe()
        torque = policy(obs.t, plant.run.observe())
        s = obs.sensed
        t.append(obs.t)
        x.append((s.socket_pitch, s.knee_angle, s.ankle_angle, s.knee_velocity,
                  s.ankle_velocity))
        c.append(s.contact)
        u.append(plant.actuate(torque).torque)
        if plant.fall is not None:
            raise ValueError(f"the held oracle fell in the stride the tables are read from: "
                             f"{plant.fall.message()}")
        plant.advance()
    return tables_from_walk(leg, np.array(t), np.array(x), np.array(c), np.array(u))


def walk_with_contact_pd(model: HumanProsthesisModel, gait: ContactGait,
                         trajectory: Mapping[Domain, Mapping[str, Any]], steps: int = 10,
                         gains: tuple[float, float, float] = GAINS,
                         stance: PDGains = STANCE_GAINS, swing: PDGains = SWING_GAINS
                         ) -> ContactWalk:
    """Walk ``gait`` ``steps`` steps with the prosthesis on :class:`ContactPhasePD`
    (``stance``, ``swing``: its gains); ``gains``: the simulated human's."""
    sim = loop_simulator(model, gait, gains)
    leg = LegKinematics.of(model)
    p = model.device.prosthesis
    try:
        tables = controller_tables(sim, leg, trajectory)
    except ValueError as e:  # the verdict line says why, no walk
        return ContactWalk(0, steps, f"no tables: {e}", np.array([]), np.array([]),
                           CONTACT_PD)
    ctl = ContactPhasePD(tables, leg,
                         (p.knee.gear_ratio.value, p.ankle.gear_ratio.value),
                         (p.knee.torque_limit.value, p.ankle.torque_limit.value), stance, swing)
    q0, qd0 = start_state(trajectory)
    plant = SimulatorPlant(sim, q0, qd0, GRAPH.domains[0])
    while True:
        obs = plant.observe()
        plant.actuate(np.array(ctl.tick(measurement(obs))))
        if plant.fall is not None or plant.run.steps >= steps or obs.t >= 2.0 * steps:
            break
        plant.advance()
    res = plant.run.result()
    strikes = [i for i in res.impacts if i.into == Domain.DS_H]
    ts = np.array([i.t for i in strikes])
    xs = np.array([float(i.q[0]) for i in strikes])
    return ContactWalk(res.steps, steps, None if res.fall is None else res.fall.message(),
                       np.diff(ts), np.diff(xs) / np.diff(ts) if ts.size > 1 else np.array([]),
                       CONTACT_PD)

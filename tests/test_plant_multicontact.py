"""The in-process plant on the multi-contact graph senses what AMPRO3 would: the foot switch on
whenever the prosthesis foot touches the ground (on its heel, flat or on its toe), the load cell
that contact's normal force, and the ground truth's socket wrench from the domain's own rows."""

from __future__ import annotations

import itertools

import numpy as np

from characterization.gait.contact_gait import GAINS, contact_gait_of, start_state
from hp_model.closed_loop import ClosedLoop, ClosedLoopMode
from hp_model.domains import Domain, DomainGraph
from hp_model.simulator import HybridSimulator
from orchestrator.loop.plant import SimulatorPlant, wrench_rows
from tests.multicontact_cycle import load_cycle

G = 9.81


def test_the_prosthesis_senses_its_own_contacts_over_a_stride() -> None:
    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    sim = HybridSimulator(model, ClosedLoop(model, 5), gait.thetas(), np.array(GAINS))
    q0, qd0 = start_state(traj)
    plant = SimulatorPlant(sim, q0, qd0, DomainGraph.MULTICONTACT.domains[0],
                           mode=ClosedLoopMode.FULL)
    rows = wrench_rows(model)
    weight = model.tree.total_mass * G
    loads: dict[Domain, list[float]] = {d: [] for d in model.graph.domains}
    ticks: list[tuple[Domain, float]] = []
    while plant.observe().t < 1.3:  # more than a stride
        obs = plant.observe()
        truth = plant.actuate(None)
        lam = plant.run.observe().lam
        d = obs.domain
        contact = d.prosthesis_contact
        assert obs.sensed.contact == (contact is not None), d
        if contact is None:
            assert obs.sensed.foot_load == 0.0
        else:  # the prosthesis contact's own F_z, by the constraint's name
            fz = lam[model.domains[d].wrench_slice(contact.name)][1]
            assert obs.sensed.foot_load == max(fz, 0.0)
        np.testing.assert_array_equal(truth.socket_force,
                                      lam[model.domains[d].wrench_slice("socket")])
        assert rows[d].socket.stop - rows[d].socket.start == 3
        loads[d].append(obs.sensed.foot_load)
        ticks.append((d, obs.sensed.foot_load))
        plant.advance()
    assert all(loads[d] for d in model.graph.domains)  # every domain visited
    # the prosthesis's single support carries the walker: over it the mean load is within
    # 20 % of its weight (the body's centre falls and rises again), every sample within a
    # person's double hump (0.5-1.5 weights: valley about 0.7, peaks 1.1-1.3)
    # (the tick of a heel strike, whose load is the impact's, left out)
    single = np.array([f for (d, f), (nxt, _) in itertools.pairwise(ticks)
                       if d in (Domain.PS, Domain.PS_TOE) and nxt == d]) / weight
    assert abs(single.mean() - 1.0) < 0.2, single.mean()
    assert single.min() > 0.5 and single.max() < 1.5, (single.min(), single.max())
    # the double supports share it: the prosthesis foot bears part of the weight
    for d in (Domain.DS_H, Domain.DS_P):
        assert 0.0 < np.mean(loads[d]) < 1.5 * weight, (d, np.mean(loads[d]) / weight)

"""The multi-contact loop with the prosthesis's torque given from outside (mode human, what a
prosthesis controller drives): a prosthesis that applies the oracle's torque, held over each
1 ms period like a controller's and within the motors' limits, walks the oracle's walk,
every contact watched (a double support's trailing foot leaves when it would pull:
hp_model.simulator).  The committed cycle is fitted with a margin under the motors (the fit's
``motor_margin``): fitted at the limits, the ankle saturated through the push-off and the
walker fell at the first heel strike.

The human's rows in each double support (hp_model.contact_outputs) are the ones its four
torques can hold on the walk: with the squeeze among its rows in ``ds_p`` they went singular
4 ms into it (both knees nearly straight), and the held oracle fell in the second step with
the prosthesis heel pulling 0.48 kN."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of, held_oracle, start_state
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain, DomainGraph
from hp_model.simulator import HybridSimulator, SimResult
from tests.multicontact_cycle import load_cycle

G = 9.81
pytestmark = pytest.mark.slow  # about a minute: a model of its own (compiled once)


@pytest.fixture(scope="module")
def loop():
    model, traj, durations, _ = load_cycle()
    gait = contact_gait_of(model, traj, durations)
    cl = ClosedLoop(model, 5)
    sim = HybridSimulator(model, cl, gait.thetas(), np.array(GAINS))
    return model, traj, cl, sim


def _held(traj, cl, sim, steps: int) -> SimResult:
    q0, qd0 = start_state(traj)
    return sim.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=steps,
                   duration=2.0 * steps, policy=held_oracle(cl, sim.thetas, sim.gains))


def test_a_prosthesis_holding_the_oracles_torque_walks_the_oracles_walk(loop) -> None:
    model, traj, cl, sim = loop
    steps = 6
    held = _held(traj, cl, sim, steps)
    q0, qd0 = start_state(traj)
    full = sim.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=steps,
                   duration=2.0 * steps)
    assert held.fall is None and held.steps == steps and full.fall is None
    # the same gait: each step's duration within 3 % and length within 1 % of the oracle's
    # (the torque held 1 ms instead of evaluated at every Runge-Kutta stage, and clamped to
    # the motors' limits, moves the limit cycle a little)
    def steps_of(res):  # (durations s, lengths m) of the steps after the first heel strike
        strikes = [i for i in res.impacts if i.starts_step]
        t, x = np.array([i.t for i in strikes]), np.array([i.q[0] for i in strikes])
        return np.diff(t), np.diff(x)

    (dt_h, dx_h), (dt_f, dx_f) = steps_of(held), steps_of(full)
    np.testing.assert_allclose(dt_h, dt_f, rtol=0.03)
    np.testing.assert_allclose(dx_h, dx_f, rtol=0.01)
    # and every contact of a double support bears load: a heel strike starts from zero
    # load, so the 1 ms hold may pull on it for a period or two (the fall check allows
    # five); the trailing foot leaves within the period its load crosses zero
    weight = model.tree.total_mass * G
    for d in (Domain.DS_H, Domain.DS_P):
        rows = held.domain == d.code
        assert held.lam[rows, 1].min() > -0.05 * weight, d
        assert held.lam[rows, d.contacts[0].size + 1].min() > -0.03 * weight, d


def test_the_humans_rows_are_well_conditioned_on_the_walk(loop) -> None:
    """Rows scaled to unit size, the human's block of the decoupling matrix (its rows, its
    four torques) keeps a condition number below 300 in every double-support period of the
    oracle's walk (with the squeeze among ``ds_p``'s rows it reached 3900)."""
    _, traj, cl, sim = loop
    q0, qd0 = start_state(traj)
    res = sim.run(q0, qd0, DomainGraph.MULTICONTACT.domains[0], steps=2, duration=4.0)
    assert res.fall is None
    for d in (Domain.DS_H, Domain.DS_P):
        A_of = cl.vcs[d].decoupling
        worst = 0.0
        for k in np.flatnonzero(res.domain == d.code):
            A = np.array(A_of(res.q[k], res.qd[k], sim.thetas[d]))
            A = A / np.abs(A).max(axis=1, keepdims=True)
            worst = max(worst, float(np.linalg.cond(A[list(d.human_outputs), :4])))
        assert worst < 300, (d, worst)

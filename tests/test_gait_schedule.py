"""The person choosing its gait as it walks (``hp_model/simulator.py``, ``GaitSchedule``):
the simulator asks the schedule at each domain it enters, the run tracks what it gives and
the held oracle follows; and the commanded speed over time (``hp_model/speed_profile.py``)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of, held_oracle, start_state
from characterization.gait.multicontact import GRAPH
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.simulator import HybridSimulator
from hp_model.speed_profile import SpeedProfile
from orchestrator.experiments.contact_perturbations import paced


@pytest.fixture(scope="module")
def person():
    c = load_contact_cycle(REFERENCE_PERSON_GAIT)
    gait = contact_gait_of(c.model, c.trajectory, c.durations)
    cl = ClosedLoop(c.model, 5)
    return c, gait, cl


def _run(person, thetas, steps, gaits=None, seen=None):
    c, _, cl = person
    sim = HybridSimulator(c.model, cl, thetas, np.array(GAINS))
    oracle = held_oracle(cl, thetas, np.array(GAINS))

    def policy(t, st):
        if seen is not None:
            seen.append((t, st.domain, st.theta))
        return oracle(t, st)

    return sim.run(*start_state(c.trajectory), GRAPH.domains[0], steps=steps,
                   duration=2.0 * steps, policy=policy, gaits=gaits)


def test_a_schedule_of_the_simulators_own_gait_changes_nothing(person):
    _, gait, _ = person
    th = gait.thetas()
    asked = []

    def same(d, t):
        asked.append((d, t))
        return th[d]

    a, b = _run(person, th, 3), _run(person, th, 3, same)
    assert a.fall is None and b.fall is None
    assert np.array_equal(a.q, b.q) and np.array_equal(a.u, b.u)  # bit for bit
    # asked at the start and at every domain entered, in the graph's order
    assert asked[0] == (GRAPH.domains[0], 0.0)
    order = [d for d, _ in asked]
    assert all(GRAPH.next(p) == n for p, n in itertools.pairwise(order))
    assert len(asked) == 1 + sum(1 for _ in a.impacts) + sum(
        1 for d in (Domain.PS_TOE, Domain.PNS_TOE) for k in range(1, len(a.domain))
        if a.domain[k] == d.code and a.domain[k - 1] != d.code)


def test_the_person_walks_faster_from_when_its_schedule_says(person):
    """From 1.5 s the person takes the gait paced 5 % faster: the oracle sees it in the
    state's theta, and the strides after the switch are faster by about that much."""
    _, gait, _ = person
    th, fast = gait.thetas(), paced(gait, 1.05).thetas()
    seen = []
    res = _run(person, th, 12, lambda d, t: (fast if t >= 1.5 else th)[d], seen)
    assert res.fall is None
    after = [(t, d, theta) for t, d, theta in seen if t > 2.5]
    assert after and all(np.array_equal(theta, fast[d]) for _, d, theta in after)
    strikes = [i for i in res.impacts if i.into == Domain.DS_H]
    t = np.array([i.t for i in strikes])
    x = np.array([float(i.q[0]) for i in strikes])
    v = np.diff(x) / np.diff(t)
    assert v[-1] == pytest.approx(1.05 * v[0], rel=0.02)


def test_a_schedule_giving_no_gait_of_the_domain_is_refused(person):
    _, gait, _ = person
    th = gait.thetas()
    with pytest.raises(ValueError, match=r"gait schedule gave ps at t = 0\.000 s"):
        _run(person, th, 2, lambda d, t: th[d][:-1])
    with pytest.raises(ValueError, match=r"gait schedule gave ps_toe .* non-finite"):
        _run(person, th, 2, lambda d, t: th[d] * (np.nan if d == Domain.PS_TOE else 1.0))


def test_a_speed_profile_is_linear_between_its_knots_and_held_outside():
    p = SpeedProfile.parse("0:0.8, 20:1.2,40:0.8")
    assert [p.at(t) for t in (-1, 0, 10, 20, 30, 40, 99)] == pytest.approx(
        [0.8, 0.8, 1.0, 1.2, 1.0, 0.8, 0.8])
    assert SpeedProfile.parse(p.text()) == p
    assert SpeedProfile.parse("1.1") == SpeedProfile.constant(1.1)
    for bad, why in (("0:0.8,0:1.0", "increase"), ("0:5", "within"), ("0-0.8", "time:speed"),
                     ("0:nan", "finite"), ("", "time:speed")):
        with pytest.raises(ValueError, match=why):
            SpeedProfile.parse(bad)

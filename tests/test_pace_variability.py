"""The simulated person's pace varying from stride to stride
(``characterization/gait/pace_variability.py``): its curves, when it draws, and how much its
strides vary; the ``stride`` family of the perturbation experiments."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, contact_gait_of, held_oracle, start_state
from characterization.gait.multicontact import GRAPH
from characterization.gait.multicontact_artifact import load_contact_cycle
from characterization.gait.pace_variability import PACE_DOMAIN, paced_theta, varying_pace
from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.simulator import HybridSimulator
from orchestrator.experiments.contact_perturbations import STRIDE_CV, draw, paced


@pytest.fixture(scope="module")
def person():
    c = load_contact_cycle(REFERENCE_PERSON_GAIT)
    return c, contact_gait_of(c.model, c.trajectory, c.durations)


def test_a_paced_theta_is_the_paced_gaits(person):
    _, gait = person
    for d, th in gait.thetas().items():
        assert np.array_equal(paced_theta(d, th, 1.07, 5), paced(gait, 1.07).thetas()[d])
    assert np.array_equal(paced_theta(Domain.PS_TOE, gait.thetas()[Domain.PS_TOE], 1.07, 5),
                          gait.thetas()[Domain.PS_TOE])  # no hip-rate row on a toe


def test_the_pace_is_drawn_entering_the_persons_own_stance(person):
    _, gait = person
    th = gait.thetas()
    f = varying_pace(th, 0.05, seed=3, degree=5)
    assert np.array_equal(f(GRAPH.domains[0], 0.0), th[GRAPH.domains[0]])  # its own pace
    assert np.array_equal(f(PACE_DOMAIN, 0.0), th[PACE_DOMAIN])  # not at the start
    drawn = f(PACE_DOMAIN, 1.0)
    k = float(np.exp(np.random.default_rng(3).normal(0.0, 0.05)))
    assert np.array_equal(drawn, paced_theta(PACE_DOMAIN, th[PACE_DOMAIN], k, 5))
    assert np.array_equal(f(Domain.DS_P, 1.3), paced_theta(Domain.DS_P, th[Domain.DS_P], k, 5))
    with pytest.raises(ValueError, match="pace variation"):
        varying_pace(th, -0.1, 0, 5)


def test_the_persons_strides_vary_by_about_its_cv(person):
    """40 steps at 3 %: the strides' coefficient of variation (from one flat landing of the
    person's foot to the next: one pace each) is within a factor 1.5 of the paces' drawn
    (the toe domains' durations, their zero dynamics', do not scale with the pace), and the
    person walks them with the held oracle."""
    c, gait = person
    cl = ClosedLoop(c.model, 5)
    th = gait.thetas()
    sim = HybridSimulator(c.model, cl, th, np.array(GAINS))
    res = sim.run(*start_state(c.trajectory), GRAPH.domains[0], steps=40, duration=80.0,
                  policy=held_oracle(cl, th, np.array(GAINS)),
                  gaits=varying_pace(th, 0.03, seed=3, degree=5))
    assert res.fall is None, res.fall.message()
    t = np.array([i.t for i in res.impacts if i.into == PACE_DOMAIN])
    strides = np.diff(t)
    paces = np.exp(np.random.default_rng(3).normal(0.0, 0.03, strides.size))
    ratio = (strides.std() / strides.mean()) / ((1 / paces).std() / (1 / paces).mean())
    assert 1 / 1.5 < ratio < 1.5


def test_the_stride_family_draws_a_cv_and_a_seed(person):
    _, gait = person
    d = draw(gait, "stride", 0.5, 7)
    assert d.stride_cv == pytest.approx(0.5 * STRIDE_CV) and d.stride_seed == 7
    assert d.schedule() is not None and draw(gait, "pace", 1.0, 7).schedule() is None

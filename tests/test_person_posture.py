"""The simulated person with a posture of its own (issue 38): its curves offset as the sweep's
``human.output_offset`` draws them, walked with the held oracle.  The person yields its
feedback to its contacts (``hp_model.contact_outputs.feedback_share``); before it did, these
draws fell in their first steps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from characterization.gait.contact_gait import GAINS, held_oracle, start_state
from characterization.gait.multicontact import GRAPH
from characterization.gait.person_synth import REFERENCE_PERSON_GAIT
from hp_model.domains import Domain
from hp_model.simulator import HybridSimulator
from orchestrator.cosim.contact_controllers import load_contact_run, loop_simulator
from orchestrator.sweep.contact import draw_gait, posture_start, prosthesis_start
from orchestrator.sweep.draws import HUMAN_JOINTS, Draw


def _walk(run, cl, thetas, offsets=(0.0, 0.0, 0.0, 0.0)):
    """10 steps of the person tracking ``thetas`` with the held oracle, from the cycle's start
    in its posture (``offsets``, as the sweep starts it): (the log, its strides between the
    human's heel strikes (s) and their speeds (m/s))."""
    sim = HybridSimulator(run.model, cl, thetas, np.array(GAINS))
    held = {Domain(k): v for k, v in sim.thetas.items()}
    log = sim.run(*posture_start(sim, start_state(run.trajectory), offsets), GRAPH.domains[0],
                  steps=10, duration=20.0, policy=held_oracle(cl, held, sim.gains))
    strikes = [i for i in log.impacts if i.into == Domain.DS_H]
    t, x = np.array([i.t for i in strikes]), np.array([float(i.q[0]) for i in strikes])
    return log, np.diff(t), np.diff(x) / np.diff(t)


@pytest.fixture(scope="module")
def person():
    run = load_contact_run(REFERENCE_PERSON_GAIT)
    cl = loop_simulator(run.model, run.gait, GAINS).cl
    log, strides, speeds = _walk(run, cl, {d.value: th for d, th in run.gait.thetas().items()})
    assert log.fall is None, log.fall
    return run, cl, float(np.median(strides)), float(np.median(speeds))


@pytest.mark.parametrize("offsets_deg", [(-0.93, 0.03, -0.07, 0.84),  # fell: toe landing
                                         (0.89, 0.81, 0.14, -0.71),  # fell: heel slipped
                                         # fell: the person's heel 30 ms later than the
                                         # prosthesis toe's 0.1-s domain, past tau 1.3
                                         (-0.867, -0.91, 0.841, 0.791),
                                         # fell started on the cycle's posture (its stance
                                         # foot out of its cone in 0.14 s), then its heel
                                         # unseen through the ground early in ps_toe
                                         (2.427, 2.365, -2.726, -2.540)])
def test_a_person_with_a_posture_of_its_own_walks(person, offsets_deg) -> None:
    """Offsets of up to 1 deg (one draw of 3 deg) on th_lh, th_lk, th_la, th_rh, the person
    started in its posture: 10 steps with the held oracle.  From the third stride on its
    speed is within 2 % per degree of the largest offset of the nominal walk's (the hip's
    rate is an output of every flat stance, not of the toe and double-support domains whose
    length moves with the posture) and its stride within 5 % per degree (1 deg at each of
    the leg's joints is about 3 cm of a 1.2 m stride)."""
    run, cl, stride, speed = person
    off = tuple(math.radians(v) for v in offsets_deg)
    log, strides, speeds = _walk(run, cl, draw_gait(run.gait, Draw("posture", 0,
                                                                   output_offset=off)), off)
    assert log.fall is None and log.steps >= 10, log.fall
    per_degree = max(1.0, max(abs(v) for v in offsets_deg))
    np.testing.assert_allclose(speeds[2:], speed, rtol=0.02 * per_degree)
    np.testing.assert_allclose(strides[2:], stride, rtol=0.05 * per_degree)


def test_a_start_with_the_prosthesis_moved_stands_on_its_foot_and_the_curves(person):
    """``initial.knee`` / ``initial.ankle`` on the person's graph (``prosthesis_start``): the
    prosthesis's stance knee and ankle moved by the offsets exactly, the stance sole flat on
    the ground where the cycle's start has it and at rest, the human's joints on the curves
    at the moved phase (their outputs zero), the prosthesis's knee off its curve by about
    its offset (the phase moves with the hip, less than the knee)."""
    run, cl, _, _ = person
    sim = HybridSimulator(run.model, cl, run.gait.thetas(), np.array(GAINS))
    start = start_state(run.trajectory)
    assert prosthesis_start(sim, start, 0.0, 0.0) is start
    knee, ankle = 0.03, -0.02
    q, qd = prosthesis_start(sim, start, knee, ankle)
    names = run.model.coord_names
    assert q[names.index("th_pk")] - start[0][names.index("th_pk")] == pytest.approx(knee)
    assert q[names.index("th_pa")] - start[0][names.index("th_pa")] == pytest.approx(ankle)
    domain = GRAPH.domains[0]
    sole = run.model.frame_index(run.model.stance_frame(domain))
    pose, vel = (np.array(a, float) for a in sim.mfs["frames"](q, qd))
    pose0 = np.array(sim.mfs["frames"](*start)[0], float)
    np.testing.assert_allclose(pose[:, sole], [pose0[0, sole], 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(vel[:, sole], 0.0, atol=1e-9)
    _, y2, dy2, tau = (np.array(a, float).ravel()
                       for a in sim.fs[f"outputs_{domain}"](q, qd, sim.thetas[domain]))
    human = [i for i, c in enumerate(domain.y2_coords) if c in HUMAN_JOINTS]
    np.testing.assert_allclose(y2[human], 0.0, atol=1e-9)
    np.testing.assert_allclose(dy2[human], 0.0, atol=1e-9)
    assert 0.3 * knee < y2[domain.y2_coords.index("th_pk")] < 1.5 * knee
    assert tau[0] != pytest.approx(sim.phase(domain, start[0]), abs=1e-3)


def test_the_walkability_oracle_walks_a_start_with_the_prosthesis_moved(person):
    """The sweep's oracle from the prosthesis's knee flexed 2.1 deg and its ankle moved -0.4
    deg (a draw of ``initial.knee``/``initial.ankle`` U(-0.04, 0.04) where the held oracle
    fell in its first stance, 0.14 s: its feedback linearization asked both motors for more
    than their limits from the first period, the clamped torques lost the hip's rate and
    the stance foot slid).  Yielding its feedback at the limits it walks 10 steps; its
    torques are within the motors' limits, and equal the held oracle's where those are."""
    run, cl, _, _ = person
    sim = HybridSimulator(run.model, cl, run.gait.thetas(), np.array(GAINS))
    thetas = {Domain(k): v for k, v in sim.thetas.items()}
    held = held_oracle(cl, thetas, sim.gains)
    oracle = held_oracle(cl, thetas, sim.gains, within_limits=True)
    limits = run.model.torque_limits[4:6]
    cut = []

    def policy(t, st):
        u, u_held = np.array(oracle(t, st)), np.array(held(t, st))
        assert np.all(np.abs(u) <= limits + 1e-12)
        if np.all(np.abs(u_held) <= limits):
            np.testing.assert_array_equal(u, u_held)
        else:
            cut.append(t)
        return u

    log = sim.run(*prosthesis_start(sim, start_state(run.trajectory), 0.037, -0.007),
                  GRAPH.domains[0], steps=10, duration=20.0, policy=policy)
    assert log.fall is None and log.steps >= 10, log.fall
    assert cut and min(cut) == 0.0  # the start asked past the limits

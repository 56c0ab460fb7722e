"""The hybrid simulator on an optimized gait: events located on the ground, impacts that
match the optimizer's, a stable periodic orbit (issue 4 evidence)."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait_fit import verify_gait
from characterization.gait_verification import make_simulator, simulate_gait
from hp_model.simulator import SimOptions

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def run20(model, template_gait):
    sim = make_simulator(model, template_gait)
    return sim, simulate_gait(sim, template_gait, steps=20)


def test_twenty_steps_without_a_fall(run20):
    _, r = run20
    assert not r.failed, r.reason
    assert r.steps == 20
    assert [i.into for i in r.impacts[:2]] == ["pns", "ps"]


def test_impacts_are_located_on_the_ground(model, run20):
    """The swing sole is at height 0 (event_tol) at every located impact, and flat up to the
    small residual pitch the touchdown correction removes."""
    _, r = run20
    fs = model.numeric()
    for imp in r.impacts:
        pose = fs["frames"](imp.q, imp.qd_minus)[0]
        frame = "p_sole" if imp.into == "ps" else "l_sole"
        assert abs(pose[1, model.frame_index(frame)]) < 1e-6
        assert abs(pose[2, model.frame_index(frame)]) < 1e-9  # flattened
        assert abs(imp.foot_pitch) < 0.02


def test_first_cycle_reproduces_the_collocation(template_gait, run20):
    """Durations within one integration step plus the collocation's discretisation error."""
    _, r = run20
    t = [i.t for i in r.impacts]
    assert t[0] == pytest.approx(template_gait.durations["ps"], abs=3e-3)
    assert t[1] - t[0] == pytest.approx(template_gait.durations["pns"], abs=3e-3)
    end = template_gait.trajectory["ps"]
    np.testing.assert_allclose(r.impacts[0].q[3:], end["q"][3:, -1], atol=2e-3)


def test_periodic_and_stable(model, template_gait):
    v = verify_gait(model, template_gait, steps=20)
    assert v["stable_20_steps"], v
    assert v["spectral_radius"] < 1.0
    assert v["fixed_point_residual"] < 1e-6


def test_event_location_does_not_depend_on_the_step_size(model, template_gait):
    """Impact times converge as h shrinks (event location, not step-boundary detection):
    the default h = 0.5 ms against h / 4.  (At h = 1 ms the RK4 of the template gait's stiff
    human tracking, kp = 1600, is not accurate enough to walk: it falls at the first impact.)"""
    times = []
    for sub in (2, 8):
        sim = make_simulator(model, template_gait, options=SimOptions(substeps=sub))
        r = simulate_gait(sim, template_gait, steps=2)
        assert not r.failed and r.steps == 2, r.reason
        times.append([i.t for i in r.impacts])
    np.testing.assert_allclose(times[0], times[1], atol=1e-5)


def test_a_policy_holds_its_torque_and_a_bad_one_falls(model, template_gait):
    """Human-side FL with a zero prosthesis torque cannot walk: the run ends as a fall with a
    reason, not an exception."""
    sim = make_simulator(model, template_gait)
    tr = template_gait.trajectory["ps"]
    r = sim.run(tr["q"][:, 0], tr["qd"][:, 0], "ps", steps=4, policy=lambda t, s: np.zeros(2))
    assert r.failed and r.reason
    assert np.all(r.u[:, 4:] == 0.0)


def test_a_stalled_phase_ends_the_run_and_an_impact_restarts_its_clock(model, template_gait,
                                                                       run20):
    """``max_step_time``: no touchdown within it of the start or of the last impact is a fall
    (a walker standing still would otherwise be simulated forever); each impact restarts the
    clock, so a limit just above the longest step lets the nominal gait walk on."""
    _, nominal = run20
    t_imp = np.array([0.0] + [i.t for i in nominal.impacts[:4]])
    longest = float(np.diff(t_imp).max())
    tr = template_gait.trajectory["ps"]
    limit = 0.5 * longest
    sim = make_simulator(model, template_gait, options=SimOptions(max_step_time=limit))
    r = simulate_gait(sim, template_gait, steps=4)
    assert r.failed and "phase stalled" in r.reason and r.steps == 0
    assert r.t[-1] == pytest.approx(np.ceil(limit / 1e-3 + 1e-9) * 1e-3, abs=1.5e-3)
    sim = make_simulator(model, template_gait,
                         options=SimOptions(max_step_time=longest + 0.01))
    r = simulate_gait(sim, template_gait, steps=4)
    assert not r.failed, r.reason
    assert r.steps == 4 and tr["q"].shape[0] == model.nq


def test_a_diverging_state_ends_the_run_before_it_turns_non_finite(model, template_gait,
                                                                   run20):
    """``max_speed``: a generalized speed above it is a fall ("state diverged"); the nominal
    gait stays far below the default (200 m/s or rad/s; the quick template gait peaks at
    27 rad/s, right after its impacts)."""
    _, nominal = run20
    peak = float(np.abs(nominal.qd).max())
    assert peak < 0.25 * SimOptions().max_speed
    sim = make_simulator(model, template_gait, options=SimOptions(max_speed=0.5 * peak))
    r = simulate_gait(sim, template_gait, steps=4)
    assert r.failed and "state diverged" in r.reason
    assert np.all(np.abs(r.qd[:-1]) <= 0.5 * peak) and np.abs(r.qd[-1]).max() > 0.5 * peak

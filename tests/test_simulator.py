"""The hybrid simulator on an optimized gait: events located on the ground, impacts that
match the optimizer's, a stable periodic orbit (issue 4 evidence); falls as data; a run
stepped one period at a time."""

from __future__ import annotations

import numpy as np
import pytest

from characterization.gait.fit import verify_gait
from characterization.gait.verification import make_simulator, simulate_gait
from hp_model.falls import Fall, FallReason
from hp_model.simulator import HybridSimulator, SimOptions, SimResult, touchdown_limit
from tests.fmu_runner import NominalPD
from tests.fmu_support import policy_table

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
    the default h = 1 ms against h / 8.  The template gait's foot touches down almost
    tangentially: at h = 1 ms it dips below the ground and rises again within one step, a
    touchdown found only by the dip check (hp_model.simulator.dip)."""
    times = []
    for sub in (SimOptions().substeps, 8):
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
    assert r.failed and r.fall is not None and r.reason == r.fall.message()
    assert r.fall.t == r.t[-1] and r.fall.tau == r.tau[-1]
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
    assert r.fall is not None and r.fall.reason is FallReason.PHASE_STALLED and r.steps == 0
    assert r.fall.values["limit"] == limit and r.fall.values["step_time"] > limit
    assert r.reason.endswith(f"phase stalled (no touchdown within {limit:g} s)")
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
    assert r.fall is not None and r.fall.reason is FallReason.DIVERGED
    assert r.fall.values["speed"] > r.fall.values["limit"] == 0.5 * peak
    assert np.all(np.abs(r.qd[:-1]) <= 0.5 * peak) and np.abs(r.qd[-1]).max() > 0.5 * peak


# -- stepped one period at a time ------------------------------------------------------------
def stepped(sim: HybridSimulator, q0, qd0, steps: int, policy=None) -> SimResult:
    """run()'s loop written out: observe, policy, apply, stop at a fall or ``steps``,
    advance."""
    r = sim.start(q0, qd0, "ps", mode="full" if policy is None else "human")
    while True:
        st = r.observe()
        fall = r.apply(None if policy is None else policy(st.t, st))
        assert fall is r.fall
        if fall is not None or r.steps >= steps:
            return r.result()
        r.advance()
        assert r.t == r.periods * sim.opt.dt


def assert_identical(a: SimResult, b: SimResult) -> None:
    for k in ("t", "q", "qd", "u", "lam", "tau", "domain"):
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), k
    assert len(a.impacts) == len(b.impacts)
    for i, j in zip(a.impacts, b.impacts, strict=True):
        assert (i.t, i.into, i.foot_pitch) == (j.t, j.into, j.foot_pitch)
        for k in ("q", "qd_minus", "qd_plus", "impulse"):
            assert getattr(i, k).tobytes() == getattr(j, k).tobytes(), k
    assert a.fall == b.fall and a.reason == b.reason


@pytest.mark.parametrize("case", ["pd walks", "zero torque falls", "full", "heel or toe"])
def test_stepping_by_hand_equals_run(model, template_gait, case):
    """observe/apply/advance with a policy gives run(policy=...) bit for bit: the log, the
    impacts and the fall (a walk, a friction-cone fall, mode full, a touchdown on heel or
    toe: a fall found in one period and reported at the start of the next)."""
    opt = SimOptions(max_touchdown_pitch=1e-7) if case == "heel or toe" else None
    sim = make_simulator(model, template_gait, options=opt)
    tr = template_gait.trajectory["ps"]
    q0, qd0 = tr["q"][:, 0], tr["qd"][:, 0]
    if case == "full":
        policy = None
    elif case == "zero torque falls":
        policy = lambda t, st: np.zeros(2)  # noqa: E731
    else:
        pd = NominalPD(policy_table(model, template_gait, sim))
        policy = lambda t, st: pd(st.domain, st.tau, st.q[10:12], st.qd[10:12])  # noqa: E731
    ref = sim.run(q0, qd0, "ps", steps=2, policy=policy)
    assert_identical(stepped(sim, q0, qd0, 2, policy), ref)
    expect = {"pd walks": None, "zero torque falls": FallReason.FRICTION_CONE, "full": None,
              "heel or toe": FallReason.HEEL_OR_TOE}[case]
    assert (ref.fall.reason if ref.fall else None) is expect
    if expect is FallReason.HEEL_OR_TOE:  # reported at the period after the touchdown
        assert ref.impacts[-1].t < ref.fall.t <= ref.impacts[-1].t + sim.opt.dt
        assert abs(ref.fall.values["pitch"]) > 1e-7 and ref.fall.domain == ref.impacts[-1].into


def test_a_run_is_stepped_in_order_and_ends_at_its_fall(model, template_gait):
    """observe twice in a period is the same state; apply before advance, once per period;
    the torque is clamped to the device's limits; mode full takes no torque; a fall ends the
    run (apply and advance refuse) and is data: reason, time, phase, the event's numbers."""
    sim = make_simulator(model, template_gait)
    tr = template_gait.trajectory["ps"]
    r = sim.start(tr["q"][:, 0], tr["qd"][:, 0], "ps")
    a, b = r.observe(), r.observe()
    assert a.t == b.t == 0.0 and a.tau == b.tau and np.array_equal(a.lam, b.lam)
    with pytest.raises(RuntimeError, match="apply"):
        r.advance()
    with pytest.raises(ValueError, match="mode human"):
        r.apply(None)
    assert r.apply(np.array([1e6, -1e6])) is None
    assert np.array_equal(r.result().u[0, 4:], [model.torque_limits[4], -model.torque_limits[5]])
    with pytest.raises(RuntimeError, match="already"):
        r.apply(np.zeros(2))
    r.advance()
    assert r.periods == 1 and r.t == sim.opt.dt and r.observe().t == r.t
    while r.apply(np.zeros(2)) is None:
        r.advance()
    f = r.fall
    assert f is not None and f.reason is FallReason.FRICTION_CONE
    assert f.t == r.t and f.domain == r.domain and f.values["periods"] == sim.opt.cone_periods
    assert f.message().startswith(f"t = {r.t:.3f} s, {r.domain}, tau = ")
    assert Fall.from_dict(f.to_dict()) == f and f.to_dict()["reason"] == "friction-cone"
    with pytest.raises(RuntimeError, match="ended"):
        r.advance()
    with pytest.raises(RuntimeError, match="ended"):
        r.apply(np.zeros(2))
    assert r.result().fall == f and r.result().t.size == r.periods + 1
    full = sim.start(tr["q"][:, 0], tr["qd"][:, 0], "ps", mode="full")
    with pytest.raises(ValueError, match="mode full"):
        full.apply(np.zeros(2))
    with pytest.raises(ValueError, match="mode"):
        sim.start(tr["q"][:, 0], tr["qd"][:, 0], "ps", mode="other")


def test_a_late_touchdown_is_the_same_time_in_every_domain():
    """The missing touchdown is a fall 0.12 s past the designed one at the gait's hip speed:
    tau 2.2 in a 0.1-s toe domain (tau_max 1.3 alone allowed 30 ms there), 1.4 in a 0.3-s
    domain; in the paper's 0.57-s domains tau_max (1.3, 171 ms) is the later and stays."""
    opt = SimOptions()
    for seconds, limit in ((0.1, 2.2), (0.3, 1.4), (0.57, 1.3)):
        v_hip, step = 1.2, 1.2 * seconds  # m/s, m
        assert touchdown_limit(opt, v_hip, step) == pytest.approx(limit, abs=1e-12)
    assert touchdown_limit(SimOptions(late_touchdown=0.0), 1.0, 0.1) == 1.3

"""The FMU, stepped by fmpy, reproduces the in-process HybridSimulator: same policy, same
scenario, same trajectory and impact times (10 steps of walking), including the human
perturbation, the initial prosthesis offsets, other step sizes, and a fall."""

from __future__ import annotations

import numpy as np
import pytest

from hp_model.contact_outputs import theta_rows
from hp_model.domains import PAPER_DOMAINS, Domain, DomainGraph
from hp_model.falls import FallReason
from hp_model.simulator import SimOptions
from human_fmu import initial_state, perturbed_thetas
from human_fmu.perturbation import splitmix64, uniform
from tests.fmu_runner import HumanFMU, NominalPD, run
from tests.fmu_support import built_fmu, policy_table, python_run, simulator, start_state

DT = 1e-3
H = DT / SimOptions().substeps  # one integration substep


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)[0]


@pytest.fixture(scope="module")
def nominal(model, template_gait):
    sim = simulator(model, template_gait)
    pd = NominalPD(policy_table(model, template_gait, sim))
    q0, qd0 = start_state(template_gait)
    return sim, pd, python_run(sim, pd, q0, qd0, steps=10)


def fmu_run(path, pd, periods, tau_from="output", real=None, integer=None, dt=DT):
    h = HumanFMU(str(path))
    h.setup(real, integer)
    log = run(h, pd, periods, dt, tau_from)
    h.free()
    return log


def test_python_reference_walks_ten_steps(nominal):
    _, _, ref = nominal
    assert not ref.failed, ref.reason
    assert ref.steps == 10
    assert set(ref.domain) == {0, 1}


@pytest.mark.parametrize("tau_from", ["q", "output"])
def test_fmu_reproduces_the_simulator_over_ten_steps(fmu_path, nominal, tau_from):
    """tau_from "q": the policy computes tau from the ground-truth q with the simulator's
    arithmetic; "output": it uses the FMU's tau output (the generated ``phase_<d>``, the
    same arithmetic).  Either way the two runs are bit-identical on this machine."""
    _, pd, ref = nominal
    log = fmu_run(fmu_path, pd, ref.t.size, tau_from)
    assert not log["fall"]
    q = np.array(log["q"])
    assert q.shape == ref.q.shape
    angles = np.array(log["sensors"])[:, 0:2]
    err_angles = np.abs(angles - ref.q[:, 10:12]).max()
    err_q = np.abs(q - ref.q).max()
    err_qd = np.abs(np.array(log["qd"]) - ref.qd).max()
    t_ref = np.array([i.t for i in ref.impacts])
    t_fmu = np.array(log["impacts"])
    assert t_fmu.shape == t_ref.shape == (10,)
    err_t = np.abs(t_fmu - t_ref).max()
    print(f"tau from {tau_from}: |d angles| {err_angles:.3g} rad, |dq| {err_q:.3g}, "
          f"|dqd| {err_qd:.3g}, |d t_impact| {err_t:.3g} s")
    assert err_angles <= 1e-6
    assert err_t < H
    # impacts are located inside the substeps, not at their boundaries
    off_grid = np.abs(t_fmu / H - np.round(t_fmu / H)) * H
    assert off_grid.min() > 1e-9, off_grid
    # the domain sequence and the sensed load agree sample by sample
    assert np.array_equal(np.array(log["domain"]), ref.domain)
    # forces read after setting the inputs = the simulator's log (same u_p)
    forces = np.array(log["forces"])
    load = np.where(ref.domain == 0, ref.lam[:, 1], 0.0)
    assert np.abs(forces[:, 0] - load).max() <= 1e-6 * np.abs(load).max()
    assert np.abs(forces[:, 1:4] - ref.lam[:, 3:6]).max() <= 1e-6 * np.abs(ref.lam).max()
    assert np.abs(forces[:, 4:7] - ref.lam[:, 0:3]).max() <= 1e-6 * np.abs(ref.lam).max()
    # same inputs, same generated C, same algorithm
    assert err_q <= 1e-12 and err_t <= 1e-12


def test_perturbation_and_offsets_match_their_python_mirrors(fmu_path, model, template_gait):
    # within what the test's NominalPD walks on the committed template gait (3 steps): at
    # amplitude 0.003 the perturbed human touches down late in the third stance and it falls
    amp, seed, dk, da = 0.001, -7, 0.01, -0.005
    thetas = perturbed_thetas({d: template_gait.theta(d) for d in PAPER_DOMAINS}, amp, seed)
    progress = template_gait.params[Domain.PS].layout.progress
    assert not np.array_equal(thetas[Domain.PS], template_gait.theta(Domain.PS))
    assert np.array_equal(thetas[Domain.PS][progress], template_gait.theta(Domain.PS)[progress])
    sim = simulator(model, template_gait, thetas)
    pd = NominalPD(policy_table(model, template_gait, sim))
    q0, qd0 = start_state(template_gait)
    q1, qd1 = initial_state(sim.cl, template_gait.theta(Domain.PS), q0, qd0, Domain.PS, dk, da)
    assert q1[10] == q0[10] + dk and q1[11] == q0[11] + da
    ref = python_run(sim, pd, q1, qd1, steps=3)
    log = fmu_run(fmu_path, pd, ref.t.size, "q",
                  real={"human_perturbation": amp, "offset_knee": dk, "offset_ankle": da},
                  integer={"human_seed": seed})
    q = np.array(log["q"])
    assert np.abs(q[0] - q1).max() <= 1e-12
    assert np.abs(np.array(log["qd"][0]) - qd1).max() <= 1e-9
    assert not ref.failed and ref.steps == 3 and not log["fall"]
    assert np.abs(q - ref.q).max() <= 1e-9
    assert len(log["impacts"]) == ref.steps
    assert np.abs(np.array(log["impacts"]) - [i.t for i in ref.impacts]).max() <= 1e-9


def test_offsets_start_where_a_scenario_does(fmu_path, model, template_gait):
    """One placement (hp_model.placement): the FMU's offset_knee/offset_ankle and a
    closed-loop scenario's initial offset start the walk from the same state."""
    from orchestrator.experiments.scenarios import initial_state as scenario_state

    dk, da = 0.02, -0.01
    sim = simulator(model, template_gait)
    q_s, qd_s = scenario_state(model, template_gait, (dk, da), sim.cl)
    q0, qd0 = start_state(template_gait)
    assert np.abs(q_s - q0).max() > 1e-3  # really moved (the human onto its outputs too)
    q_p, qd_p = initial_state(sim.cl, template_gait.theta(Domain.PS), q0, qd0, Domain.PS, dk, da)
    pd = NominalPD(policy_table(model, template_gait, sim))
    log = fmu_run(fmu_path, pd, 1, "q", real={"offset_knee": dk, "offset_ankle": da})
    for q, qd in ((q_p, qd_p), (log["q"][0], log["qd"][0])):
        assert np.abs(np.asarray(q) - q_s).max() <= 1e-12
        assert np.abs(np.asarray(qd) - qd_s).max() <= 1e-12


def test_start_in_pns(fmu_path, model, template_gait):
    """Initial state and domain as parameters: the gait's start of pns."""
    sim = simulator(model, template_gait)
    pd = NominalPD(policy_table(model, template_gait, sim))
    tr = template_gait.trajectory[Domain.PNS]
    q0, qd0 = tr["q"][:, 0], tr["qd"][:, 0]
    ref = python_run(sim, pd, q0, qd0, Domain.PNS, steps=2)
    real = {f"q0[{i + 1}]": v for i, v in enumerate(q0)}
    real |= {f"qd0[{i + 1}]": v for i, v in enumerate(qd0)}
    log = fmu_run(fmu_path, pd, ref.t.size, "q", real=real, integer={"initial_domain": 1})
    assert log["domain"][0] == 1 and not log["fall"] and not ref.failed
    assert np.abs(np.array(log["q"]) - ref.q).max() <= 1e-9
    assert np.abs(np.array(log["impacts"]) - [i.t for i in ref.impacts]).max() <= 1e-9


def test_other_step_size_and_substeps(fmu_path, model, template_gait):
    """doStep(2 ms) with 4 substeps = SimOptions(dt=2 ms, substeps=4)."""
    sim = simulator(model, template_gait, options=SimOptions(dt=2e-3, substeps=4))
    pd = NominalPD(policy_table(model, template_gait, sim))
    q0, qd0 = start_state(template_gait)
    ref = python_run(sim, pd, q0, qd0, steps=2)
    log = fmu_run(fmu_path, pd, ref.t.size, "q", integer={"substeps": 4}, dt=2e-3)
    assert np.abs(np.array(log["q"]) - ref.q).max() <= 1e-9
    assert np.abs(np.array(log["impacts"]) - [i.t for i in ref.impacts]).max() <= 1e-9


@pytest.mark.parametrize("factor", [0.0, 0.5, 2.0, 3.0, -1.0])
def test_fall_is_detected_like_the_simulator(fmu_path, model, template_gait, factor):
    """With the nominal prosthesis torques scaled the walker falls (in various ways); the FMU
    raises `fall` with the simulator's reason at the same sample (a friction-cone fall
    depends on the inputs of the step and shows one communication step later)."""
    sim = simulator(model, template_gait)
    table = policy_table(model, template_gait, sim)
    for d in PAPER_DOMAINS:
        table["nominal"][d]["u"] = (factor * np.array(table["nominal"][d]["u"])).tolist()
    pd = NominalPD(table)
    q0, qd0 = start_state(template_gait)
    ref = python_run(sim, pd, q0, qd0, steps=10)
    assert ref.failed
    log = fmu_run(fmu_path, pd, ref.t.size + 1, "q")
    assert log["fall"]
    assert FallReason(log["fall_code"]) is ref.fall.reason
    lag = 1 if log["fall_code"] == FallReason.FRICTION_CONE else 0
    assert log["fall_period"] == ref.t.size - 1 + lag
    print(f"x{factor}: {ref.reason}; FMU code {log['fall_code']} at sample "
          f"{log['fall_period']}")


@pytest.mark.parametrize("option, reason", [
    ("max_step_time", FallReason.PHASE_STALLED), ("max_speed", FallReason.DIVERGED),
    ("min_hip_height", FallReason.HIP_LOW), ("tau_max", FallReason.NO_TOUCHDOWN),
    ("late_touchdown", FallReason.NO_TOUCHDOWN),
    ("max_touchdown_pitch", FallReason.HEEL_OR_TOE)])
def test_forced_falls_are_detected_like_the_simulator(fmu_path, model, template_gait, nominal,
                                                      option, reason):
    """A limit the nominal gait breaks mid-walk -- ``max_step_time`` shorter than its first
    step, ``max_speed`` half its peak speed, ``min_hip_height`` between the start's hip height
    and the lowest, ``tau_max`` 0.5 (the limit in time off), the limit in time 0.15 s before
    the designed touchdown (tau_max off), ``max_touchdown_pitch`` below the first touchdown's
    residual pitch: the FMU stops at the simulator's sample with the simulator's reason."""
    _, _, ref0 = nominal
    limits = {"max_step_time": {"max_step_time": 0.1},
              "max_speed": {"max_speed": 0.5 * float(np.abs(ref0.qd).max())},
              "min_hip_height": {"min_hip_height": 0.5 * float(ref0.q[0, 1]
                                                                + ref0.q[:, 1].min())},
              "tau_max": {"tau_max": 0.5, "late_touchdown": -1e3},
              "late_touchdown": {"tau_max": 0.0, "late_touchdown": -0.15},
              "max_touchdown_pitch": {"max_touchdown_pitch": 1e-7}}[option]
    sim = simulator(model, template_gait, options=SimOptions(**limits))
    pd = NominalPD(policy_table(model, template_gait, sim))
    q0, qd0 = start_state(template_gait)
    ref = python_run(sim, pd, q0, qd0, steps=2)
    assert ref.fall is not None and ref.fall.reason is reason and ref.t.size > 1
    if option in ("tau_max", "late_touchdown"):  # the limit each rule sets
        v_hip, p_min, p_max = sim.thetas[ref.fall.domain][-3:]
        expected = 0.5 if option == "tau_max" else 1 - 0.15 * v_hip / (p_max - p_min)
        assert ref.fall.values["limit"] == pytest.approx(expected, rel=1e-12)
        assert ref.fall.tau > expected > ref.tau[-2]
    log = fmu_run(fmu_path, pd, ref.t.size + 1, "q", real=limits)
    assert log["fall"] and FallReason(log["fall_code"]) is reason
    assert log["fall_period"] == ref.t.size - 1


def test_perturbation_generator_is_splitmix64():
    """Published SplitMix64 values (seed 0: e220a8397b1dcdaf, 6e789e6aa1b965f4; seed 1234567:
    599ed017fb08fc85, the xoshiro reference's test vector)."""
    assert splitmix64(0, 0) == 0xE220A8397B1DCDAF
    assert splitmix64(0, 1) == 0x6E789E6AA1B965F4
    assert splitmix64(1234567, 0) == 0x599ED017FB08FC85
    assert uniform(-1, 3) == uniform((1 << 64) - 1, 3)  # negative seeds: two's complement
    th = {Domain.PS: np.arange(33.0), Domain.PNS: -np.arange(33.0)}
    assert all(np.array_equal(perturbed_thetas(th, 0.0, 5)[d], th[d]) for d in th)
    p = perturbed_thetas(th, 0.1, 5)
    for d in th:
        delta = p[d] - th[d]
        assert np.all(np.abs(delta[:30]) <= 0.1) and np.all(delta[30:] == 0)
        assert np.abs(delta[:30]).min() > 0
    assert not np.array_equal(p[Domain.PS] - th[Domain.PS], -(p[Domain.PNS] - th[Domain.PNS]))
    with pytest.raises(ValueError):
        perturbed_thetas(th, -1.0, 0)


@pytest.mark.parametrize("degree", [5, 3])
def test_on_the_multicontact_graph_each_curve_keeps_its_ends(degree):
    """The two first and two last coefficients of every row (the curve's value and slope at
    its domain's contact events) stay the gait's; the others move by the draw they have on
    any graph (k = A_d + i), within the amplitude; a degree-3 curve keeps all four."""
    m1, a, seed = degree + 1, 0.025, 11
    th = {d: np.linspace(-1.0, 1.0, theta_rows(d) * m1 + 3)
          for d in DomainGraph.MULTICONTACT.domains}
    p = perturbed_thetas(th, a, seed)
    k0 = 0
    for d in DomainGraph.MULTICONTACT.domains:
        delta = (p[d] - th[d])[:-3].reshape(theta_rows(d), m1)
        assert np.all(delta[:, :2] == 0) and np.all(delta[:, -2:] == 0), d
        assert np.all(p[d][-3:] == th[d][-3:])
        for r, c in np.ndindex(delta.shape):
            if 2 <= c < m1 - 2:
                i = r * m1 + c
                assert delta[r, c] == pytest.approx(a * (2 * uniform(seed, k0 + i) - 1), abs=1e-15)
                assert 0 < abs(delta[r, c]) <= a
        k0 += theta_rows(d) * m1
    with pytest.raises(ValueError, match="rows"):
        perturbed_thetas({**th, Domain.PS: np.zeros(theta_rows(Domain.PS) * m1 + 4)}, a, seed)

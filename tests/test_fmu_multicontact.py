"""The human FMU on the multi-contact graph (heel strike, flat foot, heel off, toe off):
built from the committed openOFM cycle, stepped by fmpy under the torques the in-process
simulator applied, it reproduces that simulator's walk (the same generated functions, the
same hybrid algorithm: lift-offs at tau = 1, the trailing foot's release, step counting);
``hpcosim fmu build`` makes it from a multi-contact gait file."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from characterization.gait.contact_gait import contact_gait_of, held_oracle, start_state
from hp_model.domains import Domain
from hp_model.simulator import HybridSimulator, SimOptions, SimResult
from human_fmu import build_fmu, perturbed_thetas
from orchestrator.cli import main as hpcosim
from orchestrator.cosim.contact_controllers import loop_simulator, tracked_gait
from orchestrator.loop.plant import wrench_rows
from tests.fmu_runner import HumanFMU
from tests.multicontact_cycle import load_cycle, write_gait_file

DT = 1e-3


@pytest.fixture(scope="module")
def cycle():
    model, traj, durations, _ = load_cycle()
    return model, traj, contact_gait_of(model, traj, durations)


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, cycle):
    model, traj, gait = cycle
    path = tmp_path_factory.mktemp("mcfmu") / "human.fmu"
    build_fmu(tracked_gait(model, gait, traj, "openofm cycle"), path, model=model)
    return path


def reference(sim: HybridSimulator, traj, thetas, steps: int) -> SimResult:
    q0, qd0 = start_state(traj)
    return sim.run(q0, qd0, Domain.PS, steps=steps, duration=10.0,
                   policy=held_oracle(sim.cl, thetas, sim.gains))


@pytest.fixture(scope="module")
def walked(cycle):
    model, traj, gait = cycle
    sim = loop_simulator(model, gait, (20.0, 1600.0, 80.0))
    return sim, reference(sim, traj, gait.thetas(), steps=6)


def replay(path, torques: np.ndarray, real: dict | None = None, integer: dict | None = None
           ) -> dict[str, np.ndarray]:
    """Step the FMU one period per row of ``torques`` (knee, ankle motor torque, N m),
    reading the state, domain, steps and the forces under each torque before its step."""
    h = HumanFMU(str(path))
    h.setup(real, integer)
    f = h.fmu
    xv = h.vrs([f"q[{i}]" for i in range(1, 13)] + [f"qd[{i}]" for i in range(1, 13)])
    iv = h.vrs(["domain", "steps", "fall_code"])
    uv, fv = h.vrs(["u_knee", "u_ankle"]), h.vrs(["foot_load", "socket_Fx", "socket_Fz",
                                                  "socket_My"])
    log: dict[str, list] = {"x": [], "domain": [], "steps": [], "forces": []}
    for k, u in enumerate(torques):
        log["x"].append(f.getReal(xv))
        dom, steps, code = f.getInteger(iv)
        assert code == 0, f"the FMU fell (code {code}) at period {k}"
        log["domain"].append(dom)
        log["steps"].append(steps)
        f.setReal(uv, u.tolist())
        log["forces"].append(f.getReal(fv))
        f.doStep(k * DT, DT)
    h.free()
    return {k: np.array(v) for k, v in log.items()}


def test_the_fmu_walks_the_simulators_walk(fmu_path, cycle, walked):
    model, _, _ = cycle
    _, ref = walked
    assert ref.fall is None and ref.steps == 6
    into = [i.into for i in ref.impacts]
    # the walk crosses every transition: heel strikes, the double supports' ends (the
    # trailing foot's release or the leading toe's touchdown), and the lift-offs
    assert {Domain.DS_H, Domain.DS_P} <= set(into)
    assert any(i.release for i in ref.impacts)
    assert {Domain.PS_TOE, Domain.PNS_TOE} <= {Domain.from_code(int(c)) for c in ref.domain}
    log = replay(fmu_path, ref.u[:, 4:6])
    x_ref = np.c_[ref.q, ref.qd]
    # the same generated C and arithmetic (-ffp-contract=off): equal to rounding
    assert np.abs(log["x"] - x_ref).max() <= 1e-9
    assert np.array_equal(log["domain"], ref.domain)
    # steps: the heel strikes so far, period by period
    strikes = np.array([i.t for i in ref.impacts if i.starts_step])
    assert np.array_equal(log["steps"], np.searchsorted(strikes, ref.t, side="right"))
    rows = wrench_rows(model)
    for k in range(0, ref.t.size, 7):
        r = rows[Domain.from_code(int(ref.domain[k]))]
        load = 0.0 if r.load is None else ref.lam[k, r.load]
        assert log["forces"][k, 0] == pytest.approx(load, abs=1e-6)
        assert log["forces"][k, 1:] == pytest.approx(ref.lam[k, r.socket], abs=1e-6)


def test_the_human_perturbation_is_the_python_mirrors(fmu_path, cycle, walked):
    """A perturbed human (the Bezier coefficients of the six domains moved by their draws,
    each curve's ends kept) walks in the FMU as the simulator walks
    :func:`perturbed_thetas`'s gait."""
    model, traj, gait = cycle
    sim, _ = walked
    amplitude, seed = 0.002, 7
    thetas = perturbed_thetas(gait.thetas(), amplitude, seed)
    assert all(np.abs(thetas[d] - gait.thetas()[d])[-3:].max() == 0 for d in thetas)
    for d, p in gait.params.items():  # the curves' values and slopes at the events kept
        m1 = np.asarray(p.alpha).shape[1]
        moved = (thetas[d] - gait.thetas()[d])[:-3].reshape(-1, m1)
        assert np.all(moved[:, [0, 1, -2, -1]] == 0), d
        assert np.all(moved[:, 2:-2] != 0) and np.abs(moved).max() <= amplitude, d
    psim = HybridSimulator(model, sim.cl, thetas, sim.gains)
    ref = reference(psim, traj, thetas, steps=2)
    assert ref.fall is None
    log = replay(fmu_path, ref.u[:, 4:6], {"human_perturbation": amplitude},
                 {"human_seed": seed})
    assert np.abs(log["x"] - np.c_[ref.q, ref.qd]).max() <= 1e-9
    assert np.array_equal(log["domain"], ref.domain)


def test_offsets_are_refused_on_this_graph(fmu_path):
    h = HumanFMU(str(fmu_path))
    try:
        with pytest.raises(FMICallException):
            h.setup({"offset_knee": 0.02})
    finally:
        h.fmu.freeInstance()


def test_fmu_build_reads_a_multicontact_gait_file(tmp_path, cycle, capsys):
    model, _, _ = cycle
    gait = tmp_path / "gait.json"
    write_gait_file(gait)
    out = tmp_path / "human.fmu"
    assert hpcosim(["fmu", "build", "--gait", str(gait), "--out", str(out)]) == 0
    assert validate_fmu(str(out)) == []
    h = HumanFMU(str(out))
    names = set(h.vr)
    h.fmu.freeInstance()
    assert {f"theta_{d}[1]" for d in model.graph.domains} <= names
    # a subject given beside it is refused in one line, nothing written
    bad = tmp_path / "bad.fmu"
    assert hpcosim(["fmu", "build", "--gait", str(gait), "--out", str(bad), "--subject",
                    "hp_model/configs/subject_example.toml"]) != 0
    assert not bad.exists()
    assert "carries its subject" in capsys.readouterr().err


def test_clfqp_walks_the_fmu_through_the_loop(fmu_path, cycle, walked):
    """The product's closed loop (``run_loop``) with the FMU as the plant and ``clfqp`` as
    the controller, its measurements and torques at the CAN frames' resolution (what the
    co-simulation's controller node sees): 6 steps, the strides the in-process plant
    gives the same controller within 1 % (the quantization is the only difference)."""
    from human_fmu.instance import HumanFmu
    from orchestrator.cosim.contact_controllers import contact_clfqp
    from orchestrator.experiments.contact_walk import walk_controller
    from orchestrator.loop.link import ControllerLink
    from orchestrator.loop.plant import FmuPlant
    from orchestrator.loop.run import run_loop

    model, traj, gait = cycle
    sim, _ = walked
    ctl = contact_clfqp(model, gait, traj)
    in_process = walk_controller(sim, traj, ctl, 6, "clfqp")
    assert in_process.walks, in_process.line()
    fmu = HumanFmu(fmu_path)
    try:
        q0, qd0 = start_state(traj)
        fmu.start_walk(gait.thetas(), q0, qd0)
        log = run_loop(FmuPlant(fmu, DT), ControllerLink(ctl, quantize=True), steps=6)
    finally:
        fmu.free()
    assert log.fall is None and log.fault == "", log.fall
    assert log.steps == 6
    domain = np.array(log.domain)
    t = np.array(log.t)
    # heel strikes of the human foot: entries into ds_h
    strikes = t[1:][(domain[1:] == Domain.DS_H.code) & (domain[:-1] != Domain.DS_H.code)]
    stride = np.median(np.diff(strikes))
    assert stride == pytest.approx(np.median(in_process.strides), rel=0.01)
    modes = set(log.mode)
    assert {"stance", "swing"} <= {str(m) for m in modes}
    assert log.fallback_count == 0


def test_a_gait_set_in_step_mode_is_taken_up_as_the_walker_enters_its_domain(fmu_path, cycle,
                                                                             walked):
    """The master's gait schedule (``FmuPlant(gaits=...)``, a person changing speed): the
    FMU walks the in-process simulator's walk under the same schedule, to rounding; a gait
    that is not one (v_hip <= 0) is refused and the domain keeps its own.  The schedule
    ramps from the gait to a 3 % faster one over the walk, so every entry (the impacts and
    the heels' lift-offs alike) takes a gait of its own, sampled at the period's start on
    both sides."""
    from orchestrator.experiments.contact_perturbations import paced

    _, traj, gait = cycle
    sim, nominal = walked
    base, fast = gait.thetas(), paced(gait, 1.03).thetas()
    entries = [i.t for i in nominal.impacts]
    switch = 0.5 * (entries[2] + entries[3])  # the bad gait: from between two entries
    ramp = entries[-1]

    def schedule(d: Domain, t: float) -> np.ndarray:
        w = min(t / ramp, 1.0)
        return (1.0 - w) * base[d] + w * fast[d]

    q0, qd0 = start_state(traj)
    ref = sim.run(q0, qd0, Domain.PS, steps=5, duration=10.0,
                  policy=held_oracle(sim.cl, base, sim.gains), gaits=schedule)
    assert ref.fall is None
    n = min(ref.t.size, nominal.t.size)
    assert np.abs(ref.q[:n] - nominal.q[:n]).max() > 1e-3  # the schedule changed the walk

    def fmu_walk(gaits, torques: np.ndarray) -> np.ndarray:
        return replay_walk(fmu_path, base, q0, qd0, torques, gaits)

    assert np.abs(fmu_walk(schedule, ref.u[:, 4:6]) - np.c_[ref.q, ref.qd]).max() <= 1e-9
    bad = {d: th.copy() for d, th in fast.items()}
    for th in bad.values():
        th[-3] = -1.0  # v_hip
    x = fmu_walk(lambda d, t: bad[d] if t >= switch else base[d], nominal.u[:, 4:6])
    assert np.abs(x - np.c_[nominal.q, nominal.qd]).max() <= 1e-9  # the base gait kept


def test_a_heel_strike_early_in_a_toe_domain_lands_in_both(fmu_path, cycle, walked):
    """A person standing in a posture of its own (hips +-2 deg: its swing heel lower) strikes
    the ground at tau 0.57 of ``ps_toe``, before ``guard_tau_min``: the toe domains' guard is
    armed from their entry (their landing foot already in the air), in the FMU's C as in the
    simulator, which land it at the same period, to rounding, up to the walk's end."""
    import math

    from orchestrator.sweep.contact import draw_gait, posture_start
    from orchestrator.sweep.draws import Draw

    model, traj, gait = cycle
    sim, _ = walked
    off = (math.radians(2.0), 0.0, 0.0, -math.radians(2.0))
    thetas = {Domain(k): v for k, v in draw_gait(gait, Draw("posture", 0,
                                                             output_offset=off)).items()}
    psim = HybridSimulator(model, sim.cl, thetas, sim.gains)
    q0, qd0 = posture_start(psim, start_state(traj), off)
    ref = psim.run(q0, qd0, Domain.PS, steps=2, duration=10.0,
                   policy=held_oracle(sim.cl, thetas, sim.gains))
    strike = next(i for i in ref.impacts if i.into == Domain.DS_H)
    k = int(np.searchsorted(ref.t, strike.t)) - 1
    assert Domain.from_code(int(ref.domain[k])) is Domain.PS_TOE
    assert ref.tau[k] < SimOptions().guard_tau_min  # early: the old guard was not armed
    n = ref.t.size - 2  # up to the walk's end (a fall in the next step)
    log = replay_walk(fmu_path, thetas, q0, qd0, ref.u[:n, 4:6])
    assert log.shape[0] == n  # no fall in the FMU either
    assert np.abs(log - np.c_[ref.q[:n], ref.qd[:n]]).max() <= 1e-9


def replay_walk(path, thetas, q0, qd0, torques: np.ndarray, gaits=None) -> np.ndarray:
    """The FMU's states (q, qd) under ``torques`` from (q0, qd0) with the person's gait
    ``thetas`` (``HumanFmu.start_walk``; ``gaits``: the master's schedule of them), one
    period per row, until the torques or the walk end."""
    from human_fmu.instance import HumanFmu
    from orchestrator.loop.plant import FmuPlant

    fmu = HumanFmu(path)
    try:
        fmu.start_walk(thetas, q0, qd0)
        plant = FmuPlant(fmu, DT, gaits=gaits)
        x = []
        for u in torques:
            if plant.observe().held:
                break
            truth = plant.actuate(u)
            x.append(np.r_[truth.q, truth.qd])
            plant.advance()
        return np.array(x)
    finally:
        fmu.free()

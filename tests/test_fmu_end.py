"""The end of a walk through FMI 2.0's own path, for every fall code, driven through fmpy's
low-level API: the doStep at the fall and every later one return fmi2Discard (also with a
1e6 or a NaN torque input set after the fall), fmi2Terminated is true,
fmi2LastSuccessfulTime is the fall time of the in-process simulator (the same run, the same
policy), and every output is finite and the simulator's state at that time (the feedthrough
outputs: the simulator's torques and wrenches at that state under the torque held)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Discard, fmi2LastSuccessfulTime, fmi2Terminated

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.falls import FallReason
from hp_model.simulator import SimOptions
from tests.fmu_runner import HumanFMU, NominalPD
from tests.fmu_support import built_fmu, policy_table, python_run, simulator, start_state

#: friction-cone check off (|F_x| <= mu F_z always holds for F_z >= min_normal_force)
NO_CONE = {"mu": 1e9, "min_normal_force": -1e12}
#: every check but the non-finite one off
ONLY_NON_FINITE = {**NO_CONE, "min_hip_height": -1e9, "tau_max": 1e9, "max_step_time": 1e9,
                   "max_speed": 1e300, "tau_backward": 1e9}
INTEGER = ("substeps", "cone_periods")
#: the falls whose state at the simulator's fall time is not finite or blown up: the FMU holds
#: the state one period earlier (the last finite one)
HELD_BEFORE = (FallReason.NON_FINITE, FallReason.DIVERGED)
#: feedthrough outputs: the torques (prosthesis: motor torques) and the wrenches
U = tuple(f"u[{i}]" for i in range(1, 7))
LAM = ("stance_Fx", "stance_Fz", "stance_My", "socket_Fx", "socket_Fz", "socket_My")
STATE = tuple(f"q[{i}]" for i in range(1, 13)) + tuple(f"qd[{i}]" for i in range(1, 13))
OTHER = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load",
         "socket_pitch", "tau", "t_impact")


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)[0]


@pytest.fixture(scope="module")
def nominal_peaks(model, template_gait):
    """(the start's hip height, the lowest over a step, the peak speed) of the nominal walk."""
    sim = simulator(model, template_gait)
    ref = python_run(sim, NominalPD(policy_table(model, template_gait, sim)),
                     *start_state(template_gait), steps=1)
    return float(ref.q[0, 1]), float(ref.q[:, 1].min()), float(np.abs(ref.qd).max())


def case(reason: FallReason, peaks: tuple[float, float, float]) -> tuple[dict, float, float]:
    """(options, torque scale, dt) that make the nominal-PD walk end with ``reason``."""
    hip0, hip_min, speed = peaks
    return {
        FallReason.NON_FINITE: ({**ONLY_NON_FINITE, "substeps": 1}, 1.0, 0.25),
        FallReason.HIP_LOW: ({"min_hip_height": 0.5 * (hip0 + hip_min)}, 1.0, 1e-3),
        FallReason.PHASE_BACKWARD: (NO_CONE, 3.0, 1e-3),
        # the limit in time: 0.15 s before the designed touchdown (tau about 0.5)
        FallReason.NO_TOUCHDOWN: ({"tau_max": 0.0, "late_touchdown": -0.15}, 1.0, 1e-3),
        FallReason.FRICTION_CONE: ({}, 0.0, 1e-3),
        FallReason.HEEL_OR_TOE: ({"max_touchdown_pitch": 1e-7}, 1.0, 1e-3),
        FallReason.PHASE_STALLED: ({"max_step_time": 0.1}, 1.0, 1e-3),
        FallReason.DIVERGED: ({"max_speed": 0.5 * speed}, 1.0, 1e-3),
    }[reason]


def scaled_pd(model, gait, sim, scale: float) -> NominalPD:
    table = policy_table(model, gait, sim)
    for d in PAPER_DOMAINS:
        table["nominal"][d]["u"] = (scale * np.array(table["nominal"][d]["u"])).tolist()
    return NominalPD(table)


def discarded(f, t: float, dt: float) -> bool:
    """doStep(t, dt) through fmpy: False when it returns fmi2OK, True for fmi2Discard (any
    other status fails the test)."""
    try:
        f.doStep(t, dt)
        return False
    except FMICallException as e:
        assert e.status == fmi2Discard, e.status
        return True


@pytest.mark.parametrize("reason", [r for r in FallReason if r is not FallReason.NONE],
                         ids=lambda r: r.label)
def test_every_fall_ends_the_run_the_fmi_way(fmu_path, model, template_gait, nominal_peaks,
                                             reason):
    options, scale, dt = case(reason, nominal_peaks)
    sim = simulator(model, template_gait, options=SimOptions(dt=dt, **options))
    pd = scaled_pd(model, template_gait, sim, scale)
    q0, qd0 = start_state(template_gait)
    ref = python_run(sim, pd, q0, qd0, steps=4)
    assert ref.fall is not None and ref.fall.reason is reason, ref.reason

    h = HumanFMU(str(fmu_path))
    h.setup({k: v for k, v in options.items() if k not in INTEGER},
            {k: v for k, v in options.items() if k in INTEGER})
    f = h.fmu
    uv, qv = h.vrs(["u_knee", "u_ankle"]), h.vrs(STATE)
    k = 0
    while True:  # the simulator's loop: read, policy, set, step
        q = np.array(f.getReal(qv)[:12])
        qd = np.array(f.getReal(qv)[12:])
        d = Domain.from_code(f.getInteger(h.vrs(["domain"]))[0])
        f.setReal(uv, pd(d, pd.phase(d, q), q[10:12], qd[10:12]).tolist())
        if discarded(f, k * dt, dt):
            break
        k += 1
        assert k < ref.t.size, "the FMU walks on past the simulator's fall"
    t_step = k * dt  # the start of the step that ended the walk
    assert f.getBooleanStatus(fmi2Terminated)
    assert f.getBoolean(h.vrs(["fall"])) == [True]
    assert f.getInteger(h.vrs(["fall_code"])) == [int(reason)]
    last = f.getRealStatus(fmi2LastSuccessfulTime)
    # the fall time: the simulator's (the time of its fall checks, at a period's start), or,
    # where the simulator's state there is not finite or blown up, the period before it
    fall_t = ref.fall.t - dt if reason in HELD_BEFORE else ref.fall.t
    assert last == pytest.approx(fall_t, abs=1e-12)
    assert t_step <= last <= t_step + dt
    i = int(np.argmin(np.abs(ref.t - last)))
    assert abs(ref.t[i] - last) <= 1e-12
    # every output finite; the state is the simulator's at that time
    held = f.getReal(h.vrs(STATE))
    others = f.getReal(h.vrs(OTHER + U + LAM))
    assert all(math.isfinite(v) for v in held + others)
    np.testing.assert_array_equal(held, np.r_[ref.q[i], ref.qd[i]])
    assert f.getInteger(h.vrs(["domain"]))[0] == ref.domain[i]
    # later steps, with a 1e6 torque or a NaN set, are discarded; the state stays, and the
    # feedthrough outputs are the simulator's at that state under the torque held
    lim = model.torque_limits[4:6]
    for j, (u, held_u) in enumerate((((1e6, -1e6), (lim[0], -lim[1])),
                                     ((math.nan, math.nan), (lim[0], -lim[1])))):
        f.setReal(uv, list(u))
        assert discarded(f, t_step + (j + 1) * dt, dt)
        assert f.getBooleanStatus(fmi2Terminated)
        assert f.getRealStatus(fmi2LastSuccessfulTime) == last
        assert f.getReal(h.vrs(STATE)) == held
        out = f.getReal(h.vrs(U + LAM))
        assert all(math.isfinite(v) for v in out)
        _, u_ref, lam_ref = sim._eval("human", Domain.from_code(ref.domain[i]),
                                   np.r_[ref.q[i], ref.qd[i]],
                                   np.array(held_u, float), None)
        np.testing.assert_allclose(out, np.r_[u_ref, lam_ref], rtol=1e-9, atol=1e-9)
    h.free()


# -- the project's own master: FmuPlant ends the run on the standard status -------------------
class ConstantLink:
    """A link that commands a constant motor torque (N m) every period."""

    def __init__(self, torque: tuple[float, float]) -> None:
        self.torque = torque

    def exchange(self, obs):
        from orchestrator.loop import Command

        return Command(self.torque)

    def pace(self, k: int) -> None:
        pass


class NoFallOutput:
    """A master's view of the human FMU without the project's ``fall``/``fall_code`` outputs
    (the real FMU underneath): the end must come from fmi2Discard/fmi2Terminated alone."""

    def __init__(self, fmu, limits: dict | None = None) -> None:
        self.fmu, self.limits = fmu, limits or {}

    def start_walk(self, thetas, q0, qd0):
        self.fmu.start_walk(thetas, q0, qd0, self.limits)

    def read(self):
        return self.fmu.read()._replace(fall_code=0, fell=False)

    def __getattr__(self, name):
        return getattr(self.fmu, name)


@pytest.fixture(scope="module")
def human(fmu_path):
    from human_fmu.instance import HumanFmu

    fmu = HumanFmu(fmu_path, instance="end")
    yield fmu
    fmu.free()


@pytest.mark.parametrize("limits, reason", [({}, FallReason.FRICTION_CONE),
                                            ({"max_step_time": 0.1},
                                             FallReason.PHASE_STALLED)])
def test_fmu_plant_ends_where_the_simulator_plant_does(human, model, template_gait, limits,
                                                       reason):
    """No prosthesis torque: the walk ends in a friction-cone fall (decided before the step:
    the FMU holds the previous period's state) or, with a 0.1 s bound on the step time,
    stalled (the state at the end of the step).  FmuPlant ends the run on the
    FMU's fmi2Discard/fmi2Terminated with the simulator plant's samples and fall."""
    from orchestrator.loop import FmuPlant, SimulatorPlant, run_loop

    thetas = {d: template_gait.theta(d) for d in PAPER_DOMAINS}
    q0, qd0 = start_state(template_gait)
    sim = simulator(model, template_gait, options=SimOptions(**limits))
    ref = run_loop(SimulatorPlant(sim, q0, qd0), ConstantLink((0.0, 0.0)), steps=4)
    human.start_walk(thetas, q0, qd0, limits)
    log = run_loop(FmuPlant(human, 1e-3), ConstantLink((0.0, 0.0)), steps=4)
    assert ref.fall is not None and ref.fall.reason is reason
    assert log.fall is not None and log.fall.reason is reason
    assert (log.fall.t, log.fall.domain, log.fall.tau) == (ref.fall.t, ref.fall.domain,
                                                           ref.fall.tau)
    assert log.periods == ref.periods
    np.testing.assert_array_equal(np.array(log.q), np.array(ref.q))


def test_a_discard_without_a_fall_code_ends_the_run(human, model, template_gait, ctx):
    """A master that reads no fall output still ends the run: the loop stops at the FMU's
    fmi2Discard/fmi2Terminated with an error naming it, never loops; so does a sweep run."""
    from orchestrator.experiments.scenarios import NOMINAL, Scenario
    from orchestrator.loop import FmuEndError, FmuPlant, run_loop
    from orchestrator.sweep.fmu import period_bound, run_fmu_scenario

    thetas = {d: template_gait.theta(d) for d in PAPER_DOMAINS}
    q0, qd0 = start_state(template_gait)
    human.start_walk(thetas, q0, qd0)
    with pytest.raises(FmuEndError, match="without a fall code"):
        run_loop(FmuPlant(NoFallOutput(human), 1e-3), ConstantLink((0.0, 0.0)), steps=4,
                 periods=20_000)  # a loop that missed the end would stop here, not raise
    with pytest.raises(FmuEndError, match="without a fall code"):
        # a walking controller, a step-time bound it breaks (0.1 s)
        run_fmu_scenario(NoFallOutput(human, {"max_step_time": 0.1}), model, template_gait, ctx,
                         Scenario("phase-pd", NOMINAL, 4), (q0, qd0))
    # a run's periods are bounded: (steps + 1) max_step_time (3 s) at 1 kHz, plus one
    assert period_bound(human, 4, 1e-3) == 15001

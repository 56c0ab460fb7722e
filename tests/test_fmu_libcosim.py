"""A second FMI importer: libcosim (the Open Simulation Platform's co-simulation library,
through libcosimpy) loads the human FMU, steps it at 1 ms with the torque inputs at their
start value 0 until the walk ends, and sees the end: the step that fmpy sees discarded is
the one libcosim's execution fails on ("Step not complete"), and every state libcosim
observed up to there is fmpy's of the same run."""

from __future__ import annotations

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2Discard, fmi2LastSuccessfulTime, fmi2Terminated
from libcosimpy._internal import get_last_error_message
from libcosimpy.CosimEnums import CosimExecutionState, CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

from hp_model.falls import FallReason
from tests.fmu_runner import HumanFMU
from tests.fmu_support import built_fmu

DT_NS = 1_000_000  # libcosim's step size (ns)
STATE = tuple(f"q[{i}]" for i in range(1, 13)) + tuple(f"qd[{i}]" for i in range(1, 13))


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)[0]


def fmpy_run(path, real: dict) -> tuple[list[list[float]], float, int]:
    """fmpy: the states at every communication point up to the discarded step, that step's
    start time and the fall code."""
    h = HumanFMU(str(path))
    h.setup(real)
    f = h.fmu
    states = [f.getReal(h.vrs(STATE))]
    k = 0
    while True:
        try:
            f.doStep(k * 1e-3, 1e-3)
        except FMICallException as e:
            assert e.status == fmi2Discard
            break
        k += 1
        states.append(f.getReal(h.vrs(STATE)))
    assert f.getBooleanStatus(fmi2Terminated)
    last = f.getRealStatus(fmi2LastSuccessfulTime)
    assert k * 1e-3 <= last <= (k + 1) * 1e-3
    code = f.getInteger(h.vrs(["fall_code"]))[0]
    h.free()
    return states, k * 1e-3, code


@pytest.mark.parametrize("real, reason", [({}, FallReason.FRICTION_CONE),
                                          ({"max_step_time": 0.1}, FallReason.PHASE_STALLED)])
def test_libcosim_runs_the_fmu_to_its_end(fmu_path, real, reason):
    states, t_end, code = fmpy_run(fmu_path, real)
    assert code == reason
    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_step_size(step_size=DT_NS)
    i = ex.add_local_slave(CosimLocalSlave(fmu_path=str(fmu_path), instance_name="human"))
    vr = {v.name.decode(): v.reference for v in ex.slave_variables(i)}
    for name, value in real.items():
        ex.real_initial_value(i, vr[name], value)
    series = CosimObserver.create_time_series()
    ex.add_observer(series)
    for name in STATE:
        series.start_time_series(i, vr[name], CosimVariableType.REAL)
    n = 0
    while ex.step():
        n += 1
        assert n <= len(states), "libcosim steps on past fmpy's discarded step"
    status = ex.status()
    assert CosimExecutionState(status.state) is CosimExecutionState.ERROR
    assert "Step not complete" in get_last_error_message()
    assert status.current_time == round(t_end * 1e9) == n * DT_NS
    # libcosim samples after every completed step (steps 1..n)
    samples = [series.time_series_real_samples(i, vr[name], from_step=1, sample_count=n)
               for name in STATE]
    assert all(list(s[1]) == list(range(1, n + 1)) for s in samples)
    seen = np.array([s[2] for s in samples]).T
    assert seen.shape == (n, len(STATE))
    assert np.abs(seen - np.array(states[1:])).max() <= 1e-12

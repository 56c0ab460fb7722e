"""The human FMU at run time: in a Python without this project, two instances in one
process, reset, free and re-instantiation, FMU state, and bad parameters or calls that fail
with an FMI error status and a log message (never a crash)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from fmpy import calloc, free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2Discard,
    fmi2Error,
    fmi2LastSuccessfulTime,
    fmi2Terminated,
)

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.falls import FallReason
from hp_model.simulator import SimOptions
from tests.fmu_runner import HumanFMU, NominalPD, run, stepper
from tests.fmu_support import built_fmu, policy_table, python_run, simulator, start_state

RUNNER = Path(__file__).with_name("fmu_runner.py")
PROJECT = ("hp_model", "characterization", "human_fmu", "orchestrator", "prosthesis_controller",
           "bus_schemas", "tests")


@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)[0]


@pytest.fixture(scope="module")
def table(model, template_gait):
    return policy_table(model, template_gait, simulator(model, template_gait))


class Logger:
    """fmpy callbacks that collect the FMU's log messages."""

    def __init__(self) -> None:
        self.messages: list[tuple[int, str, str]] = []
        self._fn = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = self._fn
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)

    def _log(self, env, name, status, category, message) -> None:
        self.messages.append((status, category.decode(), message.decode()))

    def errors(self) -> list[str]:
        return [m for s, _, m in self.messages if s >= fmi2Error]


# -- a Python without this project ---------------------------------------------------------
ISOLATED = """
import importlib.abc, importlib.util, runpy, sys
sys.path.append({site!r})
missing = [m for m in {project!r} if importlib.util.find_spec(m) is not None]
assert not missing, f"project packages importable: {{missing}}"
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split(".")[0] in {blocked!r}:
            raise ImportError(name + " is blocked in this test")
sys.meta_path.insert(0, Block())
sys.argv = ["fmu_runner.py", *{args!r}]
try:
    runpy.run_path("fmu_runner.py", run_name="__main__")
except SystemExit as e:
    assert e.code == 0, e.code
mods = sorted(m for m in sys.modules if m.split(".")[0] in {blocked!r})
assert not mods, mods
print("isolated run ok")
"""


def test_runs_in_a_python_without_this_project(fmu_path, model, template_gait, table,
                                                tmp_path):
    """Python -I -S (no site: the editable install of this project is not on the path), only
    the site-packages folder appended for fmpy and numpy, CasADi blocked, cwd elsewhere."""
    work = tmp_path / "elsewhere"
    work.mkdir()
    (work / "fmu_runner.py").write_text(RUNNER.read_text())
    sim = simulator(model, template_gait)
    pd = NominalPD(table)
    ref = python_run(sim, pd, *start_state(template_gait), steps=10)
    spec = {"policy": table, "periods": int(ref.t.size), "dt": 1e-3, "tau_from": "output"}
    (work / "spec.json").write_text(json.dumps(spec))
    code = ISOLATED.format(site=sysconfig.get_paths()["purelib"], project=PROJECT,
                           blocked=(*PROJECT, "casadi"),
                           args=[str(fmu_path), "spec.json", "out.json"])
    r = subprocess.run([sys.executable, "-I", "-S", "-c", code], cwd=work, env={},
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "isolated run ok" in r.stdout
    log = json.loads((work / "out.json").read_text())
    assert not log["fall"]
    angles = np.array(log["sensors"])[:, 0:2]
    assert np.abs(angles - ref.q[:, 10:12]).max() <= 1e-6
    t_ref = np.array([i.t for i in ref.impacts])
    assert len(log["impacts"]) == 10
    assert np.abs(np.array(log["impacts"]) - t_ref).max() < 0.5e-3


# -- instances ----------------------------------------------------------------------------------
def _solo(path, table, periods, factor=1.0):
    t = json.loads(json.dumps(table))
    for d in PAPER_DOMAINS:
        t["nominal"][d]["u"] = (factor * np.array(t["nominal"][d]["u"])).tolist()
    h = HumanFMU(str(path))
    h.setup()
    log = run(h, NominalPD(t), periods, tau_from="q")
    h.free()
    return log, NominalPD(t)


def test_two_instances_in_one_process(fmu_path, table):
    """Interleaved step by step, with different policies, each instance walks exactly as it
    does alone."""
    n = 900
    solo_a, pd_a = _solo(fmu_path, table, n)
    solo_b, pd_b = _solo(fmu_path, table, n, factor=0.5)
    a, b = HumanFMU(str(fmu_path), instance="a"), HumanFMU(str(fmu_path), instance="b")
    a.setup()
    b.setup()
    log_a: dict = {}
    log_b: dict = {}
    ga = stepper(a, pd_a, n, 1e-3, "q", log_a)
    gb = stepper(b, pd_b, n, 1e-3, "q", log_b)
    for _ in range(n):
        next(ga, None)
        next(gb, None)
    a.free()
    b.free()
    assert log_a["q"] == solo_a["q"] and log_a["impacts"] == solo_a["impacts"]
    assert log_b["q"] == solo_b["q"] and log_b["fall"] == solo_b["fall"]
    assert log_a["q"] != log_b["q"]


def test_reset_and_reinstantiation_repeat_the_run(fmu_path, table):
    pd = NominalPD(table)
    h = HumanFMU(str(fmu_path))
    f = h.fmu
    h.setup(real={"offset_knee": 0.02}, integer={"substeps": 3})
    first = run(h, pd, 400, tau_from="q")
    f.reset()  # all variables back to their start values
    assert f.getInteger(h.vrs(["substeps"])) == [SimOptions().substeps]
    assert f.getReal(h.vrs(["offset_knee"])) == [0.0]
    h.setup(real={"offset_knee": 0.02}, integer={"substeps": 3})
    again = run(h, pd, 400, tau_from="q")
    assert again["q"] == first["q"]
    f.reset()
    h.setup()
    nominal = run(h, pd, 400, tau_from="q")
    h.free()
    h2 = HumanFMU(str(fmu_path))  # the library was closed by freeInstance: load it again
    h2.setup()
    assert run(h2, pd, 400, tau_from="q")["q"] == nominal["q"]
    h2.free()
    assert nominal["q"] != first["q"]


def test_fmu_state_rollback(fmu_path, table):
    pd = NominalPD(table)
    h = HumanFMU(str(fmu_path))
    f = h.fmu
    h.setup()
    uv = h.vrs(["u_knee", "u_ankle"])
    qv = h.vrs([f"q[{i}]" for i in range(1, 13)])

    def walk(k0, n):
        out = []
        for k in range(k0, k0 + n):
            q = np.array(f.getReal(qv))
            d = Domain.from_code(f.getInteger(h.vrs(["domain"]))[0])
            y = f.getReal(h.vrs(["knee_angle", "ankle_angle", "knee_velocity",
                                 "ankle_velocity"]))
            f.setReal(uv, pd(d, pd.phase(d, q), np.array(y[:2]), np.array(y[2:])).tolist())
            f.doStep(k * 1e-3, 1e-3)
            out.append(f.getReal(qv))
        return out

    walk(0, 300)
    state = f.getFMUstate()
    first = walk(300, 300)
    f.setFMUstate(state)
    assert walk(300, 300) == first
    f.freeFMUstate(state)
    h.free()


# -- errors -------------------------------------------------------------------------------------
BAD = [
    ({}, {"substeps": 0}, "substeps"),
    ({}, {"substeps": -3}, "substeps"),
    ({}, {"event_iters": 0}, "event_iters"),
    ({}, {"cone_periods": 0}, "cone_periods"),
    ({}, {"initial_domain": 2}, "initial_domain"),
    ({"theta_ps[33]": -1.0}, {}, "p_max"),
    ({"theta_pns[1]": math.nan}, {}, "not finite"),
    ({"human_perturbation": -0.1}, {}, "human_perturbation"),
    ({"event_tol": 0.0}, {}, "event_tol"),
    ({"q0[8]": 0.05}, {}, "socket"),
    ({"q0[2]": 1.5}, {}, "not flat"),
]


@pytest.mark.parametrize(("real", "integer", "words"), BAD)
def test_bad_parameters_fail_initialization(fmu_path, real, integer, words):
    log = Logger()
    h = HumanFMU(str(fmu_path), callbacks=log.callbacks)
    f = h.fmu
    f.setupExperiment(startTime=0.0)
    if real:
        f.setReal(h.vrs(real), list(real.values()))
    if integer:
        f.setInteger(h.vrs(integer), list(integer.values()))
    f.enterInitializationMode()
    with pytest.raises(FMICallException) as e:
        f.exitInitializationMode()
    assert e.value.status == fmi2Error
    assert any(words in m for m in log.errors()), log.messages
    with pytest.raises(FMICallException):  # the instance refuses to step
        f.doStep(0.0, 1e-3)
    f.reset()  # and recovers after a reset
    h.setup()
    f.doStep(0.0, 1e-3)
    h.free()


def test_bad_calls_are_errors_not_crashes(fmu_path):
    log = Logger()
    h = HumanFMU(str(fmu_path), callbacks=log.callbacks)
    f = h.fmu
    with pytest.raises(FMICallException):
        f.doStep(0.0, 1e-3)  # before initialization
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    # initial unknowns are available in initialization mode
    knee = f.getReal(h.vrs(["knee_angle"]))[0]
    assert knee == f.getReal(h.vrs(["q0[11]"]))[0]
    f.exitInitializationMode()
    for call in (lambda: f.setInteger(h.vrs(["substeps"]), [4]),  # parameter after init
                 lambda: f.setReal(h.vrs(["knee_angle"]), [0.0]),  # an output
                 lambda: f.setString(h.vrs(["model_hash"]), ["x"]),  # a constant
                 lambda: f.getReal([10_000]),  # unknown value reference
                 lambda: f.doStep(0.0, -1e-3)):  # negative step
        with pytest.raises(FMICallException):
            call()
    f.setReal(h.vrs(["u_knee"]), [math.nan])
    with pytest.raises(FMICallException):
        f.doStep(0.0, 1e-3)
    assert len(log.errors()) == 7, log.messages
    h.fmu.freeInstance()
    # a binary with another GUID is refused at instantiation
    bad = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}", unzipDirectory=h.unzipdir,
                    modelIdentifier=h.md.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="instantiate"):
        bad.instantiate(callbacks=log.callbacks)
    assert any("GUID" in m for m in log.errors())
    bad.freeLibrary()


def test_torque_inputs_are_bounded_by_the_device_limits(fmu_path, model):
    """A master that bypasses the bus is bounded too: torque inputs beyond the device's motor
    limits are applied at the limits (the ``u`` outputs) and counted (``torque_clamped``);
    inputs within them pass unchanged."""
    lim = [float(x) for x in model.torque_limits[4:6]]
    h = HumanFMU(str(fmu_path))
    f = h.fmu
    h.setup()
    uv, out = h.vrs(["u_knee", "u_ankle"]), h.vrs(["u[5]", "u[6]"])
    count = h.vrs(["torque_clamped"])
    f.setReal(uv, [10 * lim[0], -10 * lim[1]])
    assert f.getReal(out) == pytest.approx([lim[0], -lim[1]], abs=1e-12)
    assert f.getInteger(count) == [2]  # each input value beyond its limit
    f.doStep(0.0, 1e-3)
    f.setReal(uv, [0.5 * lim[0], -0.25 * lim[1]])
    assert f.getReal(out) == pytest.approx([0.5 * lim[0], -0.25 * lim[1]], abs=1e-12)
    f.doStep(1e-3, 1e-3)
    assert f.getInteger(count) == [2]
    h.free()


# -- the end of the walk --------------------------------------------------------------------------
OUTPUTS = ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load",
           "socket_pitch", "tau", "stance_Fx", "stance_Fz", "socket_Fx", "socket_Fz",
           *(f"q[{i}]" for i in range(1, 13)), *(f"qd[{i}]" for i in range(1, 13)))


def _walk_to_the_end(h: HumanFMU, torque: float, periods: int = 3000):
    """Step with a constant knee torque until doStep discards: (period, time before the
    discarded step, the outputs before it)."""
    f = h.fmu
    f.setReal(h.vrs(["u_knee", "u_ankle"]), [torque, 0.0])
    out = h.vrs(OUTPUTS)
    for k in range(periods):
        before = f.getReal(out)
        try:
            f.doStep(k * 1e-3, 1e-3)
        except FMICallException as e:
            assert e.status == fmi2Discard
            return k, k * 1e-3, before
    raise AssertionError("the walker did not fall")


@pytest.mark.parametrize(("params", "code"),
                         [({}, None), ({"max_speed": 0.5}, FallReason.DIVERGED)])
def test_a_fall_ends_the_walk_through_fmi(fmu_path, params, code):
    """A fall (no prosthesis torque: the knee buckles; or a speed bound the first step
    exceeds: code 8) ends the walk the FMI 2.0 way: the step returns fmi2Discard, and so
    does every later one; fmi2Terminated is true; fmi2LastSuccessfulTime is the time of the
    state held; every output is finite (for code 8 the state before the step); the warning
    logged names the reason with the message generated from FallReason."""
    log = Logger()
    h = HumanFMU(str(fmu_path), callbacks=log.callbacks)
    h.setup(params)
    f = h.fmu
    _k, t0, before = _walk_to_the_end(h, 0.0)
    fall_code = f.getInteger(h.vrs(["fall_code"]))[0]
    assert f.getBoolean(h.vrs(["fall"]))[0] and fall_code > 0
    if code is not None:
        assert fall_code == code
    why = f"(code {fall_code}: {FallReason(fall_code).description})"
    assert [m for s, c, m in log.messages if c == "logEvents" and why in m], log.messages
    assert f.getBooleanStatus(fmi2Terminated)
    after = f.getReal(h.vrs(OUTPUTS))
    assert all(math.isfinite(v) for v in after)
    last = f.getRealStatus(fmi2LastSuccessfulTime)
    if fall_code in (FallReason.NON_FINITE, FallReason.FRICTION_CONE, FallReason.DIVERGED):
        # the state at the start of the step is held
        assert last == t0 and after[len(OUTPUTS) - 24:] == before[len(OUTPUTS) - 24:]
    else:
        assert last == pytest.approx(t0 + 1e-3, abs=1e-12)
    for j in range(1, 4):  # ended: every later step is discarded, nothing moves
        with pytest.raises(FMICallException) as e:
            f.doStep(t0 + j * 1e-3, 1e-3)
        assert e.value.status == fmi2Discard
    assert f.getReal(h.vrs(OUTPUTS)) == after
    assert f.getRealStatus(fmi2LastSuccessfulTime) == last
    h.free()

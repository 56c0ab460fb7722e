"""The FMI 3.0 variant of the human FMU (``hpcosim fmu build --fmi 3``): fmpy validates it, its
value references are unique, it walks bit for bit like the FMI 2.0 FMU built from the same
gait, and a fall ends its run through FMI 3.0's own path (terminateSimulation)."""

from __future__ import annotations

import math
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from hp_model.domains import Domain
from human_fmu import MODEL_IDENTIFIER
from human_fmu.fmi3 import PLATFORM_TUPLE, VR_TIME
from tests.fmu_runner import HumanFMU, NominalPD
from tests.fmu_support import built_fmu, policy_table, simulator

FMI3_DISCARD = 2


@pytest.fixture(scope="module")
def built3(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait, fmi_version=3)


@pytest.fixture(scope="module")
def built2(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)


class Human3:
    """An fmpy FMU3Slave of the FMI 3.0 human FMU with name-based value references."""

    def __init__(self, path: Path) -> None:
        self.md = read_model_description(str(path))
        self.unzipdir = extract(str(path))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=self.unzipdir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName="human3")
        self.fmu.instantiate()
        self.fmu.enterInitializationMode(startTime=0.0)
        self.fmu.exitInitializationMode()

    def vrs(self, names) -> list[int]:
        return [self.vr[n] for n in names]

    def free(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self.unzipdir, ignore_errors=True)


def test_fmpy_validates_the_fmi3_fmu_and_its_layout(built3):
    fmu = built3[0]
    assert validate_fmu(str(fmu)) == []
    with zipfile.ZipFile(fmu) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", f"binaries/{PLATFORM_TUPLE}/{MODEL_IDENTIFIER}.so",
            "sources/hpfmu3.c", "sources/hpfmu_core.inc", "sources/hpfmu_casadi.inc",
            "sources/hpfmu_config.h", "sources/fmi3Functions.h",
            "sources/fmi3FunctionTypes.h", "sources/fmi3PlatformTypes.h",
            "sources/buildDescription.xml"} <= names
    assert not any(n.startswith("sources/fmi2") for n in names)
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "3.0" and md.coSimulation is not None
    vrs = [v.valueReference for v in md.modelVariables]
    assert len(vrs) == len(set(vrs))  # FMI 3.0: unique over all variables
    time = [v for v in md.modelVariables if v.causality == "independent"]
    assert [(v.name, v.type, v.valueReference) for v in time] == [("time", "Float64", VR_TIME)]
    types = {v.type for v in md.modelVariables}
    assert types == {"Float64", "Int32", "Boolean", "String"}


def test_fmi3_binary_exports_only_fmi3_functions(built3, tmp_path):
    if shutil.which("nm") is None:
        pytest.skip("binutils not installed")
    with zipfile.ZipFile(built3[0]) as zf:
        so = Path(zf.extract(f"binaries/{PLATFORM_TUPLE}/{MODEL_IDENTIFIER}.so", tmp_path))
    out = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True,
                         text=True, check=True).stdout
    syms = {ln.split()[-1] for ln in out.splitlines() if " T " in ln}
    assert syms and all(s.startswith("fmi3") for s in syms), sorted(syms)
    # fmpy binds every function of the FMI 3.0 API: all of them are there
    assert {"fmi3DoStep", "fmi3InstantiateCoSimulation", "fmi3GetFloat64",
            "fmi3InstantiateModelExchange", "fmi3GetClock", "fmi3ActivateModelPartition"} <= syms


def _outputs(md) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for v in md.modelVariables:
        if v.causality == "output":
            out.setdefault(v.type, []).append(v.name)
    return out


def test_fmi3_walks_bit_for_bit_like_fmi2(built2, built3, model, template_gait):
    """The same nominal-PD prosthesis policy (computed from the FMI 2.0 outputs) applied to
    both FMUs: every output of every period, the feedthrough forces after the inputs and the
    time are identical bit for bit over 10 steps (the same generated C and core)."""
    sim = simulator(model, template_gait)
    pd = NominalPD(policy_table(model, template_gait, sim))
    h2 = HumanFMU(str(built2[0]))
    h2.setup()
    h3 = Human3(built3[0])
    out2, out3 = _outputs(h2.md), _outputs(h3.md)
    assert out2["Real"] == out3["Float64"] and out2["Integer"] == out3["Int32"]
    real2, real3 = h2.vrs(out2["Real"]), h3.vrs(out3["Float64"])
    int2, int3 = h2.vrs(out2["Integer"]), h3.vrs(out3["Int32"])
    bool2, bool3 = h2.vrs(out2["Boolean"]), h3.vrs(out3["Boolean"])
    u2, u3 = h2.vrs(["u_knee", "u_ankle"]), h3.vrs(["u_knee", "u_ankle"])
    names = out2["Real"]
    i_tau, i_knee = names.index("tau"), names.index("knee_angle")
    i_ankle, i_vk = names.index("ankle_angle"), names.index("knee_velocity")
    i_va = names.index("ankle_velocity")
    i_steps, i_dom = out2["Integer"].index("steps"), out2["Integer"].index("domain")
    dt, steps, k = 1e-3, 0, 0
    try:
        while steps < 10:
            y2, y3 = h2.fmu.getReal(real2), h3.fmu.getFloat64(real3)
            assert np.array(y2).tobytes() == np.array(y3).tobytes(), f"period {k}"
            i2, i3 = h2.fmu.getInteger(int2), h3.fmu.getInt32(int3)
            assert list(i2) == list(i3), f"period {k}"
            assert list(h2.fmu.getBoolean(bool2)) == list(h3.fmu.getBoolean(bool3))
            assert h3.fmu.getFloat64([VR_TIME])[0] == pytest.approx(k * dt, abs=1e-12)
            assert not h3.fmu.getBoolean(h3.vrs(["fall"]))[0], f"fell at period {k}"
            steps = i2[i_steps]
            d = Domain.from_code(i2[i_dom])
            u = pd(d, y2[i_tau], np.array([y2[i_knee], y2[i_ankle]]),
                   np.array([y2[i_vk], y2[i_va]])).tolist()
            h2.fmu.setReal(u2, u)
            h3.fmu.setFloat64(u3, u)
            f2, f3 = h2.fmu.getReal(real2), h3.fmu.getFloat64(real3)  # after the inputs
            assert np.array(f2).tobytes() == np.array(f3).tobytes(), f"period {k}"
            h2.fmu.doStep(k * dt, dt)
            event, terminate, early, last = h3.fmu.doStep(k * dt, dt)
            assert (event, terminate, early) == (False, False, False)
            assert last == k * dt + dt
            k += 1
            assert k < 20_000, "10 steps take about 3 s on the template gait"
    finally:
        h2.free()
        h3.free()
    assert steps == 10


def test_a_fall_ends_the_fmi3_run_through_terminate_simulation(built3):
    """Saturated torques make the walker fall: that doStep returns fmi3OK with
    terminateSimulation and lastSuccessfulTime = the time of the state held; every later
    doStep is fmi3Discard and changes nothing; the outputs stay finite."""
    h = Human3(built3[0])
    f = h.fmu
    reals = [v.valueReference for v in h.md.modelVariables
             if v.causality == "output" and v.type == "Float64"]
    try:
        f.setFloat64(h.vrs(["u_knee", "u_ankle"]), [1e6, -1e6])  # clamped to the limits
        dt, k, last = 1e-3, 0, None
        while k < 5000:
            _, terminate, early, last = f.doStep(k * dt, dt)
            assert not early
            k += 1
            if terminate:
                break
        assert terminate, "saturated torques should end the walk within 5 s"
        assert (k - 1) * dt <= last <= k * dt + 1e-12
        assert f.getBoolean(h.vrs(["fall"]))[0]
        code = f.getInt32(h.vrs(["fall_code"]))[0]
        assert 1 <= code <= 8
        held = f.getFloat64(reals)
        assert all(math.isfinite(x) for x in held)
        assert f.getFloat64([VR_TIME])[0] == last
        with pytest.raises(FMICallException) as e:
            f.doStep(k * dt, dt)
        assert e.value.status == FMI3_DISCARD
        assert f.getFloat64(reals) == held and f.getFloat64([VR_TIME])[0] == last
    finally:
        h.free()


def test_fmpy_simulate_stops_at_the_fall(built3):
    """fmpy's own FMI 3.0 co-simulation loop (no inputs: zero torque) ends at the fall
    through terminateSimulation, with finite results."""
    res = simulate_fmu(str(built3[0]), stop_time=5.0, output_interval=1e-3,
                       output=["knee_angle", "tau", "fall"])
    assert res["fall"][-1] and not res["fall"][0]
    assert res["time"][-1] < 5.0
    assert np.all(np.isfinite(res["knee_angle"])) and np.all(np.isfinite(res["tau"]))


def test_the_fmi2_drivers_refuse_an_fmi3_fmu_clearly(built3):
    """The co-simulation and the sweeps drive FMI 2.0; given the 3.0 FMU they say so."""
    from human_fmu import FmuBuildError
    from human_fmu.instance import HumanFmu

    with pytest.raises(FmuBuildError, match=r"an FMI 3.0 FMU; the co-simulation and the sweeps "
                       r"drive FMI 2.0 FMUs"):
        HumanFmu(built3[0])

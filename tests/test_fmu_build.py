"""Building the human FMU: fmpy validation, layout, model description, embedded hashes,
refusal of a gait of another model, the CLI verb, and rebuilding from the shipped sources."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.model_description import read_build_description
from fmpy.validation import validate_fmu

from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.falls import FallReason
from hp_model.simulator import SimOptions
from human_fmu import MODEL_IDENTIFIER, FmuBuildError, build_fmu
from human_fmu.build import FMU_CFLAGS
from tests.fmu_runner import HumanFMU, NominalPD, run
from tests.fmu_support import built_fmu, policy_table, simulator

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def built(tmp_path_factory, model, template_gait):
    return built_fmu(tmp_path_factory, model, template_gait)


def test_fmpy_validation_reports_no_problem(built):
    assert validate_fmu(str(built[0])) == []


def test_layout_is_a_source_and_binary_fmu(built):
    with zipfile.ZipFile(built[0]) as zf:
        names = set(zf.namelist())
    assert {"modelDescription.xml", f"binaries/linux64/{MODEL_IDENTIFIER}.so",
            "sources/hpfmu.c", "sources/hpfmu_casadi.inc", "sources/hpfmu_config.h",
            "sources/fmi2Functions.h", "sources/fmi2FunctionTypes.h",
            "sources/fmi2TypesPlatform.h", "sources/buildDescription.xml",
            "resources/build_info.json"} <= names
    md = read_model_description(str(built[0]))
    assert md.buildConfigurations[0].sourceFileSets[0].sourceFiles == ["hpfmu.c"]
    bd = read_build_description(str(built[0]))  # validated against the FMI 3 schema
    assert bd[0].modelIdentifier == MODEL_IDENTIFIER
    assert bd[0].sourceFileSets[0].sourceFiles == ["hpfmu.c"]


def test_binary_needs_only_the_c_library_and_exports_only_fmi(built, tmp_path):
    if shutil.which("readelf") is None or shutil.which("nm") is None:
        pytest.skip("binutils not installed")
    with zipfile.ZipFile(built[0]) as zf:
        so = Path(zf.extract(f"binaries/linux64/{MODEL_IDENTIFIER}.so", tmp_path))
    dyn = subprocess.run(["readelf", "-d", str(so)], capture_output=True, text=True).stdout
    needed = {ln.split("[")[1].split("]")[0] for ln in dyn.splitlines() if "NEEDED" in ln}
    assert needed <= {"libm.so.6", "libc.so.6"}, needed
    syms = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True,
                          text=True).stdout.splitlines()
    exported = {ln.split()[2] for ln in syms if len(ln.split()) == 3}
    assert exported and all(s.startswith("fmi2") for s in exported), exported


def test_model_description_variables(built, model, template_gait):
    md = read_model_description(str(built[0]), validate_model_structure=True)
    assert md.fmiVersion == "2.0" and md.coSimulation is not None and md.modelExchange is None
    v = {x.name: x for x in md.modelVariables}
    assert [n for n, x in v.items() if x.causality == "input"] == ["u_knee", "u_ankle"]
    assert v["u_knee"].unit == "N.m" and v["knee_angle"].unit == "rad"
    assert v["foot_load"].unit == "N" and v["socket_My"].unit == "N.m"
    assert v["q[1]"].unit == "m" and v["q[3]"].unit == "rad" and v["qd[2]"].unit == "m/s"
    for name in ("knee_angle", "ankle_angle", "knee_velocity", "ankle_velocity", "foot_load",
                 "foot_contact", "socket_Fx", "socket_Fz", "socket_My", "tau", "domain",
                 "steps", "fall", "fall_code", "t_impact", *[f"q[{i}]" for i in range(1, 13)],
                 *[f"qd[{i}]" for i in range(1, 13)]):
        assert v[name].causality == "output", name
    for d in PAPER_DOMAINS:
        th = np.array([float(v[f"theta_{d}[{i}]"].start) for i in range(1, 34)])
        assert np.array_equal(th, template_gait.theta(d))
    q0 = np.array([float(v[f"q0[{i}]"].start) for i in range(1, 13)])
    assert np.array_equal(q0, template_gait.trajectory[Domain.PS]["q"][:, 0])
    assert v["substeps"].type == "Integer" and int(v["substeps"].start) == SimOptions().substeps
    assert v["model_hash"].start == model.parameter_hash()
    assert v["gait_hash"].start == template_gait.hash()
    # outputs: only the forces and torques feed through from the inputs
    idx = {x: i + 1 for i, x in enumerate(md.modelVariables)}
    inputs = {idx[v["u_knee"]], idx[v["u_ankle"]]}
    deps = {u.variable.name: {idx[d] for d in u.dependencies} for u in md.outputs}
    assert deps["socket_Fz"] == inputs and deps["foot_load"] == inputs
    assert deps["knee_angle"] == set() and deps["q[5]"] == set()
    assert {u.variable.name for u in md.initialUnknowns} == set(deps)
    info = json.loads(zipfile.ZipFile(built[0]).read("resources/build_info.json"))
    assert info["model_hash"] == model.parameter_hash()
    assert info["gait_hash"] == template_gait.hash()


def test_fall_codes_and_messages_are_generated_from_fall_reason(built):
    """Every FallReason is a C constant of its code with its description as the message in
    the generated header, the core refers to the codes by name only, and the fall_code
    output's description lists them."""
    with zipfile.ZipFile(built[0]) as zf:
        config = zf.read("sources/hpfmu_config.h").decode()
        core = zf.read("sources/hpfmu_core.inc").decode()
    md = read_model_description(str(built[0]))
    fall_code = next(v for v in md.modelVariables if v.name == "fall_code")
    for r in FallReason:
        assert f"#define HP_FALL_{r.name} {int(r)}\n" in config, r
        assert f"HP_FALL_{r.name}" in core, r  # every reason is decided or tested by name
        assert f"{int(r)} {r.description}" in fall_code.description, r
        if r is not FallReason.NONE:
            assert f'case HP_FALL_{r.name}: return "{r.description}";' in config, r
    assert "fall_reason(int code)" not in core and "fall_reason(code)" in core
    for k in range(1, len(FallReason)):  # no bare code left in the core
        assert f"set_fall(c, {k})" not in core and f"fall_code == {k}" not in core


def test_hashes_readable_at_runtime(built, model, template_gait):
    h = HumanFMU(str(built[0]))
    assert h.fmu.getString(h.vrs(["model_hash", "gait_hash"])) == [
        model.parameter_hash().encode(), template_gait.hash().encode()]
    h.fmu.freeInstance()


def _other_model_gait(path: Path, out: Path) -> Path:
    doc = json.loads(path.read_text())
    doc["model_hash"] = "0123456789abcdef"
    doc.pop("gait_hash")
    out.write_text(json.dumps(doc))
    return out


def test_gait_of_another_model_is_refused(built, model, tmp_path):
    bad = _other_model_gait(built[1], tmp_path / "other.json")
    with pytest.raises(FmuBuildError, match="model_hash"):
        build_fmu(bad, tmp_path / "x.fmu", model=model)
    with pytest.raises(FmuBuildError, match=r"\.fmu"):
        build_fmu(built[1], tmp_path / "x.zip", model=model)
    assert not (tmp_path / "x.fmu").exists()
    doc = json.loads(built[1].read_text())
    doc["trajectory"] = {}
    doc.pop("gait_hash")
    (tmp_path / "notraj.json").write_text(json.dumps(doc))
    with pytest.raises(FmuBuildError, match="initial state"):
        build_fmu(tmp_path / "notraj.json", tmp_path / "x.fmu", model=model)


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "orchestrator.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def test_cli_build(built, tmp_path):
    r = _cli("fmu", "build", "--gait", str(built[1]), "--out", str(tmp_path / "h.fmu"),
             cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "fmpy validate" in r.stdout and "ok" in r.stdout
    assert validate_fmu(str(tmp_path / "h.fmu")) == []
    # same inputs, same GUID
    assert read_model_description(str(tmp_path / "h.fmu")).guid == \
        read_model_description(str(built[0])).guid
    bad = _other_model_gait(built[1], tmp_path / "other.json")
    r = _cli("fmu", "build", "--gait", str(bad), "--out", str(tmp_path / "b.fmu"), cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hpcosim: error:") and "model_hash" in lines[0]
    assert not (tmp_path / "b.fmu").exists()
    r = _cli("fmu", "build", "--help", cwd=tmp_path)
    assert r.returncode == 0 and "--gait" in r.stdout


def _walk(unzipdir: Path, fmu: Path, pd: NominalPD, periods: int) -> dict:
    h = HumanFMU(str(fmu), unzipdir=str(unzipdir))
    h.setup()
    log = run(h, pd, periods, tau_from="q")
    h.free()
    return log


@pytest.mark.slow
def test_rebuild_from_sources(built, model, template_gait, tmp_path):
    """The README's one-line rebuild and fmpy's CMake build both give a binary that walks
    exactly like the shipped one."""
    fmu = built[0]
    pd = NominalPD(policy_table(model, template_gait, simulator(model, template_gait)))
    ref_dir = tmp_path / "ref"
    zipfile.ZipFile(fmu).extractall(ref_dir)
    ref = _walk(ref_dir, fmu, pd, 800)
    assert len(ref["impacts"]) >= 2

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc is not None
    d = tmp_path / "gcc"
    zipfile.ZipFile(fmu).extractall(d)
    so = d / "binaries" / "linux64" / f"{MODEL_IDENTIFIER}.so"
    so.unlink()
    subprocess.run([cc, *FMU_CFLAGS, "-I.", "hpfmu.c", "-o", str(so), "-lm"],
                   cwd=d / "sources", check=True, capture_output=True)
    log = _walk(d, fmu, pd, 800)
    assert log["q"] == ref["q"] and log["impacts"] == ref["impacts"]

    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed: fmpy's build_platform_binary not tried")
    from fmpy.build import build_platform_binary

    d = tmp_path / "cmake"
    zipfile.ZipFile(fmu).extractall(d)
    (d / "binaries" / "linux64" / f"{MODEL_IDENTIFIER}.so").unlink()
    (tmp_path / "cmake_build").mkdir()
    build_platform_binary(d, build_dir=tmp_path / "cmake_build")
    log = _walk(d, fmu, pd, 800)
    assert np.abs(np.array(log["q"]) - np.array(ref["q"])).max() <= 1e-9


def test_sources_link_statically_twice_with_fmi2_function_prefix(built, tmp_path):
    """FMI 2.0 static linking: every ``.c`` of ``sources/`` compiled together with
    FMI2_FUNCTION_PREFIX into a static library, twice (prefixes hpA_ and hpB_), both linked
    into one C program (tests/data/fmu_static/two_copies.c): no duplicate symbols, and each
    copy walks exactly like the shipped shared library run by fmpy (zero torque until the
    walk ends or 300 periods)."""
    from fmpy.fmi1 import FMICallException

    cc = shutil.which("cc") or shutil.which("gcc")
    assert cc is not None
    fmu = built[0]
    src = tmp_path / "fmu"
    zipfile.ZipFile(fmu).extractall(src)
    sources = sorted((src / "sources").glob("*.c"))
    libs = []
    for p in ("hpA_", "hpB_"):
        objs = []
        for c in sources:
            o = tmp_path / f"{p}{c.stem}.o"
            subprocess.run([cc, "-c", "-O2", "-std=c99", "-fno-math-errno",
                            "-ffp-contract=off", f"-DFMI2_FUNCTION_PREFIX={p}",
                            "-I", str(src / "sources"), str(c), "-o", str(o)],
                           check=True, capture_output=True)
            objs.append(str(o))
        lib = tmp_path / f"lib{p}human.a"
        subprocess.run(["ar", "rcs", str(lib), *objs], check=True, capture_output=True)
        libs.append(str(lib))
    exe = tmp_path / "two_copies"
    r = subprocess.run([cc, "-std=c99", "-I", str(src / "sources"),
                        str(ROOT / "tests" / "data" / "fmu_static" / "two_copies.c"),
                        *libs, "-lm", "-o", str(exe)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr  # a duplicate symbol would fail here

    md = read_model_description(str(fmu))
    names = [f"q[{i}]" for i in range(1, 13)] + ["knee_angle", "tau"]
    vr = {v.name: v.valueReference for v in md.modelVariables}
    periods = 300
    r = subprocess.run([str(exe), md.guid, str(periods), *(str(vr[n]) for n in names)],
                       capture_output=True, text=True, check=True)
    rows = {ln.split()[0]: ln.split()[2:] for ln in r.stdout.splitlines()}  # P ended K ...
    assert rows["hpA_"] == rows["hpB_"]
    ended, values = int(rows["hpA_"][0]), [float(v) for v in rows["hpA_"][1:]]

    h = HumanFMU(str(fmu), unzipdir=str(src))
    h.setup()
    ref_ended = -1
    for k in range(periods):
        try:
            h.fmu.doStep(k * 1e-3, 1e-3)
        except FMICallException:
            ref_ended = k
            break
    ref = h.fmu.getReal([vr[n] for n in names])
    h.free()
    assert ended == ref_ended and values == ref  # bit for bit

"""Build the human-side FMU: generate C from the CasADi model, write modelDescription.xml and
the C configuration from one variable table, compile, and zip (atomically).

FMU layout (FMI 2.0 co-simulation, model identifier ``hpcosim_human``; FMI 3.0 with
``fmi_version=3``: ``binaries/x86_64-linux``, ``sources/hpfmu3.c`` and the ``fmi3*.h``
headers, the same core and generated C, :mod:`human_fmu.fmi3`):

    modelDescription.xml
    binaries/linux64/hpcosim_human.so
    sources/hpfmu.c             the FMI 2.0 API (hand-written)
    sources/hpfmu_core.inc      the hybrid integration, checks and outputs, independent of
                                the FMI version (included by hpfmu.c)
    sources/hpfmu_casadi.inc    the plant and the human's controller (CasADi-generated,
                                included by hpfmu.c: every function in it static)
    sources/hpfmu_config.h      variables, start values, model constants and the fall codes
                                (generated; the codes from hp_model.falls.FallReason)
    sources/fmi2*.h             the FMI 2.0 headers
    sources/buildDescription.xml
    resources/build_info.json   hashes, compiler flags, timings
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import subprocess
import tempfile
import time
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from xml.etree import ElementTree as ET

import casadi as ca
import numpy as np

import hp_model
from hp_model.artifacts import ArtifactError
from hp_model.closed_loop import ClosedLoop
from hp_model.compiled import densified, find_c_compiler, generate_c
from hp_model.domains import Domain, DomainGraph
from hp_model.falls import c_definitions
from hp_model.gait_artifact import Gait, load_gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.json_io import dumps
from hp_model.simulator import SimOptions
from human_fmu.fmi3 import PLATFORM_TUPLE, config_macros, model_description_3
from human_fmu.perturbation import moved_coefficients
from human_fmu.variables import (
    Variable,
    _Table,
    add_common_elements,
    add_constants,
    build_table,
    fmt_value,
)

MODEL_IDENTIFIER = "hpcosim_human"
PLATFORM = "linux64"
#: compiler flags of the binary (README: rebuild); -ffp-contract=off keeps the arithmetic
#: identical to the in-process simulator's compiled functions on FMA-capable targets
FMU_CFLAGS = ("-shared", "-fPIC", "-O2", "-fno-math-errno", "-ffp-contract=off",
              "-fvisibility=hidden")
C_DIR = Path(__file__).parent / "c"
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: per FMI version: the API source file, its headers and the binaries folder
API = {2: ("hpfmu.c", FMI_HEADERS, PLATFORM), 3: ("hpfmu3.c", FMI3_HEADERS, PLATFORM_TUPLE)}
#: the generated functions of each domain, by their role in the C (``F_<ROLE>[d]`` of
#: hpfmu_config.h): from the closed loop, then from the model.  ``guard`` only where a
#: touchdown ends the domain, ``start`` (the walker's placement) on the paper's graph only
CLOSED_LOOP_ROLES = ("rk4k_human", "xdot_human", "phase", "start")
MODEL_ROLES = ("impact", "guard")


class FmuBuildError(RuntimeError):
    """The FMU cannot be built from these inputs (bad gait, gait of another model, no C
    compiler, compiler failure, unsupported platform)."""


@dataclass(frozen=True)
class BuildInfo:
    path: Path
    guid: str
    model_hash: str
    gait_hash: str
    degree: int
    variables: dict[str, int]  # causality -> count
    size_bytes: int
    seconds: dict[str, float]  # model, codegen, compile, total


def fmi_header_dir() -> Path:
    import fmpy

    d = Path(fmpy.__file__).parent / "c-code"
    if not (d / "fmi2Functions.h").is_file():
        raise FmuBuildError(f"FMI 2.0 headers not found in {d} (fmpy installation)")
    return d


#: fmpy's fmi2Functions.h always exports and never prefixes; FMI 2.0's own header exports
#: only without FMI2_FUNCTION_PREFIX and prefixes every API function with it (static linking
#: of source FMUs, several in one program)
_FMPY_EXPORT = re.compile(
    r"/\*\s*\nExport FMI2 API functions.*?#define fmi2FullName\(name\) name\n", re.S)
_STANDARD_EXPORT = """/* FMI 2.0: without FMI2_FUNCTION_PREFIX (a shared library) the API functions
   are exported under their own names; with it (a source FMU linked statically) each is
   named FMI2_FUNCTION_PREFIX ## name and not exported. */
#if !defined(FMI2_FUNCTION_PREFIX)
  #if !defined(FMI2_Export)
    #if defined _WIN32 || defined __CYGWIN__
      #define FMI2_Export __declspec(dllexport)
    #elif __GNUC__ >= 4
      #define FMI2_Export __attribute__ ((visibility ("default")))
    #else
      #define FMI2_Export
    #endif
  #endif
  #define fmi2FullName(name) name
#else
  #if !defined(FMI2_Export)
    #define FMI2_Export
  #endif
  #define fmi2Paste(a, b) a ## b
  #define fmi2PasteB(a, b) fmi2Paste(a, b)
  #define fmi2FullName(name) fmi2PasteB(FMI2_FUNCTION_PREFIX, name)
#endif
"""


def standard_fmi2_functions_h(text: str) -> str:
    """fmpy's ``fmi2Functions.h`` with FMI 2.0's export and prefix rules restored."""
    out, n = _FMPY_EXPORT.subn(lambda _m: _STANDARD_EXPORT, text)
    if n != 1:
        raise FmuBuildError("fmi2Functions.h of this fmpy does not have the expected export "
                            "block; cannot restore FMI2_FUNCTION_PREFIX")
    return out


_HELPER = re.compile(r"^(casadi_real|casadi_int|void|int) (casadi_\w+)\(", re.M)


def private_helpers(src: str) -> str:
    """CasADi's runtime helpers (``casadi_sq``, ``casadi_copy``, ...) made ``static``: with
    the generated functions (``CASADI_SYMBOL_EXPORT static``) nothing of the generated code
    is global, so two FMUs' sources link into one program."""
    return _HELPER.sub(r"static \1 \2(", src)


def function_names(model: HumanProsthesisModel) -> list[tuple[str, Domain | None, str]]:
    """(role, domain, name) of each function compiled into the FMU, in its C table's order:
    per domain of the model's graph its roles (``CLOSED_LOOP_ROLES``, ``MODEL_ROLES``), then
    the model's ``frames``."""
    out: list[tuple[str, Domain | None, str]] = []
    for d in model.graph.domains:
        for role in (*CLOSED_LOOP_ROLES, *MODEL_ROLES):
            if role == "start" and model.graph != DomainGraph.PAPER:
                continue
            if role == "guard" and model.domains[d].swing_frame is None:
                continue
            out.append((role, d, f"{role}_{d}"))
    return [*out, ("frames", None, "frames")]


def fmu_functions(model: HumanProsthesisModel, cl: ClosedLoop) -> list[ca.Function]:
    """The CasADi functions compiled into the FMU (the ones HybridSimulator calls), in the
    order of :func:`function_names`."""
    return [densified(cl.functions[name] if role in CLOSED_LOOP_ROLES else
                      model.functions[name])
            for role, _d, name in function_names(model)]


# -- modelDescription.xml -----------------------------------------------------------------------
def model_description(table: _Table, guid: str, *, description: str, generated: str,
                      annotations: dict[str, str]) -> str:
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": MODEL_IDENTIFIER, "guid": guid,
        "description": description, "author": "hpcosim",
        "version": hp_model.__version__,
        "generationTool":
            f"hpcosim human_fmu {hp_model.__version__} (CasADi {ca.CasadiMeta.version()})",
        "generationDateAndTime": generated, "variableNamingConvention": "flat",
        "numberOfEventIndicators": "0"})
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": MODEL_IDENTIFIER, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "true", "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "false", "providesDirectionalDerivative": "false"})
    sf = ET.SubElement(cs, "SourceFiles")
    ET.SubElement(sf, "File", {"name": "hpfmu.c"})
    add_common_elements(root, table)
    va = ET.SubElement(root, "VendorAnnotations")
    ET.SubElement(ET.SubElement(va, "Tool", {"name": "hpcosim"}), "Build", annotations)
    mv = ET.SubElement(root, "ModelVariables")
    index: dict[str, int] = {}
    for k, v in enumerate(table.vars, start=1):
        index[v.name] = k
        attrs = {"name": v.name, "valueReference": str(v.vr), "description": v.description,
                 "causality": v.causality, "variability": v.variability}
        if v.initial is not None and v.causality != "local":
            attrs["initial"] = v.initial
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        tattrs: dict[str, str] = {}
        if v.unit:
            tattrs["unit"] = v.unit
        if v.start is not None:
            tattrs["start"] = fmt_value(v.start)
        ET.SubElement(sv, v.type, tattrs)
    ms = ET.SubElement(root, "ModelStructure")
    inputs = " ".join(str(index[v.name]) for v in table.vars if v.causality == "input")
    outs = [v for v in table.vars if v.causality == "output"]
    o = ET.SubElement(ms, "Outputs")
    for v in outs:
        ET.SubElement(o, "Unknown", {"index": str(index[v.name]),
                                     "dependencies": inputs if v.feedthrough else ""})
    iu = ET.SubElement(ms, "InitialUnknowns")
    for v in outs:
        ET.SubElement(iu, "Unknown", {"index": str(index[v.name])})
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") \
        + "\n"


def build_description(flags: Sequence[str], fmi_version: int = 2) -> str:
    source = API[fmi_version][0]
    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    bc = ET.SubElement(root, "BuildConfiguration", {
        "modelIdentifier": MODEL_IDENTIFIER,
        "description": f"one translation unit ({source} includes hpfmu_core.inc and "
                       f"hpfmu_casadi.inc); link libm; define FMI{fmi_version}_FUNCTION_PREFIX "
                       "for a static library"})
    sfs = ET.SubElement(bc, "SourceFileSet", {
        "language": "C99", "compilerOptions": " ".join(f for f in flags
                                                       if f not in ("-shared", "-fPIC"))})
    ET.SubElement(sfs, "SourceFile", {"name": source})
    ET.SubElement(bc, "Library", {"name": "m"})
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") \
        + "\n"


# -- hpfmu_config.h ---------------------------------------------------------------------------
def _c_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_double(v: float) -> str:
    r = repr(float(v))
    return r if any(ch in r for ch in ".eEn") else r + ".0"


def _c_ints(name: str, values: Sequence[int]) -> str:
    return f"static const int {name}[{len(values)}] = {{" + ", ".join(map(str, values)) + "};"


def domain_tables(cl: ClosedLoop) -> list[str]:
    """The C tables of the model's graph, indexed by a domain's place in the cycle (the
    ``domain`` output and the ``initial_domain`` parameter use ``Domain.code``): what
    :class:`hp_model.simulator.SimulationRun` reads from the model's domains."""
    model = cl.model
    graph, domains = model.graph, model.graph.domains
    place = {d: k for k, d in enumerate(domains)}
    layouts = [cl.vcs[d].layout for d in domains]
    theta_at = np.cumsum([0] + [L.size for L in layouts]).tolist()
    alpha_at = np.cumsum([0] + [L.n_alpha for L in layouts]).tolist()
    roles = model.roles
    coord = model.coord_names.index

    def trailing(d: Domain) -> int:  # the trailing contact's F_x row (F_z the next)
        return d.contacts[0].size if d.is_double_support else -1

    def lead(d: Domain) -> tuple[int, int]:  # a double support's leading sole and ankle
        if not d.is_double_support:
            return -1, -1
        leg = d.stance_leg
        return model.frame_index(leg.sole_frame), coord(leg.ankle)

    def load_row(d: Domain) -> int:  # the prosthesis contact's F_z row
        c = d.prosthesis_contact
        return -1 if c is None else model.domains[d].wrench_slice(c.name).start + 1

    fn = function_names(model)
    index = {(role, d): k for k, (role, d, _n) in enumerate(fn)}
    lines = [
        f"/* the {graph} graph: domains in walking order (their place indexes every table; "
        "the domain output reports Domain.code) */",
        f"#define HPFMU_ND {len(domains)}",
        "static const char *const HPFMU_DOMAIN_NAME[HPFMU_ND] = {"
        + ", ".join(_c_str(d) for d in domains) + "};",
        _c_ints("HPFMU_DOMAIN_CODE", [d.code for d in domains]),
        _c_ints("HPFMU_NEXT", [place[graph.next(d)] for d in domains]),
        "/* entering the domain starts a step (the paper's: every impact; else a heel strike) */",
        _c_ints("HPFMU_STARTS_STEP", [int(d in graph.step_starts) for d in domains]),
        "/* the touchdown guard armed from the domain's entry, not past guard_tau_min "
        "(DomainGraph.guard_from_entry: a landing foot already in the air) */",
        _c_ints("HPFMU_GUARD_FROM_ENTRY", [int(graph.guard_from_entry(d)) for d in domains]),
        "/* the packed gait of each domain in theta[] (hp_model.outputs.ThetaLayout): its "
        "first entry, its Bezier coefficients' count, the first of them in the perturbation's "
        "draws */",
        f"#define HPFMU_NTHETA {theta_at[-1]}",
        _c_ints("HPFMU_THETA_AT", theta_at[:-1]),
        _c_ints("HPFMU_NALPHA", [L.n_alpha for L in layouts]),
        _c_ints("HPFMU_ALPHA_AT", alpha_at[:-1]),
        "/* which of those coefficients the perturbation moves (human_fmu.perturbation: on the "
        "multi-contact graph each curve keeps its ends) */",
        _c_ints("HPFMU_MOVED", [int(v) for d, L in zip(domains, layouts, strict=True)
                                for v in moved_coefficients(graph, d, L.n_alpha)]),
        "/* the sole landed flat at a touchdown into the domain, and its ankle (-1: none; the "
        "paper's flat stances) */",
        _c_ints("HPFMU_LANDING_FRAME", [roles[d].stance_frame_index if d in roles else -1
                                        for d in domains]),
        _c_ints("HPFMU_LANDING_ANKLE", [roles[d].ankle if d in roles else -1
                                        for d in domains]),
        "/* a double support: its trailing contact's F_x row in lam (F_z the next; -1: not "
        "one), the leading foot's sole frame and ankle, landed flat when the trailing leaves */",
        _c_ints("HPFMU_TRAILING", [trailing(d) for d in domains]),
        _c_ints("HPFMU_LEAD_SOLE", [lead(d)[0] for d in domains]),
        _c_ints("HPFMU_LEAD_ANKLE", [lead(d)[1] for d in domains]),
        "/* rows of lam: the prosthesis foot's normal force (-1: it swings), the socket "
        "wrench's first; whether the first contact (the stance) has a moment (a flat sole) */",
        _c_ints("HPFMU_LOAD_ROW", [load_row(d) for d in domains]),
        _c_ints("HPFMU_SOCKET_AT", [model.domains[d].wrench_slice("socket").start
                                    for d in domains]),
        _c_ints("HPFMU_STANCE_FLAT", [int(d.contacts[0].is_flat) for d in domains]),
        "/* the first contact's frame: on the ground at the start (and level if flat) */",
        _c_ints("HPFMU_CONTACT_FRAME", [model.frame_index(d.contacts[0].frame)
                                        for d in domains]),
        "/* the generated functions (hpfmu_casadi.inc) and each domain's by role (-1: none) */",
        "typedef int (*cs_eval)(const casadi_real **, casadi_real **, casadi_int *, "
        "casadi_real *, int);",
        "typedef int (*cs_work)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);",
        f"#define N_FN {len(fn)}",
        "static const cs_eval FN[N_FN] = {" + ", ".join(n for *_r, n in fn) + "};",
        "static const cs_work FN_WORK[N_FN] = {" + ", ".join(f"{n}_work" for *_r, n in fn)
        + "};",
        *(_c_ints(f"F_{role.split('_')[0].upper()}", [index.get((role, d), -1)
                                                      for d in domains])
          for role in (*CLOSED_LOOP_ROLES, *MODEL_ROLES)),
        f"#define F_FRAMES {index[('frames', None)]}",
    ]
    return lines


def config_header(table: _Table, cl: ClosedLoop, guid: str) -> str:
    model, degree = cl.model, cl.degree
    names = model.coord_names
    pk, pa = (names.index(c) for c in ("th_pk", "th_pa"))
    lam_width = max(dom.n_constraints for dom in model.domains.values())
    lines = [
        "/* hpfmu_config.h: generated by human_fmu.build from the variable table; do not edit */",
        "#ifndef HPFMU_CONFIG_H", "#define HPFMU_CONFIG_H", "",
        f"#define HPFMU_GUID {_c_str(guid)}",
        f"#define HPFMU_NQ {model.nq}", f"#define HPFMU_NU {model.nu}",
        f"#define HPFMU_NLAM {lam_width}",
        f"#define HPFMU_DEGREE {degree}",
        f"#define HPFMU_NFRAMES {len(model.frame_names)}",
        f"#define HPFMU_IDX_ZB {names.index('z_B')}",
        f"#define HPFMU_IDX_PK {pk}",
        f"#define HPFMU_IDX_PA {pa}",
        f"#define HPFMU_SOCKET_FIRST {names.index('x_f')}", "",
        "/* the device's motor torque limits (knee, ankle; N m): inputs are clamped to them */",
        "static const double HPFMU_TORQUE_LIMIT[2] = {"
        + ", ".join(_c_double(float(v)) for v in model.torque_limits[4:6]) + "};", "",
        *domain_tables(cl), "",
        "/* fall codes (the fall_code output) and messages: hp_model.falls.FallReason */",
        *c_definitions().splitlines(),
        *config_macros(),
        "/* socket_pitch = row . q: the world pitch of the prosthesis top link */",
        f"static const double HPFMU_SOCKET_PITCH_ROW[{model.nq}] = {{"
        + ", ".join(_c_double(v) for v in model.pitch_row("socket")) + "};", "",
    ]
    for typ in ("Real", "Integer", "Boolean", "String"):
        vs = [v for v in table.vars if v.type == typ]
        up = typ.upper()
        lines.append(f"#define HPFMU_N_{up} {len(vs)}")
        for v in vs:
            lines.append(f"#define VR_{v.macro} {v.vr}")
        kind = "".join("t" if v.variability == "tunable" else
                       {"input": "i", "output": "o", "parameter": "p", "local": "c"}[v.causality]
                       for v in vs)
        lines.append(f"static const char HPFMU_{up}_KIND[{len(vs) + 1}] = {_c_str(kind)};")
        lines.append(f"static const char *const HPFMU_{up}_NAME[{len(vs)}] = {{")
        lines += [f"  {_c_str(v.name)}," for v in vs]
        lines.append("};")
        if typ == "Real":
            vals = [_c_double(float(v.start) if v.start is not None else 0.0) for v in vs]
            lines.append(f"static const double HPFMU_REAL_START[{len(vs)}] = {{")
        elif typ == "String":
            vals = [_c_str(str(v.start)) for v in vs]
            lines.append(f"static const char *const HPFMU_STRING_START[{len(vs)}] = {{")
        else:
            vals = [str(int(v.start or 0)) for v in vs]
            lines.append(f"static const int HPFMU_{up}_START[{len(vs)}] = {{")
        lines += [f"  {x}," for x in vals]
        lines += ["};", ""]
    at = [table.arrays[f"THETA_{d.upper()}"][1] for d in model.graph.domains]
    sizes = [table.arrays[f"THETA_{d.upper()}"][2] for d in model.graph.domains]
    if at != [at[0] + sum(sizes[:k]) for k in range(len(at))]:
        raise AssertionError("the theta arrays are not consecutive in the variable table")
    lines += ["/* the domains' packed gaits: one array after the other (HPFMU_THETA_AT) */",
              f"#define VR_THETA_1 VR_THETA_{model.graph.domains[0].upper()}_1",
              "#endif", ""]
    return "\n".join(lines)


# -- build ----------------------------------------------------------------------------------
def builder_digest() -> str:
    """SHA-256 over everything besides the gait and the model parameters that decides what
    an FMU build produces: the sources of the builder, its C wrapper and headers, the model
    package (the generated C comes from it), CasADi's version and the compiler flags.  A
    cached FMU is reused only under the same digest."""
    h = hashlib.sha256()
    files = sorted([*Path(__file__).parent.glob("*.py"), *C_DIR.glob("*"),
                    *Path(hp_model.__file__).parent.glob("*.py")])
    for f in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    h.update(f"casadi {ca.CasadiMeta.version()}\0{' '.join(FMU_CFLAGS)}".encode())
    return h.hexdigest()


def _guid(*parts: str) -> str:
    h = hashlib.sha256("\0".join(parts).encode()).hexdigest()
    return f"{{{h[:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}}}"


def load_checked_gait(gait: str | os.PathLike[str], model: HumanProsthesisModel) -> Gait:
    """The gait file, refused (FmuBuildError) if invalid or made for other model parameters,
    or without the optimized initial state."""
    try:
        g = load_gait(gait, model.parameter_hash())
    except ArtifactError as e:
        raise FmuBuildError(str(e)) from None
    tr = g.trajectory.get(Domain.PS, {})
    if "q" not in tr or "qd" not in tr or tr["q"].shape[0] != model.nq:
        raise FmuBuildError(f"{gait}: field 'trajectory.ps': the optimized initial state "
                            "(q, qd) is missing; the FMU starts from it")
    return g


def _compile(cc: str, src_dir: Path, out: Path, source: str = "hpfmu.c") -> None:
    cmd = [cc, *FMU_CFLAGS, "-I", str(src_dir), str(src_dir / source), "-o", str(out), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        err = [ln for ln in proc.stderr.splitlines() if "error" in ln] or \
            proc.stderr.strip().splitlines() or ["unknown error"]
        raise FmuBuildError(f"compiling the FMU failed: {err[0]}")


def _check_target(out: Path, fmi_version: int) -> str:
    """The C compiler, once the FMI version, the output path and the platform are known to
    be buildable (else FmuBuildError)."""
    if fmi_version not in API:
        raise FmuBuildError(f"FMI version {fmi_version}: only 2 and 3 are built")
    if out.suffix != ".fmu":
        raise FmuBuildError(f"{out}: the output file must end in .fmu")
    if not out.parent.is_dir():
        raise FmuBuildError(f"{out.parent}: no such folder")
    if platform.system() != "Linux" or platform.machine() not in ("x86_64", "AMD64"):
        raise FmuBuildError(f"binaries are built for {PLATFORM} only, not "
                            f"{platform.system()} {platform.machine()}")
    cc = find_c_compiler()
    if cc is None:
        raise FmuBuildError("no C compiler found (set CC or install gcc)")
    return cc


@dataclass(frozen=True)
class TrackedGait:
    """What the FMU's human tracks and starts from, on its model's graph: the packed gait
    of each domain (:class:`hp_model.outputs.ThetaLayout`), the feedback gains (eps 1/s, kp
    1/s^2, kd 1/s), the initial state (q0, qd0) in the graph's first domain, the curves'
    Bezier degree, and the gait's identity (its hash, its file's name)."""

    thetas: Mapping[Domain, np.ndarray]
    gains: tuple[float, float, float]
    q0: np.ndarray
    qd0: np.ndarray
    degree: int
    hash: str
    name: str


def paper_tracked_gait(gait: str | os.PathLike[str], model: HumanProsthesisModel
                       ) -> TrackedGait:
    """The paper's gait file as the FMU tracks it: its optimized ps start (FmuBuildError
    if it is not a gait of ``model``)."""
    g = load_checked_gait(gait, model)
    tr = g.trajectory[Domain.PS]
    return TrackedGait({d: g.theta(d) for d in model.graph.domains},
                       (float(g.gains[0]), float(g.gains[1]), float(g.gains[2])),
                       tr["q"][:, 0], tr["qd"][:, 0], g.degree, g.hash(), Path(gait).name)


@dataclass(frozen=True)
class _Inputs:
    """What an FMU is built from: the model, the gait it tracks, the closed loop along it
    and the variable table (start values from the gait)."""

    model: HumanProsthesisModel
    gait: TrackedGait
    closed_loop: ClosedLoop
    table: _Table
    model_hash: str


def _load_inputs(gait: str | os.PathLike[str] | TrackedGait,
                 subject: str | os.PathLike[str] | None,
                 device: str | os.PathLike[str] | None,
                 model: HumanProsthesisModel | None) -> _Inputs:
    """The model (built from subject/device unless given), the gait checked against it and
    the variable table."""
    if model is None:
        if isinstance(gait, TrackedGait):
            raise ValueError("a TrackedGait is built with the model it was made for")
        model = hp_model.load_model(str(subject) if subject else None,
                                    str(device) if device else None)
    elif subject is not None or device is not None:
        raise ValueError("give either model or subject/device")
    g = gait if isinstance(gait, TrackedGait) else paper_tracked_gait(gait, model)
    if set(g.thetas) != set(model.graph.domains):
        raise FmuBuildError(f"gait {g.name}: its domains ({', '.join(map(str, g.thetas))}) "
                            f"are not the {model.graph} graph's")
    cl = ClosedLoop(model, g.degree)
    for d, th in g.thetas.items():
        if np.size(th) != cl.vcs[d].n_params:
            raise FmuBuildError(f"gait {g.name}: the {d} gait has {np.size(th)} parameters; "
                                f"degree {g.degree} on the {model.graph} graph has "
                                f"{cl.vcs[d].n_params}")
    table = build_table(model, g.thetas, g.gains, g.q0, g.qd0, g.degree, SimOptions())
    model_hash = model.parameter_hash()
    add_constants(table, model_hash, g.hash)
    return _Inputs(model=model, gait=g, closed_loop=cl, table=table, model_hash=model_hash)


@dataclass(frozen=True)
class _Sources:
    """The FMU's text files of one build: generated (CasADi C, config header, model
    description) and copied (the API wrapper, the core), with the build's GUID and time."""

    casadi: str
    wrapper: str
    core: str
    header: str
    model_description: str
    guid: str
    generated: str  # UTC, ISO 8601


def _generate_sources(inp: _Inputs, fmi_version: int) -> _Sources:
    """Generate the C and the model description; the GUID hashes everything the binary's
    behaviour depends on."""
    model, g, table = inp.model, inp.gait, inp.table
    casadi_src = private_helpers(generate_c(fmu_functions(model, inp.closed_loop),
                                            "hpfmu_casadi"))
    wrapper_src = (C_DIR / API[fmi_version][0]).read_text()
    core_src = (C_DIR / "hpfmu_core.inc").read_text()
    table_key = dumps([(v.name, v.type, v.causality, v.vr, fmt_value(v.start)
                        if v.start is not None else None) for v in table.vars])
    guid = _guid(casadi_src, wrapper_src + core_src + c_definitions(), table_key,
                 inp.model_hash, g.hash, f"fmi{fmi_version}")
    header = config_header(table, inp.closed_loop, guid)
    generated = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    annotations = {"model_hash": inp.model_hash, "gait_hash": g.hash,
                   "gait_file": g.name, "degree": str(g.degree),
                   "domain_graph": str(model.graph),
                   "subject": model.subject.name, "device": model.device.name}
    about = ("hpcosim human side: 12-DOF human-prosthesis hybrid dynamics with the human's "
             "feedback linearization along the gait; inputs: prosthesis motor torques; "
             "outputs: AMPRO3 sensors and ground truth")
    if fmi_version == 3:
        md = model_description_3(table, guid, model_identifier=MODEL_IDENTIFIER,
                                 description=about, generated=generated,
                                 annotations=annotations)
    else:
        md = model_description(table, guid, generated=generated, annotations=annotations,
                               description=about)
    return _Sources(casadi=casadi_src, wrapper=wrapper_src, core=core_src, header=header,
                    model_description=md, guid=guid, generated=generated)


def _write_tree(root: Path, srcs: _Sources, fmi_version: int, headers: Path
                ) -> tuple[Path, Path, Path]:
    """Lay out the FMU's folders under ``root`` and write its text files; returns the
    sources, binaries and resources folders."""
    api_src, api_headers, bin_dir = API[fmi_version]
    src = root / "sources"
    binp = root / "binaries" / bin_dir
    res = root / "resources"
    for p in (src, binp, res):
        p.mkdir(parents=True)
    (src / "hpfmu_casadi.inc").write_text(srcs.casadi)
    (src / api_src).write_text(srcs.wrapper)
    (src / "hpfmu_core.inc").write_text(srcs.core)
    (src / "hpfmu_config.h").write_text(srcs.header)
    for h in api_headers:
        text = (headers / h).read_text()
        (src / h).write_text(standard_fmi2_functions_h(text) if h == "fmi2Functions.h"
                             else text)
    (src / "buildDescription.xml").write_text(build_description(FMU_CFLAGS, fmi_version))
    (root / "modelDescription.xml").write_text(srcs.model_description)
    return src, binp, res


def _build_info(inp: _Inputs, srcs: _Sources, fmi_version: int, cc: str,
                seconds: dict[str, float]) -> str:
    """``resources/build_info.json``: hashes, compiler and flags, versions, timings."""
    info = {"model_identifier": MODEL_IDENTIFIER, "fmi_version": f"{fmi_version}.0",
            "guid": srcs.guid, "model_hash": inp.model_hash,
            "gait_hash": inp.gait.hash, "gait_file": inp.gait.name, "degree": inp.gait.degree,
            "domain_graph": str(inp.model.graph),
            "generated": srcs.generated, "compiler": cc, "cflags": list(FMU_CFLAGS),
            "casadi": ca.CasadiMeta.version(), "hpcosim": hp_model.__version__,
            "functions": [n for *_r, n in function_names(inp.model)], "seconds": seconds}
    return dumps(info, indent=1) + "\n"


def _zip_atomically(root: Path, out: Path) -> None:
    """Zip the tree under ``root`` into ``out`` through a temporary file next to it (a
    failed build leaves no partial FMU; mode 0o666 less the umask: hp_model.atomic_io)."""
    from hp_model.atomic_io import atomic_write_with

    def write(tmp_zip: str) -> None:
        with zipfile.ZipFile(tmp_zip, "w", zipfile.ZIP_DEFLATED) as zf:
            for p in sorted(root.rglob("*")):
                if p.is_file():
                    zf.write(p, p.relative_to(root).as_posix())

    atomic_write_with(out, write)


def build_fmu(gait: str | os.PathLike[str] | TrackedGait, out: str | os.PathLike[str],
              subject: str | os.PathLike[str] | None = None,
              device: str | os.PathLike[str] | None = None, *,
              model: HumanProsthesisModel | None = None,
              progress: Callable[[str], None] | None = None,
              fmi_version: int = 2) -> BuildInfo:
    """Build ``out`` (.fmu) for the gait file and the subject/device configs (defaults: the
    shipped example files); ``model`` reuses an already built model of those configs.  A
    :class:`TrackedGait` (another graph's gait, e.g. the multi-contact one) comes with the
    ``model`` it was made for.
    ``fmi_version``: 2 (FMI 2.0) or 3 (FMI 3.0), the same generated C and core."""
    t0 = time.perf_counter()
    say = progress or (lambda _msg: None)
    out = Path(out)
    cc = _check_target(out, fmi_version)
    headers = fmi_header_dir()
    say("building the model")
    inp = _load_inputs(gait, subject, device, model)
    t_model = time.perf_counter()

    say("generating C")
    srcs = _generate_sources(inp, fmi_version)
    t_gen = time.perf_counter()

    say("compiling")
    with tempfile.TemporaryDirectory(prefix="hpfmu_") as tmp:
        root = Path(tmp) / "fmu"
        src, binp, res = _write_tree(root, srcs, fmi_version, headers)
        _compile(cc, src, binp / f"{MODEL_IDENTIFIER}.so", API[fmi_version][0])
        t_cc = time.perf_counter()
        seconds = {"model": t_model - t0, "codegen": t_gen - t_model, "compile": t_cc - t_gen}
        (res / "build_info.json").write_text(_build_info(inp, srcs, fmi_version, cc, seconds))
        say("packaging")
        _zip_atomically(root, out)
    seconds["total"] = time.perf_counter() - t0
    counts: dict[str, int] = {}
    for v in inp.table.vars:
        counts[v.causality] = counts.get(v.causality, 0) + 1
    return BuildInfo(path=out, guid=srcs.guid, model_hash=inp.model_hash,
                     gait_hash=inp.gait.hash, degree=inp.gait.degree, variables=counts,
                     size_bytes=out.stat().st_size, seconds=seconds)


__all__ = ["MODEL_IDENTIFIER", "BuildInfo", "FmuBuildError", "TrackedGait", "Variable",
           "build_fmu", "fmu_functions", "load_checked_gait", "paper_tracked_gait"]

"""The FMU's variables: one table from which both ``modelDescription.xml`` and the C header
``hpfmu_config.h`` are written, so the two cannot disagree.

Value references are counted per type (Real, Integer, Boolean, String) from 0, in table
order.  Every variable also has a C macro ``VR_<NAME>`` (arrays: ``VR_<NAME>`` is the first
element, the rest follow consecutively).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from xml.etree import ElementTree as ET

import numpy as np

from hp_model.domains import Domain, DomainGraph
from hp_model.falls import FallReason
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import SimOptions

#: unit name -> SI base-unit exponents (kg, m, s, rad)
UNITS: dict[str, dict[str, int]] = {
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "1/s2": {"s": -2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.s": {"kg": 1, "m": 1, "s": -1},
}


@dataclass(frozen=True)
class Variable:
    name: str
    type: str  # Real, Integer, Boolean, String
    causality: str  # input, output, parameter, local
    variability: str  # continuous, discrete, fixed, constant
    vr: int
    macro: str
    description: str
    start: float | int | bool | str | None = None
    unit: str | None = None
    initial: str | None = None
    #: outputs: whether the value depends directly on the inputs (feedthrough)
    feedthrough: bool = False


class _Table:
    def __init__(self) -> None:
        self.vars: list[Variable] = []
        self.count = {"Real": 0, "Integer": 0, "Boolean": 0, "String": 0}
        self.arrays: dict[str, tuple[str, int, int]] = {}  # macro -> (type, first vr, length)

    def add(self, name: str, type_: str, causality: str, description: str, *,
            start=None, unit: str | None = None, macro: str | None = None,
            feedthrough: bool = False) -> Variable:
        variability = {"input": "continuous" if type_ == "Real" else "discrete",
                       "output": "continuous" if type_ == "Real" else "discrete",
                       "parameter": "fixed", "local": "constant"}[causality]
        initial = {"input": None, "output": "calculated", "parameter": "exact",
                   "local": "exact"}[causality]
        v = Variable(name, type_, causality, variability, self.count[type_],
                     macro or name.upper(), description, start, unit, initial, feedthrough)
        self.count[type_] += 1
        self.vars.append(v)
        return v

    def array(self, base: str, type_: str, causality: str, descriptions: Sequence[str],
              units: Sequence[str | None], starts: Sequence | None = None,
              feedthrough: Sequence[bool] | None = None, tunable: bool = False) -> None:
        first = self.count[type_]
        for k, (desc, unit) in enumerate(zip(descriptions, units, strict=True)):
            self.add(f"{base}[{k + 1}]", type_, causality, desc,
                     start=None if starts is None else starts[k], unit=unit,
                     macro=f"{base.upper()}_{k + 1}",
                     feedthrough=bool(feedthrough[k]) if feedthrough is not None else False)
        if tunable:  # parameters settable in step mode
            n = len(descriptions)
            self.vars[-n:] = [replace(v, variability="tunable") for v in self.vars[-n:]]
        self.arrays[base.upper()] = (type_, first, len(descriptions))


def coord_unit(name: str, derivative: bool = False) -> str:
    linear = name.startswith(("x_", "z_"))
    if derivative:
        return "m/s" if linear else "rad/s"
    return "m" if linear else "rad"


def theta_rows(graph: DomainGraph, domain: str) -> list[tuple[str, str | None]]:
    """(what, unit) of each alpha row of ``domain``'s packed gait on ``graph``: its y2
    joints' angles; on the multi-contact graph then the hip progress rate where the domain
    has that output and the leading contact's friction ratio in a double support
    (:mod:`hp_model.contact_outputs`)."""
    d = Domain(domain)
    rows: list[tuple[str, str | None]] = [(coord, "rad") for coord in d.y2_coords]
    if graph == DomainGraph.MULTICONTACT:
        if d.velocity_output:
            rows.append(("the hip progress rate", "m/s"))
        if d.is_double_support:
            rows.append(("the leading contact's friction ratio F_x/F_z", None))
    return rows


def theta_descriptions(domain: str, degree: int,
                       graph: DomainGraph = DomainGraph.PAPER
                       ) -> tuple[list[str], list[str | None]]:
    desc: list[str] = []
    units: list[str | None] = []
    for row, (what, unit) in enumerate(theta_rows(graph, domain)):
        for j in range(degree + 1):
            desc.append(f"{domain} gait: Bezier coefficient alpha[{row},{j}] of {what}")
            units.append(unit)
    desc += [f"{domain} gait: hip velocity v_hip", f"{domain} gait: phase start p_min",
             f"{domain} gait: phase end p_max"]
    units += ["m/s", "m", "m"]
    return desc, units


def domain_codes(graph: DomainGraph) -> str:
    """The graph's domains by the code the ``domain`` output reports: "0 = ps, 1 = pns"."""
    return ", ".join(f"{d.code} = {d}" for d in sorted(graph.domains, key=lambda d: d.code))


def build_table(model: HumanProsthesisModel, thetas: Mapping[Domain, np.ndarray],
                gains: Sequence[float], q0: np.ndarray, qd0: np.ndarray, degree: int,
                options: SimOptions | None = None) -> _Table:
    """The variable table with start values from the gait (thetas, gains, initial state)."""
    opt = options or SimOptions()
    names, graph = model.coord_names, model.graph
    t = _Table()
    # inputs
    t.add("u_knee", "Real", "input", "prosthesis knee motor torque, held over the step",
          start=0.0, unit="N.m")
    t.add("u_ankle", "Real", "input", "prosthesis ankle motor torque, held over the step",
          start=0.0, unit="N.m")
    # outputs: what AMPRO3 senses
    t.add("knee_angle", "Real", "output", "prosthesis knee angle th_pk", unit="rad")
    t.add("ankle_angle", "Real", "output", "prosthesis ankle angle th_pa", unit="rad")
    t.add("knee_velocity", "Real", "output", "prosthesis knee velocity", unit="rad/s")
    t.add("ankle_velocity", "Real", "output", "prosthesis ankle velocity", unit="rad/s")
    t.add("foot_load", "Real", "output",
          "prosthesis foot normal force (N) while it is on the ground (flat, heel or toe), "
          "else 0", unit="N", feedthrough=True)
    t.add("foot_contact", "Boolean", "output",
          "prosthesis foot on the ground (a domain with a prosthesis contact)")
    t.add("socket_pitch", "Real", "output",
          "world pitch of the prosthesis top link (AMPRO3's IMU), about +y", unit="rad")
    # outputs: ground truth
    t.add("socket_Fx", "Real", "output", "socket force F_x (human on prosthesis, top-link frame)",
          unit="N", feedthrough=True)
    t.add("socket_Fz", "Real", "output", "socket force F_z", unit="N", feedthrough=True)
    t.add("socket_My", "Real", "output", "socket moment M_y", unit="N.m", feedthrough=True)
    t.add("stance_Fx", "Real", "output",
          "stance-foot ground force F_x (world; a double support's leading foot)", unit="N",
          feedthrough=True)
    t.add("stance_Fz", "Real", "output", "stance-foot ground force F_z (world)", unit="N",
          feedthrough=True)
    t.add("stance_My", "Real", "output",
          "stance-foot ground moment M_y (world; 0 on a heel or a toe)", unit="N.m",
          feedthrough=True)
    t.array("q", "Real", "output", [f"coordinate {n}" for n in names],
            [coord_unit(n) for n in names])
    t.array("qd", "Real", "output", [f"velocity of {n}" for n in names],
            [coord_unit(n, True) for n in names])
    t.array("u", "Real", "output",
            [f"torque of {a} ({'motor, N m' if a.startswith('th_p') else 'joint, N m'})"
             for a in model.actuated], ["N.m"] * model.nu, feedthrough=[True] * model.nu)
    t.add("tau", "Real", "output", "phase variable tau of the current domain")
    t.add("t_impact", "Real", "output", "time of the last impact (located), -1 before any",
          unit="s")
    t.add("domain", "Integer", "output", f"current domain: {domain_codes(graph)}")
    t.add("steps", "Integer", "output",
          "steps so far: the impacts that start one (the paper's graph: every impact; the "
          "multi-contact graph: the heel strikes)")
    t.add("fall", "Boolean", "output", "the walker fell (integration stopped)")
    t.add("fall_code", "Integer", "output",
          "why: " + "; ".join(f"{int(r)} {r.description}" for r in FallReason))
    t.add("torque_clamped", "Integer", "output",
          "torque inputs set outside the device's motor limits so far (applied at the limit)")
    # parameters: the gait the human tracks and its feedback gains; a domain's gait is tunable
    # in step mode, taken up the next time the walker enters the domain (a person changing
    # speed: the master sets the curves of the speed commanded, README)
    for d in graph.domains:
        desc, units = theta_descriptions(d, degree, graph)
        t.array(f"theta_{d}", "Real", "parameter", desc, units,
                [float(v) for v in thetas[d]], tunable=True)
    t.add("fl_eps", "Real", "parameter", "human feedback linearization gain on y1",
          start=float(gains[0]), unit="1/s")
    t.add("fl_kp", "Real", "parameter", "human feedback linearization gain kp on y2",
          start=float(gains[1]), unit="1/s2")
    t.add("fl_kd", "Real", "parameter", "human feedback linearization gain kd on y2",
          start=float(gains[2]), unit="1/s")
    t.add("human_perturbation", "Real", "parameter",
          "amplitude of the deterministic perturbation of every Bezier coefficient "
          "(uniform in [-a, a), SplitMix64; see README)", start=0.0, unit="rad")
    t.add("human_seed", "Integer", "parameter", "seed of the human perturbation", start=0)
    # parameters: initial state
    t.array("q0", "Real", "parameter", [f"initial {n}" for n in names],
            [coord_unit(n) for n in names], [float(v) for v in q0])
    t.array("qd0", "Real", "parameter", [f"initial velocity of {n}" for n in names],
            [coord_unit(n, True) for n in names], [float(v) for v in qd0])
    t.add("initial_domain", "Integer", "parameter",
          f"initial domain: {domain_codes(graph)}", start=graph.domains[0].code)
    t.add("offset_knee", "Real", "parameter",
          "initial offset added to th_pk (see README: the human put on its outputs, the "
          "walker re-placed on its stance foot; the paper's graph only)", start=0.0,
          unit="rad")
    t.add("offset_ankle", "Real", "parameter", "initial offset added to th_pa", start=0.0,
          unit="rad")
    # parameters: integration and events (SimOptions)
    t.add("substeps", "Integer", "parameter", "RK4 steps per communication step",
          start=opt.substeps)
    t.add("guard_tau_min", "Real", "parameter", "the touchdown guard is armed past this phase",
          start=opt.guard_tau_min)
    t.add("event_tol", "Real", "parameter", "swing-sole height tolerance of the located impact",
          start=opt.event_tol, unit="m")
    t.add("event_iters", "Integer", "parameter", "maximum Illinois iterations per event",
          start=opt.event_iters)
    t.add("min_hip_height", "Real", "parameter", "fall: hip height below this",
          start=opt.min_hip_height, unit="m")
    t.add("tau_backward", "Real", "parameter", "fall: tau drops this far below its peak",
          start=opt.tau_backward)
    t.add("tau_max", "Real", "parameter",
          "fall: no touchdown by this phase (or late_touchdown, if later)", start=opt.tau_max)
    t.add("late_touchdown", "Real", "parameter",
          "fall: nor a touchdown this long past the domain's designed one, at its gait's hip "
          "speed", start=opt.late_touchdown, unit="s")
    t.add("max_step_time", "Real", "parameter",
          "fall: no touchdown this long after the start or the last impact",
          start=opt.max_step_time, unit="s")
    t.add("max_speed", "Real", "parameter",
          "fall: a generalized speed above this (m/s or rad/s: the state diverging)",
          start=opt.max_speed)
    t.add("min_normal_force", "Real", "parameter",
          "fall: stance normal force below this (a double support's trailing foot leaves "
          "below it)", start=opt.min_normal_force, unit="N")
    t.add("mu", "Real", "parameter", "friction coefficient of the slip check", start=opt.mu)
    t.add("cone_periods", "Integer", "parameter",
          "fall: friction cone violated this many consecutive communication steps",
          start=opt.cone_periods)
    t.add("trailing_slip_load", "Real", "parameter",
          "a double support's trailing contact counts as slipping above this normal force "
          "(negative: its slip is not watched)",
          start=-1.0 if opt.trailing_slip_load is None else
          opt.trailing_slip_load * model.tree.total_mass * model.tree.gravity, unit="N")
    t.add("max_touchdown_pitch", "Real", "parameter",
          "fall: landing-foot pitch removed at touchdown above this",
          start=opt.max_touchdown_pitch, unit="rad")
    return t


def add_constants(t: _Table, model_hash: str, gait_hash: str) -> None:
    t.add("model_hash", "String", "local", "hash of the subject/device parameters",
          start=model_hash)
    t.add("gait_hash", "String", "local", "hash of the gait the FMU was built from",
          start=gait_hash)


def fmt_value(v: float | int | bool | str) -> str:
    """A start value as modelDescription.xml writes it (both FMI versions)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(float(v))
    return str(v)


def add_common_elements(root: ET.Element, table: _Table) -> None:
    """The modelDescription elements both FMI versions share, in the schemas' order after
    the interface element: UnitDefinitions (the table's units), LogCategories,
    DefaultExperiment."""
    ud = ET.SubElement(root, "UnitDefinitions")
    for u in sorted({v.unit for v in table.vars if v.unit}):
        ET.SubElement(ET.SubElement(ud, "Unit", {"name": u}), "BaseUnit",
                      {k: str(e) for k, e in UNITS[u].items()})
    lc = ET.SubElement(root, "LogCategories")
    for name, desc in (("logEvents", "impacts and falls"),
                       ("logStatusError", "errors: bad parameters, calls in the wrong state")):
        ET.SubElement(lc, "Category", {"name": name, "description": desc})
    ET.SubElement(root, "DefaultExperiment",
                  {"startTime": "0.0", "stopTime": "10.0", "stepSize": "0.001"})

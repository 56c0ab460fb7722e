"""FMI 3.0 variant of the human FMU: its value references and ``modelDescription.xml``.

The same variable table as FMI 2.0 (:mod:`human_fmu.variables`), mapped to FMI 3.0 types
(Real -> Float64, Integer -> Int32, Boolean, String) with value references unique over all
variables, as FMI 3.0 requires: each type's FMI 2.0 reference plus its base
(:data:`VR_BASE`), and the independent variable ``time`` at :data:`VR_TIME`.  The C side
reads the same numbers from ``hpfmu_config.h`` (``HPFMU3_VR_BASE_*``, ``HPFMU3_VR_TIME``),
written by the same build from the same table.
"""

from __future__ import annotations

import itertools
from xml.etree import ElementTree as ET

import casadi as ca

import hp_model
from human_fmu.variables import Variable, _Table, add_common_elements, fmt_value

#: FMI 3.0 value reference = FMI 2.0 reference (per type, from 0) + the type's base
VR_BASE = {"Real": 0, "Integer": 10_000, "Boolean": 20_000, "String": 30_000}
#: the independent variable ``time`` (s)
VR_TIME = 40_000
#: FMI 3.0 element name of each table type
TYPE3 = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
#: where FMI 3.0 puts the binary (fmpy, the standard's platform tuple)
PLATFORM_TUPLE = "x86_64-linux"


def vr3(v: Variable) -> int:
    """The FMI 3.0 value reference of a table variable."""
    return VR_BASE[v.type] + v.vr


def check_capacity(table: _Table) -> None:
    """Every type's references fit below the next base (ValueError otherwise)."""
    bases = [*sorted(VR_BASE.items(), key=lambda kv: kv[1]), ("time", VR_TIME)]
    for (typ, base), (_, nxt) in itertools.pairwise(bases):
        if base + table.count[typ] > nxt:
            raise ValueError(f"{table.count[typ]} {typ} variables do not fit the FMI 3.0 "
                             f"value references {base}..{nxt - 1}")


def config_macros() -> list[str]:
    """The C macros of :data:`VR_BASE` and :data:`VR_TIME` for ``hpfmu_config.h``."""
    lines = ["/* FMI 3.0 value references: the type's base + its FMI 2.0 reference */"]
    lines += [f"#define HPFMU3_VR_BASE_{t.upper()} {b}u" for t, b in VR_BASE.items()]
    lines.append(f"#define HPFMU3_VR_TIME {VR_TIME}u")
    return lines


def model_description_3(table: _Table, token: str, *, model_identifier: str,
                        description: str, generated: str,
                        annotations: dict[str, str]) -> str:
    """``modelDescription.xml`` of the FMI 3.0 co-simulation FMU."""
    check_capacity(table)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": model_identifier, "instantiationToken": token,
        "description": description, "author": "hpcosim", "version": hp_model.__version__,
        "generationTool":
            f"hpcosim human_fmu {hp_model.__version__} (CasADi {ca.CasadiMeta.version()})",
        "generationDateAndTime": generated, "variableNamingConvention": "flat"})
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": model_identifier, "needsExecutionTool": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
        "canSerializeFMUState": "false", "providesDirectionalDerivatives": "false",
        "providesAdjointDerivatives": "false", "providesPerElementDependencies": "false",
        "canHandleVariableCommunicationStepSize": "true", "maxOutputDerivativeOrder": "0",
        "providesIntermediateUpdate": "false", "mightReturnEarlyFromDoStep": "false",
        "canReturnEarlyAfterIntermediateUpdate": "false", "hasEventMode": "false",
        "providesEvaluateDiscreteStates": "false"})
    add_common_elements(root, table)
    mv = ET.SubElement(root, "ModelVariables")
    ET.SubElement(mv, "Float64", {"name": "time", "valueReference": str(VR_TIME),
                                  "causality": "independent", "variability": "continuous",
                                  "description": "simulation time", "unit": "s"})
    for v in table.vars:
        attrs = {"name": v.name, "valueReference": str(vr3(v)), "description": v.description,
                 "causality": v.causality, "variability": v.variability}
        if v.initial is not None and v.causality != "local":
            attrs["initial"] = v.initial
        if v.unit and v.type == "Real":
            attrs["unit"] = v.unit
        if v.start is not None and v.type != "String":
            attrs["start"] = fmt_value(v.start)
        el = ET.SubElement(mv, TYPE3[v.type], attrs)
        if v.start is not None and v.type == "String":
            ET.SubElement(el, "Start", {"value": str(v.start)})
    ms = ET.SubElement(root, "ModelStructure")
    inputs = " ".join(str(vr3(v)) for v in table.vars if v.causality == "input")
    outs = [v for v in table.vars if v.causality == "output"]
    for v in outs:
        ET.SubElement(ms, "Output", {"valueReference": str(vr3(v)),
                                     "dependencies": inputs if v.feedthrough else ""})
    for v in outs:
        ET.SubElement(ms, "InitialUnknown", {"valueReference": str(vr3(v))})
    an = ET.SubElement(ET.SubElement(root, "Annotations"), "Annotation", {"type": "hpcosim"})
    ET.SubElement(an, "Build", annotations)  # the schema's order: Annotations come last
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") \
        + "\n"

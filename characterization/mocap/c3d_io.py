"""C3D files through ezc3d: markers, and the lab's model outputs kept apart from them.

``c3d(path)['data']['points']`` is (4, points, frames) in POINT:UNITS (usually mm); a
missing sample is NaN or has a negative residual.

Not every point is a marker.  A processed file (Vicon Nexus's Plug-in Gait, the Oxford Foot
Model, ...) stores what the lab's model computed as points too, and names them in POINT
parameters: POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS, REACTIONS, MODELED_MARKERS
(POINT:TYPE_GROUPS lists the ones a file uses; their units are POINT:ANGLE_UNITS,
FORCE_UNITS, ...).  Those points become the take's ``model_outputs`` (in the file's units),
never markers: they are not positions on the body (a knee angle in deg, a hip moment in
N mm) and would mislead the axes guess and the mapping.  Nexus also writes each model
segment as four points no parameter names (Plug-in Gait's "bones": XXXO origin, XXXA
anterior, XXXL lateral, XXXP proximal, e.g. PELO/PELA/PELL/PELP); in a file with model
outputs those are model outputs of kind ``"BONES"``.

The up axis: POINT:Y_SCREEN, the lab axis the file is displayed bottom-to-top (c3d.org),
when the file has it (Vicon writes "+Z"); else C3D's convention ``"+z"``.  The mapping's
``up`` overrides either.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from characterization.mocap.subject_from_take import c3d_subject_metadata
from characterization.mocap.take import LabEvent, MocapError, ModelOutput, Take
from hp_model.atomic_io import atomic_write_with

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: POINT parameters whose labels are model outputs, whether or not TYPE_GROUPS lists them
MODEL_OUTPUT_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS",
                       "MODELED_MARKERS")
#: the kind of Vicon's segment points (origin, anterior, lateral, proximal; no parameter)
BONES = "BONES"
_BONE_SUFFIXES = "OALP"
_SCREEN_AXIS = re.compile(r"^[+-][XYZ]$")
#: POINT parameters that are never a group of point names
_NOT_GROUPS = re.compile(r"^((LABELS|DESCRIPTIONS)\d*|UNITS|X_SCREEN|Y_SCREEN|TYPE_GROUPS)$")


def read_c3d(path: str | os.PathLike[str]) -> Take:
    """Read the POINT data of a C3D file into a :class:`Take` (metres, lab axes)."""
    import ezc3d

    src = str(path)
    if not Path(path).is_file():
        raise FileNotFoundError(f"{src}: no such file")
    try:
        c = ezc3d.c3d(src)
    except Exception as e:  # ezc3d raises plain RuntimeError/IndexError on bad files
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise MocapError(f"{src}: not a readable C3D file ({first})") from None
    return take_from_c3d(c, src)


def point_labels(par: Mapping[str, Any], n_points: int) -> list[str]:
    """The labels of the ``n_points`` stored markers: POINT:LABELS continued by LABELS2,
    LABELS3, ... (files with more than 255 markers), cut to POINT:USED when the file names
    spare labels beyond the markers it stores (e.g. the c3d.org gait samples)."""
    labels = [str(s).strip() for s in par["LABELS"]["value"]]
    k = 2
    while f"LABELS{k}" in par:
        labels += [str(s).strip() for s in par[f"LABELS{k}"]["value"]]
        k += 1
    used = int(np.ravel(par["USED"]["value"])[0]) if "USED" in par else len(labels)
    if len(labels) > n_points and used == n_points:
        labels = labels[:n_points]
    return labels


def _strings(par: Mapping[str, Any], name: str) -> list[str]:
    """A POINT parameter's strings, stripped; [] if absent or not text."""
    if name not in par:
        return []
    v = par[name].get("value") if hasattr(par[name], "get") else None
    if isinstance(v, str):
        return [v.strip()]
    if v is None or not all(isinstance(x, str) for x in v):
        return []
    return [x.strip() for x in v]


def model_output_kinds(par: Mapping[str, Any], labels: Sequence[str]) -> dict[str, str]:
    """Label -> kind (the POINT parameter naming it) of the points that are not markers:
    those named by the groups POINT:TYPE_GROUPS lists or :data:`MODEL_OUTPUT_GROUPS`, and,
    in a file with any, Vicon's bones (module docstring)."""
    present = set(labels)
    kinds: dict[str, str] = {}
    for g in dict.fromkeys([*_strings(par, "TYPE_GROUPS"), *MODEL_OUTPUT_GROUPS]):
        if not _NOT_GROUPS.match(g):
            for name in _strings(par, g):
                if name in present:
                    kinds.setdefault(name, g)
    if kinds:
        for lab in labels:
            four = [lab[:3] + c for c in _BONE_SUFFIXES]
            if (len(lab) == 4 and lab == four[0]
                    and all(b in present and b not in kinds for b in four)):
                kinds.update(dict.fromkeys(four, BONES))
    return kinds


def output_unit(par: Mapping[str, Any], kind: str) -> str:
    """The file's unit of a kind of model output: POINT:ANGLE_UNITS for ANGLES, ...,
    POINT:UNITS for the bones; "" if the file does not say."""
    name = "UNITS" if kind == BONES else f"{kind.removesuffix('S')}_UNITS"
    got = _strings(par, name)
    return got[0] if got else ""


def file_up_axis(par: Mapping[str, Any]) -> str | None:
    """The up axis the file gives (``"+z"``, ...): POINT:Y_SCREEN, the axis displayed
    bottom-to-top; None if absent, malformed or along POINT:X_SCREEN's axis."""
    y, x = _strings(par, "Y_SCREEN"), _strings(par, "X_SCREEN")
    if not y or not _SCREEN_AXIS.match(y[0].upper()):
        return None
    if x and x[0].upper()[1:] == y[0].upper()[1:]:
        return None
    return y[0].lower()


def _lost(c: Any, pts: np.ndarray) -> np.ndarray:
    """(points, frames) bool: a sample missing (not finite, or a negative residual)."""
    lost = ~np.all(np.isfinite(pts[:3]), axis=0)
    if "meta_points" in c["data"]:
        lost |= np.asarray(c["data"]["meta_points"]["residuals"])[0] < 0
    return lost


def take_from_c3d(c: Any, src: str) -> Take:
    """A :class:`Take` from an ezc3d ``c3d`` object (its parameters and data)."""
    par = c["parameters"]["POINT"]
    pts = np.asarray(c["data"]["points"], dtype=float)
    labels = point_labels(par, pts.shape[1] if pts.ndim == 3 else -1)
    unit = str(par["UNITS"]["value"][0]).strip().lower() if "UNITS" in par else "mm"
    if unit not in UNITS:
        raise MocapError(f"{src}: parameter POINT:UNITS: unknown units '{unit}' "
                         f"(expected one of {', '.join(UNITS)})")
    rate = float(np.ravel(par["RATE"]["value"])[0])
    if pts.ndim != 3 or pts.shape[1] != len(labels):
        raise MocapError(f"{src}: POINT data has {pts.shape[1] if pts.ndim == 3 else '?'} "
                         f"markers but POINT:LABELS names {len(labels)}")
    n = pts.shape[2]
    if n == 0:
        raise MocapError(f"{src}: no frames")
    lost = _lost(c, pts)
    kinds = model_output_kinds(par, labels)
    markers: dict[str, np.ndarray] = {}
    outputs: dict[str, ModelOutput] = {}
    for i, lab in enumerate(labels):
        if lab in markers or lab in outputs:
            what = "model output" if lab in kinds else "marker"
            raise MocapError(f"{src}: POINT:LABELS: duplicate {what} label '{lab}'")
        xyz = pts[:3, i, :].T * (1.0 if lab in kinds else UNITS[unit])
        xyz[lost[i]] = np.nan
        if lab in kinds:
            outputs[lab] = ModelOutput(kinds[lab], output_unit(par, kinds[lab]), xyz)
        else:
            markers[lab] = xyz
    first = int(c["header"]["points"]["first_frame"])
    time = (first + np.arange(n)) / rate
    up = file_up_axis(par)
    return Take(source=src, frame_rate=rate, time=time, markers=markers,
                up_axis=up or "+z", up_axis_source="POINT:Y_SCREEN" if up else "",
                metadata={"format": "c3d", **c3d_subject_metadata(c["parameters"])},
                events=lab_events(c["parameters"], src),
                model_outputs=outputs)


def lab_events(params: Mapping[str, Any], src: str) -> tuple[LabEvent, ...]:
    """The EVENT group's events (LABELS, CONTEXTS, TIMES = [minutes; seconds]), the first
    USED of them; none without the group."""
    ev = params.get("EVENT") if hasattr(params, "get") else None
    if not ev or "TIMES" not in ev or "LABELS" not in ev:
        return ()
    times = np.asarray(ev["TIMES"]["value"], dtype=float)
    if times.ndim == 1:
        times = times.reshape(2, -1) if times.size % 2 == 0 else np.zeros((2, 0))
    labels = [str(x).strip() for x in ev["LABELS"]["value"]]
    contexts = ([str(x).strip() for x in ev["CONTEXTS"]["value"]] if "CONTEXTS" in ev
                else [""] * len(labels))
    n = min(len(labels), times.shape[1] if times.ndim == 2 else 0, len(contexts))
    if "USED" in ev:
        n = min(n, int(np.ravel(ev["USED"]["value"])[0]))
    out = []
    for k in range(n):
        t = 60.0 * times[0, k] + times[1, k]
        if not np.isfinite(t):
            raise MocapError(f"{src}: parameter EVENT:TIMES: event {k + 1} has no time")
        out.append(LabEvent(labels[k], contexts[k], float(t)))
    return tuple(sorted(out, key=lambda e: e.time))


def write_c3d(path: str | os.PathLike[str], take: Take, *, units: str = "mm") -> None:
    """Write the take's reconstructed markers (in ``units``), its model outputs (as they
    are, named in their POINT groups), its up axis (POINT:Y_SCREEN) and its events to a
    C3D file (atomically)."""
    import ezc3d

    names = [*take.markers, *take.model_outputs]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(take.frame_rate)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c.add_parameter("POINT", "UNITS", [units])
    up = take.up_axis.upper()
    c.add_parameter("POINT", "X_SCREEN", ["+Y" if up[1] == "X" else "+X"])
    c.add_parameter("POINT", "Y_SCREEN", [up])
    pts = np.ones((4, len(names), take.n_frames))
    values = [take.markers[k] / UNITS[units] for k in take.markers]
    values += [o.values * (UNITS[o.unit] / UNITS[units]  # the bones: in POINT:UNITS
                           if o.kind == BONES and o.unit in UNITS else 1.0)
               for o in take.model_outputs.values()]
    for i, xyz in enumerate(values):
        pts[:3, i, :] = xyz.T
        pts[:, i, ~np.all(np.isfinite(xyz), axis=1)] = np.nan
    c["data"]["points"] = pts
    _add_output_groups(c, take)
    if take.events:
        c.add_parameter("EVENT", "USED", [len(take.events)])
        c.add_parameter("EVENT", "LABELS", [e.label for e in take.events])
        c.add_parameter("EVENT", "CONTEXTS", [e.context for e in take.events])
        c.add_parameter("EVENT", "TIMES", np.array([[0.0] * len(take.events),
                                                    [e.time for e in take.events]]))
    atomic_write_with(path, lambda tmp: c.write(tmp), suffix=".c3d")


def _add_output_groups(c: Any, take: Take) -> None:
    """POINT:<kind> (the names), POINT:<kind>_UNITS and POINT:TYPE_GROUPS of the take's
    model outputs, as Vicon writes them (the bones in no group)."""
    groups: dict[str, list[str]] = {}
    for name, o in take.model_outputs.items():
        groups.setdefault(o.kind, []).append(name)
    groups.pop(BONES, None)
    for kind, labels in groups.items():
        c.add_parameter("POINT", kind, labels)
        unit = next(o.unit for o in take.model_outputs.values() if o.kind == kind)
        if unit:
            c.add_parameter("POINT", f"{kind.removesuffix('S')}_UNITS", [unit])
    if groups:
        c.add_parameter("POINT", "TYPE_GROUPS", list(groups))

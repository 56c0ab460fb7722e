"""C3D files through ezc3d: markers only (C3D has no standard rigid-body orientations).

``c3d(path)['data']['points']`` is (4, markers, frames) in POINT:UNITS (usually mm); a
missing sample is NaN or has a negative residual.  C3D files are Z-up by convention, so the
:class:`Take` gets ``up_axis = "+z"`` (override it in the mapping config if a lab differs).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from characterization.mocap.take import LabEvent, MocapError, Take
from hp_model.atomic_io import atomic_write_with

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


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
    res = c["data"]["meta_points"]["residuals"] if "meta_points" in c["data"] else None
    markers: dict[str, np.ndarray] = {}
    for i, lab in enumerate(labels):
        if lab in markers:
            raise MocapError(f"{src}: POINT:LABELS: duplicate marker label '{lab}'")
        xyz = pts[:3, i, :].T * UNITS[unit]
        lost = ~np.all(np.isfinite(xyz), axis=1)
        if res is not None:
            lost |= np.asarray(res)[0, i, :] < 0
        xyz[lost] = np.nan
        markers[lab] = xyz
    first = int(c["header"]["points"]["first_frame"])
    time = (first + np.arange(n)) / rate
    return Take(source=src, frame_rate=rate, time=time, markers=markers, up_axis="+z",
                metadata={"format": "c3d"}, events=lab_events(c["parameters"], src))


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
    """Write the take's reconstructed markers to a C3D file (atomically)."""
    import ezc3d

    names = list(take.markers)
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(take.frame_rate)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c.add_parameter("POINT", "UNITS", [units])
    pts = np.ones((4, len(names), take.n_frames))
    for i, k in enumerate(names):
        xyz = take.markers[k] / UNITS[units]
        pts[:3, i, :] = xyz.T
        pts[:, i, ~np.all(np.isfinite(xyz), axis=1)] = np.nan
    c["data"]["points"] = pts
    if take.events:
        c.add_parameter("EVENT", "USED", [len(take.events)])
        c.add_parameter("EVENT", "LABELS", [e.label for e in take.events])
        c.add_parameter("EVENT", "CONTEXTS", [e.context for e in take.events])
        c.add_parameter("EVENT", "TIMES", np.array([[0.0] * len(take.events),
                                                    [e.time for e in take.events]]))
    atomic_write_with(path, lambda tmp: c.write(tmp), suffix=".c3d")

"""A run's main channels as the tools labs use read them (``hpcosim recording export``):
the recording's ``/ground_truth`` and ``/controller/clf``, one row per control period, as a
CSV with units in its header (:mod:`hp_model.tables`), and optionally its coordinates as an
OpenSim ``.mot``.

CSV columns:

    time [s]                  simulation time of the period
    domain, step              the domain's word, steps completed
    tau [1]                   phase of the domain
    <coord> [m | rad]         the 12 coordinates (``COORDS``), ground truth
    socket_Fx, _Fz [N], socket_My [N m]   the socket force (human on prosthesis, top link's
                              frame), ground truth under the applied torques
    knee_motor, ankle_motor [N m motor]   the motor torques applied
    knee_torque, ankle_torque [N m]       at the joint (gear ratio x motor), when the
                              recording states its gear ratios (metadata ``device``, which
                              ``hpcosim run`` writes); absent otherwise
    V [1], rho [1]            the controller's CLF value and relaxation, empty where it
                              reported none (e.g. a PD controller)
    speed_command, speed_estimate, speed_controller [m/s], controller_phase [1]
                              a person walking a gait library (``hpcosim run --library``):
                              the speed commanded, the controller's estimate, the speed of
                              the controller it ran and its phase, its measurements replayed
                              through its file (:mod:`orchestrator.cosim.speed_trace`);
                              absent for other runs

The ``.mot`` (``--mot``) holds time and the 12 coordinates, angles in degrees
(``inDegrees=yes``), as :mod:`characterization.gait.export`'s ``kinematics.mot``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hp_model.human_prosthesis import COORDS
from hp_model.tables import Column, MotTable, write_csv, write_mot
from orchestrator.cosim.recording import RecordingError, read_recording
from orchestrator.cosim.speed_trace import SpeedTrace, speed_trace

GROUND_TRUTH, CLF = "/ground_truth", "/controller/clf"
#: which coordinates are angles (the others are lengths, m): the pitches
ANGLES = tuple(c.startswith("th_") for c in COORDS)


@dataclass(frozen=True)
class RunTable:
    """A run's rows: ``t`` (n,) s; ``domain`` (n,) words; ``step`` (n,); ``tau`` (n,);
    ``q`` (n, 12); ``socket`` (n, 3); ``motor`` (n, 2) N m; ``ratio`` (knee, ankle) or None;
    ``V``, ``rho`` (n,) with NaN where not reported."""

    t: np.ndarray
    domain: list[str]
    step: np.ndarray
    tau: np.ndarray
    q: np.ndarray
    socket: np.ndarray
    motor: np.ndarray
    ratio: tuple[float, float] | None
    V: np.ndarray
    rho: np.ndarray
    speed: SpeedTrace | None = None  # a gait library's run, at ``t``


def _messages(path: Path, topic: str) -> list[dict[str, Any]]:
    from bus_schemas.recording.reader import read_messages

    try:
        return [o for _, _, o in read_messages(path, [topic])]
    except Exception as e:  # the mcap reader's errors for a damaged file
        raise RecordingError(f"{path}: {topic} unreadable ({e})") from None


def _ratio(meta: dict[str, dict[str, str]]) -> tuple[float, float] | None:
    dev = meta.get("device", {})
    try:
        return (float(json.loads(dev["gear_ratio_knee"])),
                float(json.loads(dev["gear_ratio_ankle"])))
    except (KeyError, TypeError, ValueError):
        return None


def _number(v: Any) -> float:
    return float("nan") if v is None else float(v)


def run_table(path: str | os.PathLike[str]) -> RunTable:
    """The main channels of the recording ``path`` (module docstring); a file that is not
    a recording, or one without ground truth, is a :class:`RecordingError` naming it."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    rec = read_recording(p, messages=False)
    rows = _messages(p, GROUND_TRUTH)
    if not rows:
        raise RecordingError(f"{p}: 0 {GROUND_TRUTH} messages: nothing to export (a recording "
                             "of `hpcosim run --record`?)")
    clf = {o["t"]: o for o in _messages(p, CLF)}
    try:
        q = np.array([o["q"] for o in rows], dtype=float)
        t = np.array([o["t"] for o in rows], dtype=float)
        table = RunTable(
            t=t, domain=[str(o["domain"]) for o in rows],
            step=np.array([int(o["step"]) for o in rows]),
            tau=np.array([o["tau"] for o in rows], dtype=float), q=q,
            socket=np.array([[o["socket_force"][k] for k in ("Fx", "Fz", "My")]
                             for o in rows], dtype=float),
            motor=np.array([o.get("u_applied", [None, None]) for o in rows], dtype=float),
            ratio=_ratio(rec.metadata),
            V=np.array([_number(clf.get(o["t"], {}).get("V")) for o in rows]),
            rho=np.array([_number(clf.get(o["t"], {}).get("rho")) for o in rows]))
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise RecordingError(f"{p}: {GROUND_TRUTH} message without a valid field "
                             f"({type(e).__name__}: {e})") from None
    if q.ndim != 2 or q.shape[1] != len(COORDS):
        raise RecordingError(f"{p}: {GROUND_TRUTH} q has {q.shape[-1]} coordinates, the "
                             f"model {len(COORDS)}")
    trace = speed_trace(p)
    return table if trace is None else replace(table, speed=trace.at(t))


def run_columns(r: RunTable) -> list[Column]:
    """The CSV columns of a run (module docstring)."""
    cols = [Column("time", "s", r.t), Column("domain", None, r.domain),
            Column("step", None, r.step), Column("tau", "1", r.tau)]
    cols += [Column(c, "rad" if a else "m", r.q[:, i])
             for i, (c, a) in enumerate(zip(COORDS, ANGLES, strict=True))]
    cols += [Column("socket_Fx", "N", r.socket[:, 0]), Column("socket_Fz", "N", r.socket[:, 1]),
             Column("socket_My", "N m", r.socket[:, 2]),
             Column("knee_motor", "N m motor", r.motor[:, 0]),
             Column("ankle_motor", "N m motor", r.motor[:, 1])]
    if r.ratio is not None:
        cols += [Column("knee_torque", "N m", r.ratio[0] * r.motor[:, 0]),
                 Column("ankle_torque", "N m", r.ratio[1] * r.motor[:, 1])]
    cols += [Column("V", "1", r.V), Column("rho", "1", r.rho)]
    if r.speed is not None:
        cols += [Column("speed_command", "m/s", r.speed.command),
                 Column("speed_estimate", "m/s", r.speed.estimate),
                 Column("speed_controller", "m/s", r.speed.running),
                 Column("controller_phase", "1", r.speed.phase)]
    return cols


def export_recording(path: str | os.PathLike[str], out: str | os.PathLike[str],
                     mot: str | os.PathLike[str] | None = None) -> RunTable:
    """Write the recording ``path``'s main channels to the CSV ``out`` and, given ``mot``,
    its coordinates to an OpenSim motion file (both atomic); returns what was read."""
    r = run_table(path)
    write_csv(out, run_columns(r))
    if mot is not None:
        if not np.all(np.diff(r.t) > 0):
            raise RecordingError(f"{path}: {GROUND_TRUTH} times do not increase strictly; "
                                 "OpenSim refuses such a motion")
        angles = np.array(ANGLES)
        write_mot(mot, MotTable("Coordinates", r.t, COORDS, np.where(angles, np.degrees(r.q),
                                                                     r.q), in_degrees=True,
                                comments=("Units are S.I. units (second, meters, Newtons, ...)",
                                          "Angles are in degrees.")))
    return r

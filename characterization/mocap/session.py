"""A session: several takes of one subject (walkway trials of 1-2 strides each, or one
treadmill take) processed one by one and their steps pooled into one steps file.

Each take is processed as a single take is (:func:`pipeline.process_take`: its own axes,
contact detection and steps); a take that gives no step is reported with the reason and
left out, and the session fails only when no take gives a step.  The pooled steps file
(:mod:`steps_artifact`, unchanged schema) holds the takes one after the other: take k's
frames follow take k-1's after a pause of ``step_segmentation.TAKE_GAP`` in ``time``
(:func:`step_segmentation.take_spans` finds the takes again), its frame indices shifted, so
no step and no touchdown segment (:func:`domain_segmentation.domain_segments`) spans two
takes; ``source`` lists the takes joined by " + ".  The joint-centre fit fields
(``joint_lambda``, ``joint_residual``, ``joint_well_posed``) are per take: the pooled file
keeps the take with the most kept steps for ``joint_lambda``, the worst residual and
well-posed only where every take is.  Other per-take fields must agree; where they do not
(e.g. the subject's provenance names its take) the first take's is kept and a warning says
so.

What each stage needs of a session (docs/recording.md): ``mocap process`` a complete step
(a touchdown of each foot, the limbs seen between) in at least one take; ``gait fit`` a
touchdown-to-touchdown portion of each domain; ``tube fit`` ``TUBE_MIN_STEPS`` prosthesis
stance steps with single support (a degree-3 tube).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from characterization.mocap.foot_contact import Stride, strides
from characterization.mocap.pipeline import ProcessedTake, process_take, static_offsets, to_artifact
from characterization.mocap.step_segmentation import TAKE_GAP
from characterization.mocap.steps_artifact import StepsArtifact, steps_bytes, steps_output
from characterization.mocap.take import MocapError
from hp_model import COORDS
from hp_model.atomic_io import atomic_write_bytes
from hp_model.config import SubjectConfig
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.json_io import dumps

#: ps steps with single support a degree-3 force tube needs (``tube fit``'s default)
TUBE_MIN_STEPS = 4
#: how to get more steps, the end of every refusal that counts them
MORE = ("record more walkway trials (or a longer take) and pool them with "
        "`hpcosim mocap process A B C --out steps.npz`")

_FRAMES = {"time", "q", "limb_pitch", "pitch_source", "joint_position", "delta_ps",
           "foot_contact"}
_STEP_FRAMES = {"step_start", "step_end", "dropped_start", "dropped_end"}
_SS_FRAMES = {"step_ss_start", "step_ss_end"}  # -1: none
_STEPS = {"step_domain", "step_delta_lower", "step_delta_upper", "dropped_domain",
          "dropped_reason"}
_JOINT_FIT = {"joint_lambda", "joint_residual", "joint_well_posed"}


@dataclass(frozen=True)
class TakeOutcome:
    """One take of a session: its processing, or the one-line reason it gave no step."""

    path: Path
    processed: ProcessedTake | None = None
    error: str | None = None

    @property
    def strides(self) -> list[Stride]:
        p = self.processed
        if p is None:
            return []
        return strides(p.contacts, p.q[:, COORDS.index("x_B")], p.frame_rate)

    def line(self, full_path: bool = False) -> str:
        """One line: the take's strides and steps kept, or why it gave none (the take by
        its file name, or its whole path)."""
        p = self.processed
        if p is None:
            why = (self.error or "").removeprefix(f"{self.path}: ")
            return f"{self.path if full_path else self.path.name}: no step ({why})"
        n = {d: sum(s.domain == d for s in p.steps) for d in PAPER_DOMAINS}
        return (f"{self.path.name}: {len(self.strides)} full stride(s), steps kept "
                f"{n[Domain.PS]} ps + {n[Domain.PNS]} pns, {len(p.dropped)} dropped")


@dataclass(frozen=True)
class SessionResult:
    takes: tuple[TakeOutcome, ...]
    artifact: StepsArtifact
    steps_path: Path
    report_paths: tuple[Path, ...]
    #: the session's warnings (takes without steps, too few steps for a stage), one line each
    warnings: tuple[str, ...]
    #: the subject stored with the steps, and where each of its values came from
    subject: SubjectConfig | None = None
    provenance: dict[str, str] = field(default_factory=dict)

    @property
    def processed(self) -> list[ProcessedTake]:
        return [t.processed for t in self.takes if t.processed is not None]


def _same(a: object, b: object) -> bool:
    try:
        return bool(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True))
    except TypeError:
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def _time(vals: Sequence[np.ndarray]) -> np.ndarray:
    """The takes' times one after the other, from 0, ``TAKE_GAP`` between takes."""
    out, t_end = [], 0.0
    for k, t in enumerate(vals):
        t = np.asarray(t, float)
        out.append(t + (-t[0] if k == 0 else t_end + TAKE_GAP - t[0]))
        t_end = float(out[-1][-1])
    return np.concatenate(out)


def _indexed(name: str, vals: Sequence[np.ndarray], offsets: Sequence[int]) -> np.ndarray:
    """Frame indices shifted by each take's first frame (-1, none, kept); tau offsets
    renumbered."""
    if name == "tau_offsets":
        sizes = np.concatenate([np.diff(v) for v in vals])
        return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    if name in _SS_FRAMES:
        return np.concatenate([np.where(v >= 0, v + o, -1)
                               for v, o in zip(vals, offsets, strict=True)])
    return np.concatenate([v + o for v, o in zip(vals, offsets, strict=True)])


def _joint_fit(name: str, vals: Sequence[np.ndarray], best: int) -> np.ndarray:
    """The best take's marker -> joint vectors, the worst residual, well posed in all."""
    if name == "joint_lambda":
        return vals[best]
    if name == "joint_residual":
        return np.max(np.stack(vals), axis=0)
    return np.all(np.stack(vals), axis=0)


def _pooled_field(name: str, arts: Sequence[StepsArtifact], offsets: Sequence[int],
                  best: int, notes: list[str]) -> object:
    vals = [getattr(a, name) for a in arts]
    if any(v is None for v in vals):  # an optional field one of the takes lacks
        return None
    if name == "source":
        return " + ".join(vals)
    if name == "time":
        return _time(vals)
    if name in _FRAMES or name in _STEPS or name == "tau":
        return np.concatenate(vals)
    if name in _STEP_FRAMES or name in _SS_FRAMES or name == "tau_offsets":
        return _indexed(name, vals, offsets)
    if name in _JOINT_FIT:
        return _joint_fit(name, vals, best)
    if any(not _same(v, vals[0]) for v in vals[1:]):
        if name in ("frame_rate", "coord_names", "limb_names", "joint_names",
                    "hip_coefficients", "schema_version"):
            raise MocapError(f"session: the takes differ in '{name}' ("
                             + ", ".join(f"{a.source}: {np.asarray(v)}"
                                         for a, v in zip(arts, vals, strict=True))
                             + "): process them apart")
        notes.append(f"session: the takes differ in '{name}': the first take's is kept")
    return vals[0]


def pool(arts: Sequence[StepsArtifact], notes: list[str] | None = None) -> StepsArtifact:
    """The steps files of a session's takes as one (module docstring); ``notes`` gets a line
    for each per-take field that differs and was taken from the first take."""
    if not arts:
        raise MocapError("session: no take to pool")
    if len(arts) == 1:
        return arts[0]
    sink = notes if notes is not None else []
    offsets = np.concatenate([[0], np.cumsum([len(a.time) for a in arts])[:-1]]).tolist()
    best = int(np.argmax([a.n_steps for a in arts]))
    vals: dict[str, Any] = {f.name: _pooled_field(f.name, arts, offsets, best, sink)
                            for f in fields(StepsArtifact)}
    return StepsArtifact(**vals)


def stage_warnings(art: StepsArtifact) -> list[str]:
    """What the pooled steps lack for the later stages, one line each (the numbers the
    stages' own refusals check)."""
    from characterization.mocap.domain_segmentation import domain_segments

    out = []
    seg = domain_segments(art)
    for d in PAPER_DOMAINS:
        n = sum(s.domain == d for s in seg)
        if n == 0:
            out.append(f"`gait fit` needs at least one '{d}' portion between touchdowns; this "
                       f"session has 0: {MORE}")
    n_ss = sum(1 for i in range(art.n_steps)
               if art.step_domain[i] == Domain.PS and art.step_ss_start[i] >= 0)
    if n_ss < TUBE_MIN_STEPS:
        out.append(f"`tube fit` needs at least {TUBE_MIN_STEPS} ps steps with single support "
                   f"for a degree-3 tube (on a multi-contact gait: 2 for degree 1, and more "
                   f"to certify it); this session has {n_ss}: {MORE}")
    return out


def process_takes(paths: Sequence[str | os.PathLike[str]], run: object) -> list[TakeOutcome]:
    """Each take read and processed by ``run(take)`` (a :class:`ProcessedTake`); a take
    that gives no step or fails a check is an outcome with its one-line reason."""
    from characterization.mocap.files import read_take

    out = []
    for p in paths:
        path = Path(p)
        try:
            out.append(TakeOutcome(path, run(read_take(path))))  # type: ignore[operator]
        except MocapError as e:
            out.append(TakeOutcome(path, None, str(e)))
    return out


def process_session(paths: Sequence[str | os.PathLike[str]], out: str | os.PathLike[str], *,
                    subject: str | None = None, device: str | None = None,
                    mapping: str | os.PathLike[str] | object | None = None,
                    with_figures: bool = True) -> SessionResult:
    """Process every take, pool their steps and write the steps file and the session's QA
    report (one section per take).  Everything is computed before anything is written.
    Raises :class:`MocapError` (one line naming each take and why) when no take gives a
    step."""
    from characterization.mocap.mapping import MocapMapping, default_mapping, load_mapping
    from characterization.mocap.report import render_session_report
    from hp_model.config import (
        default_device_path,
        default_subject_path,
        load_device,
        load_subject,
        subject_record,
    )
    from hp_model.human_prosthesis import build_tree, hip_progress_coefficients

    outp = steps_output(out)
    for p in paths:
        if not Path(p).is_file():
            raise FileNotFoundError(f"{p}: no such file")
    m = (mapping if isinstance(mapping, MocapMapping) else
         load_mapping(mapping) if mapping is not None else default_mapping())  # type: ignore[arg-type]
    from characterization.mocap.files import read_take
    from characterization.mocap.subject_from_take import session_subject

    static = read_take(m.calibration.static_trial) if m.calibration is not None else None
    subject_error: Exception | None = None
    if subject:  # --subject FILE (a TOML, or a steps/gait file holding one)
        subj, prov = load_subject(subject), {"*": f"--subject {subject}"}
    else:  # the person of the takes (docs/subject.md)
        try:
            subj, prov = session_subject(paths, m, static)
        except (MocapError, ValueError) as e:  # the takes' own errors (units, mapping) first
            subject_error = e
            subj, prov = load_subject(default_subject_path()), {}
    tree = build_tree(subj, load_device(device or default_device_path()))
    coef = {d: hip_progress_coefficients(tree, d) for d in PAPER_DOMAINS}
    offsets = None
    if static is not None:
        offsets = static_offsets(static, m, subj.lengths)
    takes = process_takes(paths, lambda t: process_take(t, m, coef, subj.lengths, offsets))
    good = [t.processed for t in takes if t.processed is not None]
    if not good:  # each take by its path, as the file it names
        raise MocapError("no take of the session gives a step: " + "; ".join(
            t.line(full_path=True) for t in takes))
    if subject_error is not None:
        raise subject_error
    notes: list[str] = []
    art = replace(pool([to_artifact(p) for p in good], notes),
                  subject=subject_record(subj, prov))
    warns = [str(t.error) for t in takes if t.processed is None]
    warns += notes + stage_warnings(art)
    files = render_session_report(outp, takes, warns, with_figures)
    files[outp] = steps_bytes(outp, art)
    for path, data in files.items():  # the steps file last
        atomic_write_bytes(path, data)
    return SessionResult(tuple(takes), art, outp, tuple(p for p in files if p != outp),
                         tuple(warns), subj, prov)


def session_summary(takes: Sequence[TakeOutcome], warnings: Sequence[str]) -> dict:
    """The session part of the QA report (JSON-ready): each take's line and strides."""
    return {"takes": [{"source": str(t.path), "error": t.error, "line": t.line(),
                       "full_strides": len(t.strides)} for t in takes],
            "warnings": list(warnings)}


def session_bytes(summary: dict) -> bytes:
    return dumps(summary, indent=2).encode()

"""File-level entry points of motion-capture processing (used by ``hpcosim mocap``)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from characterization.mocap.c3d_io import read_c3d
from characterization.mocap.mapping import MocapMapping, default_mapping, load_mapping
from characterization.mocap.motive_csv import read_motive_csv
from characterization.mocap.pipeline import (
    ProcessedTake,
    process_take,
    static_offsets,
    to_artifact,
)
from characterization.mocap.report import render_report
from characterization.mocap.steps_artifact import steps_bytes, steps_output
from characterization.mocap.take import MocapError, Take
from characterization.mocap.trc_io import read_trc
from hp_model.atomic_io import atomic_write_bytes
from hp_model.domains import PAPER_DOMAINS

#: the take formats, by file extension: a reader returns a :class:`Take` (a new format is a
#: reader module and a row here)
READERS = {".csv": read_motive_csv, ".c3d": read_c3d, ".trc": read_trc}


def read_take(path: str | os.PathLike[str]) -> Take:
    """Read a Motive CSV (.csv), C3D (.c3d) or TRC (.trc) take."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    reader = READERS.get(p.suffix.lower())
    if reader is None:
        raise MocapError(f"{p}: unknown take format '{p.suffix}' (expected one of "
                         f"{', '.join(READERS)})")
    return reader(p)


@dataclass(frozen=True)
class ProcessResult:
    processed: ProcessedTake
    steps_path: Path
    report_paths: tuple[Path, ...]


def process_file(take_path: str | os.PathLike[str], out: str | os.PathLike[str], *,
                 subject: str | None = None, device: str | None = None,
                 mapping: str | os.PathLike[str] | MocapMapping | None = None,
                 with_figures: bool = True) -> ProcessResult:
    """Read a take, process it and write the steps file, QA report and figures.

    Everything is computed before anything is written, so bad input leaves no file.
    """
    from hp_model.config import default_device_path, default_subject_path, load_device, load_subject
    from hp_model.human_prosthesis import build_tree, hip_progress_coefficients

    outp = steps_output(out)
    m = (mapping if isinstance(mapping, MocapMapping) else
         load_mapping(mapping) if mapping is not None else default_mapping())
    take = read_take(take_path)
    subj = load_subject(subject or default_subject_path())
    # the coefficients need the model's tree only, not its dynamics (0.3 s to build)
    tree = build_tree(subj, load_device(device or default_device_path()))
    coef = {d: hip_progress_coefficients(tree, d) for d in PAPER_DOMAINS}
    offsets = None
    if m.calibration is not None:
        offsets = static_offsets(read_take(m.calibration.static_trial), m, subj.lengths)
    processed = process_take(take, m, coef, subj.lengths, offsets)
    files = render_report(outp, processed, with_figures)
    files[outp] = steps_bytes(outp, to_artifact(processed))
    for path, data in files.items():  # the steps file last
        atomic_write_bytes(path, data)
    return ProcessResult(processed, outp, tuple(p for p in files if p != outp))

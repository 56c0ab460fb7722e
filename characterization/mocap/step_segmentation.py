"""Step segmentation (paper Sec. IV-A, "Joint Trajectories from Motion Capture Data").

delta_p_hip(th_pk, th_pa) = c_k th_pk + c_a th_pa is the prosthesis-stance hip position
relative to the prosthesis ankle, linearised about upright
(:meth:`hp_model.HumanProsthesisModel.hip_progress_coefficients`, which makes it increase
during stance in this model's sign convention).  A portion where it increases from a turning
point (minimum) to the next (maximum) is a prosthesis-stance step ``ps``; from a maximum to
the next minimum, prosthesis non-stance ``pns``.  Turning points are found with hysteresis:
a turn counts once the signal has retreated ``min_excursion`` (m) from the running
extremum, so noise wiggles are ignored.  Partial portions at the take's ends are not steps.

Per step the phase variable is tau (:func:`hp_model.outputs.phase`) of delta, the stance
leg's delta_p_hip (ps: prosthesis knee/ankle; pns: the human's th_lk/th_la with the ``pns``
coefficients), with the bounds delta_lower, delta_upper its values at the step's first and
last frame (the paper's initial and final hip positions).

Double support (paper Sec. IV-B): single support by the stance leg is where the
non-stance foot's marker moves forward (sagittal x speed above a threshold); the ps rule
(human foot) is the paper's, the pns rule (prosthesis foot) its mirror.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from characterization.mocap.limb_angles import runs
from hp_model.domains import Domain
from hp_model.outputs import phase


@dataclass(frozen=True)
class StepBounds:
    """A step: its domain and frames [start, end] (both included)."""

    domain: Domain
    start: int
    end: int


def turning_points(delta: np.ndarray, min_excursion: float) -> list[tuple[int, str]]:
    """(index, "min"|"max") of the turning points of a finite signal, with hysteresis."""
    d = np.asarray(delta, float)
    n = len(d)
    pts: list[tuple[int, str]] = []
    if n < 3:
        return pts
    i_max = i_min = 0
    trend = 0
    for i in range(1, n):
        x = d[i]
        if trend >= 0 and x > d[i_max]:
            i_max = i
        if trend <= 0 and x < d[i_min]:
            i_min = i
        if trend <= 0 and x - d[i_min] >= min_excursion:
            pts.append((i_min, "min"))
            trend, i_max = 1, i
        elif trend >= 0 and d[i_max] - x >= min_excursion:
            pts.append((i_max, "max"))
            trend, i_min = -1, i
    # an extremum at the very first sample is the take's edge, not a turn
    return [(i, k) for i, k in pts if 0 < i < n - 1]


def segment_steps(delta_ps: np.ndarray, min_excursion: float) -> list[StepBounds]:
    """Complete steps between consecutive turning points of delta_p_hip(th_pk, th_pa);
    NaN samples are bridged linearly for the purpose of finding turns."""
    d = np.asarray(delta_ps, float)
    ok = np.isfinite(d)
    if ok.sum() < 3:
        return []
    idx = np.arange(len(d))
    d = np.interp(idx, idx[ok], d[ok])
    pts = turning_points(d, min_excursion)
    return [StepBounds(Domain.PS if ka == "min" else Domain.PNS, a, b)
            for (a, ka), (b, _) in itertools.pairwise(pts)]


def phase_tau(delta: np.ndarray) -> tuple[np.ndarray, float, float]:
    """tau over one step's frames and the bounds (delta at the first and last frame)."""
    lo, hi = float(delta[0]), float(delta[-1])
    return phase(delta, lo, hi), lo, hi


def single_support(foot_x: np.ndarray, rate: float, start: int, end: int,
                   speed_threshold: float) -> tuple[int, int] | None:
    """[first, last] frame of the longest run in [start, end] where the non-stance foot's
    sagittal x moves forward faster than ``speed_threshold`` (m/s); None if it never does.
    ``foot_x`` is the whole take (m, NaN allowed: bridged linearly)."""
    x = np.asarray(foot_x[start:end + 1], float)
    ok = np.isfinite(x)
    if ok.sum() < 3:
        return None
    i = np.arange(len(x))
    x = np.interp(i, i[ok], x[ok])
    v = np.gradient(x) * rate
    moving = runs(v > speed_threshold)
    if not moving:
        return None
    a, b = max(moving, key=lambda r: r[1] - r[0])
    return start + a, start + b - 1


#: s: the time between the takes pooled into one steps file (:mod:`session`); a frame-time
#: step longer than half of it starts a new take
TAKE_GAP = 1.0


def take_spans(time: np.ndarray) -> list[tuple[int, int]]:
    """[first, end) frames of each take pooled into a steps file's ``time`` (s): the takes
    are separated by ``TAKE_GAP`` (one span for a single take)."""
    cut = np.flatnonzero(np.diff(np.asarray(time, float)) > TAKE_GAP / 2) + 1
    bounds = [0, *cut.tolist(), len(time)]
    return list(itertools.pairwise(bounds))

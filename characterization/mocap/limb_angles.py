"""Limb pitch angles (paper Sec. II, "Compute Pitch Angles").

Per frame, a limb's sagittal pitch (rad, model convention: positive tilts the limb's +z axis
toward +x) comes from

1. its rigid body's orientation when the rigid body is tracked (source ``RIGID_BODY``);
2. else two markers on the limb, ``theta = atan2(x2 - x1, z2 - z1)`` (the paper's
   arctan((x2 - x1)/(z2 - z1)) with the quadrant kept; minus pi/2 for a pair along the
   limb's forward axis), aligned to the rigid body by the median difference over the frames
   where both exist (source ``MARKERS``);
3. else, in a gap no longer than ``max_gap_frames``, a cubic spline through the
   neighbouring samples (source ``INTERPOLATED``); longer gaps stay NaN (``NONE``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NONE, RIGID_BODY, MARKERS, INTERPOLATED = 0, 1, 2, 3
SOURCE_NAMES = {NONE: "none", RIGID_BODY: "rigid_body", MARKERS: "markers",
                INTERPOLATED: "interpolated"}


def wrap(a: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class Gap:
    """Frames [start, stop) with neither source; ``filled`` if interpolated."""

    start: int
    stop: int
    filled: bool

    @property
    def length(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class LimbPitch:
    """One limb's pitch over a take: ``theta`` (n,) rad, NaN in unfilled gaps; ``source``
    (n,) int8 codes (see module constants); ``pair_offset`` rad added to the marker-pair
    angle to align it with the rigid body (0 without a rigid body)."""

    limb: str
    theta: np.ndarray
    source: np.ndarray
    pair_offset: float
    gaps: tuple[Gap, ...]

    def counts(self) -> dict[str, int]:
        """Frames per source name."""
        return {SOURCE_NAMES[k]: int(np.sum(self.source == k)) for k in SOURCE_NAMES}


def pair_pitch(p1: np.ndarray, p2: np.ndarray, axis: str = "up") -> np.ndarray:
    """Pitch (rad) of the sagittal direction p1 -> p2 ((n, 2) arrays of x, z), for a pair
    lying along the limb's ``up`` axis or ``forward`` axis at zero pitch."""
    d = p2 - p1
    th = np.arctan2(d[:, 0], d[:, 1])
    if axis == "forward":
        th = wrap(th - np.pi / 2)
    return th


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where ``mask`` is True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return list(zip(d[::2].tolist(), d[1::2].tolist(), strict=True))


def fill_short_gaps(t: np.ndarray, y: np.ndarray, max_gap: int
                    ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Cubic-spline fill of NaN runs no longer than ``max_gap`` frames that have valid
    samples on both sides.  Returns (filled copy, filled mask, all NaN runs)."""
    y = np.array(y, dtype=float)
    bad = ~np.isfinite(y)
    filled = np.zeros(y.shape, bool)
    gaps = runs(bad)
    ok = ~bad
    if ok.sum() < 2 or not gaps:
        return y, filled, gaps
    todo = [(a, b) for a, b in gaps if b - a <= max_gap and a > 0 and b < len(y)]
    if todo:
        from scipy.interpolate import CubicSpline  # lazily: 0.4 s of imports

        idx = np.concatenate([np.arange(a, b) for a, b in todo])
        y[idx] = CubicSpline(t[ok], y[ok])(t[idx])  # not-a-knot at both ends
        filled[idx] = True
    return y, filled, gaps


def lowpass(y: np.ndarray, rate: float, cutoff: float, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass over each finite run (NaN runs kept); ``rate`` and
    ``cutoff`` in Hz, the cutoff below the Nyquist frequency ``rate / 2`` (callers check).
    A run no longer than the filter's padding (9 samples at order 2) is left as it is."""
    if cutoff <= 0:
        return y
    from scipy.signal import butter, sosfiltfilt  # lazily: 0.4-0.9 s of imports

    sos = butter(order, cutoff / (rate / 2), output="sos")
    out = np.array(y, dtype=float)
    # sosfiltfilt's default padding: 3 taps per side, a first-order section counting one less
    pad = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    for a, b in runs(np.isfinite(out)):
        if b - a > pad:
            out[a:b] = sosfiltfilt(sos, out[a:b])
    return out


def limb_pitch(limb: str, t: np.ndarray, rb_theta: np.ndarray | None,
               pair_theta: np.ndarray | None, max_gap: int) -> LimbPitch:
    """Combine the two sources of one limb (see the module docstring).

    ``rb_theta``/``pair_theta``: (n,) rad with NaN where unavailable, or None if the limb has
    no such source.  ``max_gap``: frames.
    """
    n = len(t)
    rb = np.full(n, np.nan) if rb_theta is None else np.asarray(rb_theta, float)
    pair = np.full(n, np.nan) if pair_theta is None else np.asarray(pair_theta, float)
    both = np.isfinite(rb) & np.isfinite(pair)
    offset = float(np.median(wrap(rb[both] - pair[both]))) if both.any() else 0.0
    theta = np.where(np.isfinite(rb), rb, pair + offset)
    source = np.where(np.isfinite(rb), RIGID_BODY,
                      np.where(np.isfinite(pair), MARKERS, NONE)).astype(np.int8)
    # unwrap the known samples so interpolation never crosses the +-pi seam
    ok = np.isfinite(theta)
    if ok.any():
        theta[ok] = np.unwrap(theta[ok])
    theta, filled, nan_runs = fill_short_gaps(t, theta, max_gap)
    source[filled] = INTERPOLATED
    gaps = tuple(Gap(a, b, bool(filled[a])) for a, b in nan_runs)
    theta.setflags(write=False)
    source.setflags(write=False)
    return LimbPitch(limb, theta, source, offset, gaps)

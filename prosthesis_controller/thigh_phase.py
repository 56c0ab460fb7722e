"""The swing phase from the residual thigh (:class:`ThighSwingPhase`): no clock.

Through a prosthesis swing the socket's world pitch (the residual thigh's, from AMPRO3's IMU;
rad, positive toe-down, so a flexing thigh's pitch falls) falls from toe-off to the thigh's
peak flexion at phase ``s_peak`` (about 0.6-0.7 of the swing on the real takes' gaits: 25-35
deg), then rises a few degrees as the person retracts the leg for the heel strike.  The phase
is read off the gait's own thigh pitch against its swing phase (``tables_from_walk``), one
branch at a time:

- theta is the pitch as read on the steep part of the flexion (no lag there), else
  low-passed over ``SMOOTHING`` against the IMU's noise (the phase never falls back, so raw
  noise would ratchet it ahead, most near the peak where the pitch is flat);
- **flexing** (from toe-off): s = S_flex(theta - delta), delta = the pitch at toe-off less
  the gait's (a person's posture offset or an IMU bias moves the whole thigh curve);
- **retracting** (once theta has risen ``TURN`` above its least value since toe-off):
  s = S_retract(theta - delta'), delta' = that least value less the gait's peak, so the
  branch starts where the thigh turned;
- where the pitch hardly changes (around the peak, and at the end of the retraction, where
  the gaits' thigh stops or flexes again by a few tenths of a degree before the heel strike)
  the phase goes on at the rate the thigh set over the steep part of its flexion
  (``RATE_SPAN`` of the branch: this swing's pace, not the gait's): at most ``CARRY`` past
  the peak until the retraction is seen (the phase waits for the thigh to turn), then on to
  the heel strike, the retracting branch taking it further where the thigh leads;
- the phase never falls back (the larger of the new and the last), and stays in [0, 1].

So a person who swings the thigh faster or slower than the gait moves the prosthesis's swing
with them: the phase is where the thigh is, not how long ago the toe left the ground
(Quintero, Villarreal, Lambert, Kapp, Gregg, IEEE T-RO 2018, make the same point for a whole
stride from the thigh's angle and its integral; a swing alone has its toe-off to start
from).  Before, the swing phase was the time since toe-off over the gait's swing time: with a
simulated person whose hip moved 8 % slower than the gait's, ``clfqp`` and contact-pd fell
in 2-3 steps while the held oracle walked (docs/gait-design.md).
"""

from __future__ import annotations

import math

import numpy as np

#: rad: how far the (smoothed) pitch must rise above its least value since toe-off before the
#: retracting branch takes over (above the IMU noise the perturbation families put on it,
#: 0.2 deg, smoothed)
TURN = math.radians(1.0)
#: s: the time constant of the pitch's low-pass (the turn's detection, the flat peak and the
#: retraction)
SMOOTHING = 0.005
#: the flexing branch runs to this fraction of its phase span before a turn is believed
EARLIEST_TURN = 0.5
#: the part of the flexing branch (fractions of its span) whose mean phase rate carries the
#: phase over the peak, from the end of that part on
RATE_SPAN = (0.2, 0.8)
#: how far past the peak (phase) the phase is carried at that rate before the retraction
CARRY = 0.1


class ThighSwingPhase:
    """The swing phase of the module docstring for one gait: ``phase`` (n,) rising from 0
    to 1 over the swing, ``pitch`` (n,) the socket's world pitch (rad) there."""

    def __init__(self, phase: np.ndarray, pitch: np.ndarray) -> None:
        s, th = np.asarray(phase, float), np.asarray(pitch, float)
        if s.ndim != 1 or s.shape != th.shape or s.size < 4:
            raise ValueError("a swing's phase and pitch must be two equal rows of >= 4 samples")
        if not (np.all(np.isfinite(s)) and np.all(np.isfinite(th))):
            raise ValueError("a swing's phase and pitch must be finite")
        k = int(np.argmin(th))
        if k == 0:
            raise ValueError("the swing's thigh pitch does not fall after toe-off (no flexion)")
        self.s_peak = float(s[k])
        self.pitch_off, self.pitch_peak = float(th[0]), float(th[k])
        # each branch as a rising table of (pitch, phase) for np.interp: the flexing one
        # by the pitch's fall, the retracting one by its rise, each made monotone
        self._flex = (np.maximum.accumulate(-th[: k + 1]), s[: k + 1])
        self._retract = (np.maximum.accumulate(th[k:]), s[k:])
        self.reset(math.nan, math.nan)

    def reset(self, t: float, pitch: float) -> None:
        """A toe-off at time ``t`` (s) with the socket at ``pitch`` (rad)."""
        self._delta = pitch - self.pitch_off if math.isfinite(pitch) else 0.0
        self._smooth = pitch
        self._least = pitch
        self._t = t
        self._retracting = False
        self.value = 0.0
        #: (time, phase) where the phase entered RATE_SPAN, and the rate over it (1/s)
        self._rate_start: tuple[float, float] | None = None
        self._rate = math.nan

    def update(self, t: float, pitch: float) -> float:
        """The phase at time ``t`` (s) with the socket at ``pitch`` (rad), both finite."""
        if not math.isfinite(self._smooth):
            self.reset(t, pitch)
        dt = max(t - self._t, 0.0)
        k = min(dt / SMOOTHING, 1.0)
        self._t = t
        self._smooth += k * (pitch - self._smooth)
        self._least = min(self._least, self._smooth)
        if not self._retracting:
            # raw on the steep part (no lag), smoothed towards the flat peak
            th = pitch if self.value < RATE_SPAN[1] * self.s_peak else self._smooth
            s = float(np.interp(-(th - self._delta), *self._flex))
            if (self._smooth > self._least + TURN and
                    max(s, self.value) >= EARLIEST_TURN * self.s_peak):
                self._retracting = True
                self._delta = self._least - self.pitch_peak
        if self._retracting:
            s = float(np.interp(self._smooth - self._delta, *self._retract))
        s = max(s, self._carried(t, dt))
        self.value = min(max(s, self.value), 1.0)
        return self.value

    def _carried(self, t: float, dt: float) -> float:
        """The phase carried on at the thigh's own rate past ``RATE_SPAN`` (else 0): up to
        ``CARRY`` past the peak until the retraction is seen, then on."""
        lo, hi = (f * self.s_peak for f in RATE_SPAN)
        if self._rate_start is None and self.value >= lo:
            self._rate_start = (t, self.value)
        if math.isnan(self._rate) and self._rate_start is not None and self.value >= hi:
            t0, s0 = self._rate_start
            self._rate = (self.value - s0) / (t - t0) if t > t0 else math.nan
        if math.isnan(self._rate):
            return 0.0
        carried = self.value + self._rate * dt
        return carried if self._retracting else min(carried, self.s_peak + CARRY)

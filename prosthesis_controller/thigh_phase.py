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
- **flexing** (from toe-off): s = S_flex((top - theta) R_gait / R), the pitch's fall from
  its highest value since toe-off (``top``, followed until ``EARLIEST_TURN`` of the peak's
  phase) against the gait's fall from its own highest pitch, scaled by the flexion's range:
  R_gait the gait's (top to peak), R this swing's, from ``top`` to the peak it is expected
  to reach (within ``RANGE`` of R_gait).  The expected peak is the gait's peak pitch plus
  the person's offset from it that the last swing showed (:attr:`peak_offset`): a person's
  thigh peaks where it peaked the last swing, while its pitch at toe-off varies from step
  to step (on the committed openOFM cycle the second swing starts 0.4 deg lower than the
  first and peaks within 0.03 deg of it; read against the last swing's range instead, its
  phase lagged the clock by 2 % at the peak and the prosthesis landed 5 ms late, which the
  simulated person on its toe does not survive).  Before the person's peak is seen (a
  walk's first swing) it is the gait's: on the fit of the synthetic person's take the
  first swing's thigh leaves the ground 0.23 deg higher than the gait's and peaks within
  0.01 deg of it; read against the gait's range, the phase ran 2 % ahead of the clock, the
  prosthesis held its landing posture at rest before it landed, and the person on its toe
  slid.  A posture offset or an IMU bias the stance did not remove moves the whole thigh
  curve, its peak too: the first swing reads it off (3 deg: by up to 0.27 of
  the phase, mostly near the flat peak), the next ones from the peak it reached.  A
  person whose thigh extends a few degrees after toe-off (the simulated person under
  posture offsets: 4 deg over 40 ms, the gait's 0.3 deg) starts its flexion from there,
  not from the pitch at toe-off; a person walking faster swings the thigh through more
  from a higher toe-off to the same peak (on the committed openOFM cycle with the hip 8 %
  faster, 40 deg against the gait's 36: read against the gait's range the phase ended the
  swing at 1.32, against the expected peak at 0.98; Quintero et al. scale the thigh's
  phase portrait by the last stride's range);
- **retracting** (once theta has risen ``TURN`` above its least value since toe-off):
  s = S_retract(peak + theta - least), the rise from that least value against the gait's
  from its peak, so the branch starts where the thigh turned (not scaled: on the committed
  cycle a faster person's thigh starts its swing higher and peaks where the gait's does);
- past the steep part of the flexion (where the pitch hardly changes: around the peak, and
  in the retraction, where the gaits' thigh rises by a degree or less, or flexes again, before
  the heel strike) the phase goes on at the rate the thigh set over the steep part
  (``RATE_SPAN`` of the branch: this swing's pace, not the gait's), on to 1 and past it, the
  retracting branch taking it further where the thigh leads.  There the flexing branch's
  reading is not used: near the flat peak a tenth of a degree is a large step of the phase
  (the packaged person's library peaks at 0.86-0.97 of its swings; a person flexing 0.7
  deg past the expected peak read the gait's peak at 0.85 of the swing, and the phase
  reached the heel strike at 1.15).  Past 1 the swing has outlasted
  the thigh's pace: the law holds the landing posture at rest until the heel strike
  (:meth:`~prosthesis_controller.contact_phase_pd.ContactPhasePD.reference`), as it does for
  the clock;
- the phase never falls back (the larger of the new and the last) and is never negative.

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
#: the flexing branch runs to this fraction of its phase span before a turn is believed (and
#: the flexion's start, the highest pitch since toe-off, is followed until then)
EARLIEST_TURN = 0.5
#: the flexion's range a swing is read against, as fractions of the gait's (a swing
#: outside it is not a walking one: a stumble, a stop)
RANGE = (0.5, 2.0)
#: the part of the flexing branch (fractions of its span) whose mean phase rate carries the
#: phase on, from the end of that part
RATE_SPAN = (0.2, 0.8)


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
        self.pitch_top, self.pitch_peak = float(np.max(th[: k + 1])), float(th[k])
        # each branch as a rising table of (pitch, phase) for np.interp: the flexing one
        # by the pitch's fall from the gait's highest, the retracting one by its rise, each
        # made monotone
        self._flex = (np.maximum.accumulate(self.pitch_top - th[: k + 1]), s[: k + 1])
        self._retract = (np.maximum.accumulate(th[k:]), s[k:])
        self.gait_range = self.pitch_top - self.pitch_peak
        #: rad: the person's peak flexion pitch less the gait's, as the last swing that got
        #: past its peak showed it (0 before one: a walk's first swing)
        self.peak_offset = 0.0
        self._top = self._least = math.nan
        self.value = 0.0
        self.reset(math.nan, math.nan)

    def reset(self, t: float, pitch: float) -> None:
        """A toe-off at time ``t`` (s) with the socket at ``pitch`` (rad); the swing before,
        if it got past its peak, sets the peak this one is expected to reach."""
        if self.value > self.s_peak and math.isfinite(self._least):
            self.peak_offset = self._least - self.pitch_peak
        self._smooth = self._top = self._least = pitch
        self._turned_at = pitch  # the least pitch when the retraction was believed
        self._t = t
        self._retracting = False
        self.value = 0.0
        #: (time, phase) where the phase entered RATE_SPAN, and the rate over it (1/s)
        self._rate_start: tuple[float, float] | None = None
        self._rate = math.nan

    def take_over(self, other: ThighSwingPhase) -> None:
        """Continue from ``other``'s swing and the person's peak offset (another gait's
        tables: a switch of speed mid-swing, :mod:`prosthesis_controller.speed_following`;
        the peak expected is this gait's plus the person's offset)."""
        for k in ("peak_offset", "_smooth", "_top", "_least", "_turned_at", "_t", "_retracting",
                  "value", "_rate_start", "_rate"):
            setattr(self, k, getattr(other, k))

    def update(self, t: float, pitch: float) -> float:
        """The phase at time ``t`` (s) with the socket at ``pitch`` (rad), both finite."""
        if not math.isfinite(self._smooth):
            self.reset(t, pitch)
        dt = max(t - self._t, 0.0)
        k = min(dt / SMOOTHING, 1.0)
        self._t = t
        self._smooth += k * (pitch - self._smooth)
        self._least = min(self._least, self._smooth)
        if self.value < EARLIEST_TURN * self.s_peak:
            self._top = max(self._top, self._smooth)
        if not self._retracting:
            # raw on the steep part (no lag), smoothed towards the flat peak
            th = pitch if self.value < RATE_SPAN[1] * self.s_peak else self._smooth
            s = float(np.interp((self._top - th) * self.gait_range / self.flexion_range(),
                                *self._flex))
            if not math.isnan(self._rate):  # past the steep part: carried at its rate
                s = 0.0
            if (self._smooth > self._least + TURN and
                    max(s, self.value) >= EARLIEST_TURN * self.s_peak):
                self._retracting = True
                self._turned_at = self._least
        if self._retracting:
            rise = self._smooth - self._turned_at
            s = float(np.interp(self.pitch_peak + rise, *self._retract))
        self.value = max(s, self._carried(t, dt), self.value)
        return self.value

    def flexion_range(self) -> float:
        """R (rad): this swing's flexion from its highest pitch since toe-off to the peak
        it is expected to reach (module docstring), within ``RANGE`` of the gait's."""
        r = self._top - self.pitch_peak - self.peak_offset
        lo, hi = RANGE
        return min(max(r, lo * self.gait_range), hi * self.gait_range)

    def _carried(self, t: float, dt: float) -> float:
        """The phase carried on at the thigh's own rate past ``RATE_SPAN`` (else 0)."""
        lo, hi = (f * self.s_peak for f in RATE_SPAN)
        if self._rate_start is None and self.value >= lo:
            self._rate_start = (t, self.value)
        if math.isnan(self._rate) and self._rate_start is not None and self.value >= hi:
            t0, s0 = self._rate_start
            self._rate = (self.value - s0) / (t - t0) if t > t0 else math.nan
        if math.isnan(self._rate):
            return 0.0
        return self.value + self._rate * dt

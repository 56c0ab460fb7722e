"""A prosthesis controller that follows the person's walking speed (:class:`SpeedFollowing`):
one multi-contact controller per speed of a gait library (each made from that speed's gait,
as the single-gait controllers are), the active one the nearest to the speed it estimates
from its own sensors.  No clock, no speed sensor: the socket IMU, the encoders, the foot
switch and the library.

- **Estimate**: while the prosthesis foot is flat in stance (its active controller's
  ``tables.flat`` window of the stance phase), the hip's progress over the foot is the
  phase's (:meth:`~prosthesis_controller.contact_phase_pd.ContactPhasePD.stance_phase`: the
  leg's kinematics from the IMU and the encoders); its mean rate over that window, read at
  toe-off, is the hip's speed over the flat foot, which the person's own hip sets (the
  simulated person's rate output; a person walking faster moves the hip faster over the
  stance foot).  The speed is read off the rates of the person walking each controller's
  speed (:func:`flat_stance_rate` of its held walk), linearly between and clamped to their
  range: measured there, not interpolated between the library's speeds, whose curves
  blended walk up to 0.03 m/s off the blend of their rates.  A stance whose flat window
  lasts under 0.05 s (a stumble) or over 2 s (a stop) leaves the estimate as it was.
- **Switch**: at the next heel strike, to the controller nearest the estimate less
  ``MARGIN`` (the library's speeds and others between them, :func:`filled`), handed the
  outgoing one's state (the IMU bias estimate, the torque the rate limit starts from, the
  counts: ``take_over``), so the stance runs on the references of the person's speed.  The
  margin centres the controller in the speeds it walks: on gaitalytics' library a
  controller made at u walked a person at v (12 steps from the cycle's start) for
  v - 0.08 <= u <= v + 0.015 m/s (``clfqp`` at 0.9 m/s; contact-pd v + 0.05), and fell
  within two steps when made faster, up to 1.1 m/s; from 1.2 m/s ``clfqp``'s window turns
  to the faster side, where the margin does not serve it (docs/gait-design.md).
- **Start**: the controller of ``speed`` (the speed the person starts at, a setting as a
  prosthetist sets one) until the first flat stance is read.

Before, the estimate was the stride period (heel strike to heel strike) read off the
library's strides: one stride late, and read through the coupled walk (under ``clfqp`` the
person's strides came out 1-2 % shorter than its curves', 0.03 m/s of speed), it lagged a
ramp of 0.02 m/s per s by 0.04-0.07 m/s, past the controllers' window (a controller made
0.05 m/s off the person's speed fell within a few steps), docs/gait-design.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from prosthesis_controller.contact_phase_pd import ContactGaitTables, first_stride
from prosthesis_controller.interface import ControlOutput
from prosthesis_controller.measurement import ProsthesisMeasurement

#: m/s: the default spacing of the speeds the controller switches between (:func:`filled`)
SPEED_RESOLUTION = 0.02
#: s: a flat stance shorter than this, or longer than the second, is not a walking stance
#: (the estimate is kept)
WINDOW_RANGE = (0.05, 2.0)
#: m/s: the active controller is the one nearest the estimate less this (module docstring)
MARGIN = 0.03


class Handover(Protocol):
    """A multi-contact controller that can take over another's state."""

    name: str
    fallbacks: int

    @property
    def phase(self) -> float: ...

    @property
    def tables(self) -> ContactGaitTables: ...

    def reset(self, torque: tuple[float, float] | None = None) -> None: ...

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput: ...

    def take_over(self, other: Handover) -> None: ...

    def blended(self, other: Handover, w: float) -> Handover: ...


def flat_stance_rate(tables: ContactGaitTables, t: np.ndarray, phase: np.ndarray,
                     contact: np.ndarray) -> float:
    """The hip's mean progress rate (m/s) over the flat window of the first stance of a walk
    sampled each period: ``t`` (n,) s, ``phase`` (n,) the stance phase the controller of
    ``tables`` reads, ``contact`` (n,) the foot switch (the estimate's measure, module
    docstring).  ValueError without a stance or a flat window in it."""
    i0, i1, _ = first_stride(contact)
    s = np.asarray(phase, float)[i0:i1]
    f0, f1 = tables.flat
    k = np.flatnonzero((s >= f0) & (s <= f1))
    if k.size < 2 or t[i0 + k[-1]] <= t[i0 + k[0]]:
        raise ValueError("the walk's first stance has no flat window")
    a, b = k[0], k[-1]
    span = tables.progress[1] - tables.progress[0]
    return float((s[b] - s[a]) * span / (t[i0 + b] - t[i0 + a]))


def rising(rates: Sequence[float]) -> list[int]:
    """The places of the longest strictly rising run (not necessarily contiguous) of
    ``rates`` (m/s, in their speeds' order): the calibration points the estimate keeps.  A
    walk that is not yet periodic reads off its neighbours (the packaged person's gait at
    0.9 m/s strides at 0.94-0.96 m/s in closed loop, and its flat stance read 1.01 m/s where
    its neighbours read 0.89 and above)."""
    r = list(rates)
    best: list[list[int]] = []
    for i, x in enumerate(r):
        prev = [b for j, b in enumerate(best) if r[j] < x]
        best.append([*max(prev, key=len, default=[]), i])
    return max(best, key=len, default=[])


def filled(controllers: Sequence[Handover], speeds: Sequence[float], resolution: float
           ) -> tuple[list[Handover], np.ndarray]:
    """The library's controllers with others between them every ``resolution`` m/s or
    closer, and their speeds: each made by blending its two neighbours' references and data
    linearly in the speed (``blended``, the weights of
    :meth:`characterization.gait.library.GaitLibrary.gait_at`): the speeds the controller
    switches between.  A library's speeds are 0.2 m/s apart; a controller 0.05 m/s off the
    person's speed fell within a few steps (docs/gait-design.md)."""
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0 m/s, got {resolution}")
    v = np.asarray(speeds, float)
    out, vs = [controllers[0]], [v[0]]
    for i in range(len(v) - 1):
        n = max(math.ceil((v[i + 1] - v[i]) / resolution - 1e-9), 1)
        for k in range(1, n):
            w = k / n
            out.append(controllers[i].blended(controllers[i + 1], w))
            vs.append((1 - w) * v[i] + w * v[i + 1])
        out.append(controllers[i + 1])
        vs.append(v[i + 1])
    return out, np.array(vs)


class SpeedFollowing:
    """The controller of the module docstring: ``controllers`` at ``speeds`` (m/s,
    increasing: the library's and those between, :func:`filled`); the estimate reads the
    flat stance's hip rate against ``rates`` (m/s) measured at ``rate_speeds`` (m/s; both
    rising: :func:`rising`); it starts on the controller nearest ``speed`` less
    ``MARGIN``."""

    def __init__(self, controllers: Sequence[Handover], speeds: Sequence[float],
                 rate_speeds: Sequence[float], rates: Sequence[float], speed: float) -> None:
        v, rv, r = (np.asarray(x, float) for x in (speeds, rate_speeds, rates))
        if len(controllers) == 0 or len(controllers) != v.size or np.any(np.diff(v) <= 0):
            raise ValueError("one controller per speed, the speeds increasing")
        if rv.size < 2 or rv.shape != r.shape or np.any(np.diff(rv) <= 0) \
                or np.any(np.diff(r) <= 0):
            raise ValueError(f"the flat-stance hip rates and their speeds must rise together, "
                             f"two or more (speeds {rv.round(3).tolist()}, rates "
                             f"{r.round(3).tolist()})")
        if not math.isfinite(speed):
            raise ValueError(f"the initial speed must be finite, got {speed}")
        self.controllers, self.speeds = tuple(controllers), v
        self.rate_speeds, self.rates = rv, r
        self.name = self.controllers[0].name
        self.initial_speed = float(speed)
        self.reset()

    def reset(self, torque: tuple[float, float] | None = None) -> None:
        """Back to the initial speed's controller, no stance measured."""
        #: the estimated walking speed (m/s) and the active controller's place
        self.speed = self.initial_speed
        self.active = self._nearest(self.speed - MARGIN)
        for c in self.controllers:
            c.reset(torque)
        self._contact: bool | None = None
        #: the flat window's first and last (t, phase) of this stance
        self._first: tuple[float, float] | None = None
        self._last: tuple[float, float] | None = None

    def restart(self, speed: float) -> None:
        """:meth:`reset` with the person starting at ``speed`` (m/s) from now on."""
        if not math.isfinite(speed):
            raise ValueError(f"the initial speed must be finite, got {speed}")
        self.initial_speed = float(speed)
        self.reset()

    @property
    def fallbacks(self) -> int:
        """The active controller's count of ticks it could not use (each takes over the
        outgoing one's)."""
        return self.controller.fallbacks

    def _nearest(self, v: float) -> int:
        return int(np.argmin(np.abs(self.speeds - v)))

    @property
    def controller(self) -> Handover:
        """The active controller."""
        return self.controllers[self.active]

    @property
    def phase(self) -> float:
        return self.controller.phase

    def speed_of(self, rate: float) -> float:
        """The walking speed (m/s) of a flat stance's hip rate (m/s) (module docstring)."""
        return float(np.interp(rate, self.rates, self.rate_speeds))

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        contact = bool(m.contact)
        if not contact and self._contact:  # a toe-off
            self._read_stance()
        elif contact and self._contact is False:  # a heel strike
            self._switch()
        out = self.controller.tick(m)
        if contact and math.isfinite(m.t):
            s, (f0, f1) = self.controller.phase, self.controller.tables.flat
            if f0 <= s <= f1:
                if self._first is None:
                    self._first = (m.t, s)
                self._last = (m.t, s)
        self._contact = contact
        return out

    def _read_stance(self) -> None:
        """The estimate from the flat window of the stance that ended (module docstring)."""
        first, last, self._first, self._last = self._first, self._last, None, None
        if first is None or last is None:
            return
        window = last[0] - first[0]
        if not WINDOW_RANGE[0] <= window <= WINDOW_RANGE[1]:
            return
        p0, p1 = self.controller.tables.progress
        self.speed = self.speed_of((last[1] - first[1]) * (p1 - p0) / window)

    def _switch(self) -> None:
        """To the controller of the estimate (module docstring), at a heel strike."""
        nxt = self._nearest(self.speed - MARGIN)
        if nxt != self.active:
            self.controllers[nxt].take_over(self.controller)
            self.active = nxt


@dataclass(frozen=True)
class FollowingSetup:
    """What a :class:`SpeedFollowing` is made of, as its file keeps it
    (:func:`prosthesis_controller.gait_tables.save_speed_following`): the ``controllers`` at
    a gait library's ``speeds`` (m/s, increasing), the ``resolution`` (m/s) of those
    switched between (:func:`filled`), and the estimate's calibration, the flat-stance hip
    ``rates`` (m/s) of the person walking ``rate_speeds`` (m/s; both rising)."""

    controllers: tuple[Handover, ...]
    speeds: tuple[float, ...]
    resolution: float
    rate_speeds: tuple[float, ...]
    rates: tuple[float, ...]

    def controller(self, speed: float) -> SpeedFollowing:
        """The controller following the person, who starts at ``speed`` (m/s)."""
        grid, speeds = filled(self.controllers, self.speeds, self.resolution)
        return SpeedFollowing(grid, speeds.tolist(), self.rate_speeds, self.rates, speed)

"""A prosthesis controller that follows the person's walking speed (:class:`SpeedFollowing`):
one multi-contact controller per speed of a gait library (each made from that speed's gait,
as the single-gait controllers are), the active one the nearest to the speed it estimates
from its own strides.  No clock, no speed sensor: the foot switch and the library.

- **Estimate**: at each heel strike of the prosthesis foot (the foot switch turning on) the
  time since the last one is the person's stride period; the speed is read off the
  library's stride periods against its speeds (a person walking faster takes shorter
  strides: on gaitalytics' take 1.52 s at 0.6 m/s to 0.98 s at 1.4), linearly between and
  clamped to its range.  Strides outside 0.5-2.5 s (a stop, a stumble, the start) leave the
  estimate as it was.
- **Switch**: at that heel strike, to the controller of the speed nearest the estimate
  (the library's speeds and others between them, :func:`filled`), handed the outgoing
  one's state (the IMU bias estimate, the torque the rate limit starts from, the counts:
  ``take_over``), so the stance starts on the references of the person's speed.
- **Start**: the controller of ``speed`` (the speed the person starts at, a setting as a
  prosthetist sets one) until the first full stride.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from prosthesis_controller.interface import ControlOutput
from prosthesis_controller.measurement import ProsthesisMeasurement

#: m/s: the default spacing of the speeds the controller switches between (:func:`filled`)
SPEED_RESOLUTION = 0.02
#: the share of a stride's speed the estimate takes (an exponential filter over strides)
GAIN = 0.5
#: s: stride periods outside this range are not walking strides (the estimate is kept)
STRIDE_RANGE = (0.5, 2.5)


class Handover(Protocol):
    """A multi-contact controller that can take over another's state."""

    name: str

    @property
    def phase(self) -> float: ...

    def reset(self, torque: tuple[float, float] | None = None) -> None: ...

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput: ...

    def take_over(self, other: Handover) -> None: ...

    def blended(self, other: Handover, w: float) -> Handover: ...


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
    """The controller of the module docstring: ``controllers[i]`` made from the library's
    gait at ``speeds[i]`` (m/s, increasing) whose stride lasts ``strides[i]`` (s); it
    starts on the one nearest ``speed``."""

    def __init__(self, controllers: Sequence[Handover], speeds: Sequence[float],
                 strides: Sequence[float], speed: float) -> None:
        v, T = np.asarray(speeds, float), np.asarray(strides, float)
        if len(controllers) == 0 or len(controllers) != v.size or v.shape != T.shape:
            raise ValueError("one controller per library speed, with its stride period")
        if np.any(np.diff(v) <= 0) or np.any(np.diff(T) >= 0):
            raise ValueError(f"the library's speeds must increase and its strides shorten "
                             f"(speeds {v.round(3).tolist()}, strides {T.round(3).tolist()})")
        if not math.isfinite(speed):
            raise ValueError(f"the initial speed must be finite, got {speed}")
        self.controllers, self.speeds, self.strides = tuple(controllers), v, T
        self.name = self.controllers[0].name
        self.initial_speed = float(speed)
        self.reset()

    def reset(self, torque: tuple[float, float] | None = None) -> None:
        """Back to the initial speed's controller, no stride measured."""
        #: the estimated walking speed (m/s) and the active controller's place
        self.speed = self.initial_speed
        self.active = self._nearest(self.speed)
        for c in self.controllers:
            c.reset(torque)
        self._contact: bool | None = None
        self._t_strike: float | None = None

    def _nearest(self, v: float) -> int:
        return int(np.argmin(np.abs(self.speeds - v)))

    @property
    def controller(self) -> Handover:
        """The active controller."""
        return self.controllers[self.active]

    @property
    def phase(self) -> float:
        return self.controller.phase

    def speed_of(self, stride: float) -> float:
        """The walking speed (m/s) of a stride period (s), from the library (module
        docstring)."""
        return float(np.interp(stride, self.strides[::-1], self.speeds[::-1]))

    def tick(self, m: ProsthesisMeasurement) -> ControlOutput:
        contact = bool(m.contact)
        if contact and self._contact is False and math.isfinite(m.t):  # a heel strike
            if self._t_strike is not None:
                stride = m.t - self._t_strike
                if STRIDE_RANGE[0] <= stride <= STRIDE_RANGE[1]:
                    self.speed += GAIN * (self.speed_of(stride) - self.speed)
                    nxt = self._nearest(self.speed)
                    if nxt != self.active:
                        self.controllers[nxt].take_over(self.controller)
                        self.active = nxt
            self._t_strike = m.t
        self._contact = contact
        return self.controller.tick(m)

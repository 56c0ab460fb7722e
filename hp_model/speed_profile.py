"""A commanded walking speed over time: what the simulated person is asked to walk at
(scenarios, ``hpcosim run``, sweep specs).

Knots (t_i s, v_i m/s) with increasing times; linear between them, v_0 before the first and
the last speed after the last.  Its text form (the command line's and the specs') is
``t:v`` pairs, comma-separated: ``0:0.8,20:1.2,40:0.8`` (0.8 m/s at the start, 1.2 m/s at
20 s, 0.8 again at 40 s); a single speed ``1.0`` is a constant command.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: m/s: the speeds a command may ask for (slow to brisk walking, with a margin)
SPEED_RANGE = (0.2, 2.5)


@dataclass(frozen=True)
class SpeedProfile:
    """The knots' times (s, increasing) and speeds (m/s)."""

    times: tuple[float, ...]
    speeds: tuple[float, ...]

    def __post_init__(self) -> None:
        t, v = np.asarray(self.times, float), np.asarray(self.speeds, float)
        if t.ndim != 1 or t.size == 0 or t.shape != v.shape:
            raise ValueError("a speed profile needs as many times as speeds, at least one")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ValueError("a speed profile's times and speeds must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError(f"a speed profile's times must increase, got {t.tolist()}")
        lo, hi = SPEED_RANGE
        if np.any(v < lo) or np.any(v > hi):
            raise ValueError(f"a speed profile's speeds must be within {lo}-{hi} m/s, got "
                             f"{v.tolist()}")

    @classmethod
    def constant(cls, speed: float) -> SpeedProfile:
        return cls((0.0,), (float(speed),))

    @classmethod
    def parse(cls, text: str) -> SpeedProfile:
        """The text form (module docstring); ValueError naming the bad entry."""
        times, speeds = [], []
        parts = [p.strip() for p in text.split(",")]
        if len(parts) == 1 and ":" not in parts[0]:
            parts = [f"0:{parts[0]}"]
        for p in parts:
            try:
                t, v = p.split(":")
                times.append(float(t))
                speeds.append(float(v))
            except ValueError:
                raise ValueError(f"speed profile: {p!r} is not 'time:speed' (s:m/s)") from None
        return cls(tuple(times), tuple(speeds))

    def at(self, t: float) -> float:
        """The commanded speed (m/s) at t s."""
        return float(np.interp(t, self.times, self.speeds))

    def text(self) -> str:
        """The text form, read back by :meth:`parse`."""
        return ",".join(f"{t:g}:{v:g}" for t, v in zip(self.times, self.speeds, strict=True))

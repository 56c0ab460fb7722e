"""Realtime pacing: the wall-clock slot of each tick (:class:`WallSchedule`)."""

from __future__ import annotations

import time


class WallSchedule:
    """Tick k's wall-clock slot starts at ``origin + k dt`` (``time.perf_counter`` s).

    A plant more than ``max_lag`` behind its slot moves the schedule forward by whole periods
    (the slots in between are skipped; simulation time never skips), so a plant that fell
    behind resumes pacing instead of bursting through the backlog."""

    def __init__(self, dt: float, max_lag: float, origin: float) -> None:
        self.dt, self.max_lag, self.origin = dt, max_lag, origin

    def slot(self, k: float) -> float:
        """The wall time [s] at which tick ``k`` (or a fraction of a period past it) is due."""
        return self.origin + k * self.dt

    def catch_up(self, k: int) -> tuple[float, int] | None:
        """Tick ``k`` begun a period or more late (an overrun): (its lag [s], the slots
        skipped, the schedule moved past them when the lag exceeds ``max_lag``); else None."""
        lag = time.perf_counter() - self.slot(k)
        if lag < self.dt:
            return None
        skip = int(lag // self.dt) if lag > self.max_lag else 0
        self.origin = self.origin + skip * self.dt
        return lag, skip

"""Realtime pacing: the wall-clock slot of each tick (:class:`WallSchedule`), and the plant's
own lateness in each tick (:class:`StallMeter`: the host stalls a real-time verdict names)."""

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


class StallMeter:
    """The plant's own time in each realtime tick: the tick's wall time (from one tick's
    start to the next's) less its deliberate waits (for the controller's reply, for the
    next wall slot), each counted up to its deadline only.  What is left is the plant's
    own work (the FMU, the frames, the MCAP serialization) and any time its process was not
    scheduled (a wait that ends past its deadline: the process woke late).  A tick whose own
    time reaches one period ``dt`` is a **host stall**: the plant alone could not keep its
    period.  Of a stall, the time the plant's thread ran on a CPU is measured too (the rest
    the process was not running).  Times in s (perf_counter), figures in ms."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self._start: float | None = None  # this tick's start
        self._k = -1
        self._waited = 0.0  # this tick's deliberate waits, up to their deadlines
        self._cpu0 = 0  # the thread's CPU time at the tick's start [ns]
        self.previous = 0.0  # the previous tick's own time
        self.count = 0  # host stalls (ticks)
        self.total_ms = 0.0  # their own time, summed
        #: the largest: (own time [ms], tick, of it on a CPU [ms])
        self.largest: tuple[float, int, float] = (0.0, -1, 0.0)

    def begin(self, k: int, now: float) -> None:
        """Tick ``k`` starts at ``now`` (the previous one ends there)."""
        self.end(now)
        self._k, self._start, self._waited = k, now, 0.0
        self._cpu0 = time.thread_time_ns()

    def waited(self, t0: float, t1: float, until: float) -> None:
        """A deliberate wait from ``t0`` to ``t1``, due to end at ``until``: its time up to
        ``until`` is not the plant's own."""
        self._waited += max(0.0, min(t1, until) - t0)

    def own(self, now: float) -> float:
        """This tick's own time up to ``now`` [s] (0 before the first tick)."""
        return 0.0 if self._start is None else now - self._start - self._waited

    def held_up(self, now: float) -> float:
        """The plant's own time [ms] in this tick up to ``now`` or in the previous one,
        whichever is larger, when it reached a period (a late reply now is the host's:
        the plant's loop was held up while the controller had its window); else 0."""
        own = max(self.own(now), self.previous)
        return own * 1e3 if own >= self.dt else 0.0

    def end(self, now: float) -> None:
        """The current tick ends at ``now``: its own time counted (a stall if it reached a
        period)."""
        if self._start is None:
            return
        own = self.previous = self.own(now)
        self._start = None
        if own < self.dt:
            return
        ms = own * 1e3
        self.count += 1
        self.total_ms += ms
        if ms > self.largest[0]:
            self.largest = (ms, self._k, (time.thread_time_ns() - self._cpu0) * 1e-6)

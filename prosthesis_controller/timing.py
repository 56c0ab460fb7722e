"""Bounded per-cycle duration statistics (for a node that may serve for hours) and the
process's CPU use over a stretch of work."""

from __future__ import annotations

import os
import resource
import time
from collections import deque

import numpy as np


class Durations:
    """The last ``keep`` durations (ns) of something done once per cycle, plus the count
    and total of all of them."""

    def __init__(self, keep: int = 200_000) -> None:
        self._last: deque[int] = deque(maxlen=keep)
        self.count = 0
        self.total_ns = 0

    def add(self, ns: int) -> None:
        self._last.append(ns)
        self.count += 1
        self.total_ns += ns

    def summary(self) -> dict[str, float]:
        """``n``, ``mean_us`` over all; ``median_us``, ``p99_us`` over the kept ones."""
        if not self.count:
            return {"n": 0}
        a = np.fromiter(self._last, dtype=np.int64) * 1e-3
        return {"n": self.count, "mean_us": self.total_ns / self.count * 1e-3,
                "median_us": float(np.median(a)), "p99_us": float(np.percentile(a, 99))}


class Usage:
    """CPU time and context switches of this process (all its threads) since creation."""

    def __init__(self) -> None:
        self._wall = time.perf_counter()
        self._ru = resource.getrusage(resource.RUSAGE_SELF)

    def since(self) -> dict[str, float]:
        """``wall_s``, ``cpu_s`` (user + system), ``voluntary_switches`` (blocking waits),
        ``involuntary_switches`` (preempted while runnable: CPU contention)."""
        ru, r0 = resource.getrusage(resource.RUSAGE_SELF), self._ru
        return {"wall_s": time.perf_counter() - self._wall,
                "cpu_s": ru.ru_utime - r0.ru_utime + ru.ru_stime - r0.ru_stime,
                "voluntary_switches": ru.ru_nvcsw - r0.ru_nvcsw,
                "involuntary_switches": ru.ru_nivcsw - r0.ru_nivcsw}


def pin_thread(cpu: int) -> set[int]:
    """Run the calling thread on CPU ``cpu`` only (threads it starts later, and child
    processes, inherit this); returns the CPUs it was allowed before. Raises ValueError
    for a CPU this machine does not let it use."""
    before = os.sched_getaffinity(0)
    try:
        os.sched_setaffinity(0, {int(cpu)})
    except (OSError, OverflowError) as e:
        raise ValueError(f"cannot run on CPU {cpu}: {getattr(e, 'strerror', e)}") from None
    return before

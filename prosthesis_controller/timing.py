"""Bounded per-cycle duration statistics (for a loop that may run for hours: memory that
does not grow with the number of cycles) and the process's CPU use over a stretch of work.

:class:`Tally` keeps the count, total and largest of a quantity; :class:`Histogram` also its
distribution, binned with a relative resolution of ``2**-(SUB_BITS - 1)`` (values below
``2**SUB_BITS`` exactly): a percentile from it is within half a bin, 0.1 % of the value, of
the one ``numpy.percentile`` gives over every value (:meth:`Histogram.percentile`)."""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterable

#: significant bits a :class:`Histogram` bin keeps (a bin's width is at most 1/512 of its
#: values: 512 bins per octave; values below 1024 have one bin each)
SUB_BITS = 10


class Tally:
    """Count, total and largest of non-negative integers (e.g. durations in ns), in
    constant memory."""

    __slots__ = ("count", "largest", "total")

    def __init__(self, values: Iterable[int] = ()) -> None:
        self.count = 0
        self.total = 0
        self.largest = 0
        for v in values:
            self.add(v)

    def add(self, v: int) -> None:
        self.count += 1
        self.total += v
        if v > self.largest:
            self.largest = v

    @property
    def mean(self) -> float:
        """The mean (0.0 without values)."""
        return self.total / self.count if self.count else 0.0


def _bin(v: int) -> int:
    """The :class:`Histogram` bin of ``v`` >= 0: ``v`` itself below ``2**SUB_BITS``, else
    (shift, the top ``SUB_BITS`` bits) packed into one int, increasing with ``v``."""
    shift = v.bit_length() - SUB_BITS
    if shift <= 0:
        return v
    return (shift << SUB_BITS) | (v >> shift)


def _bin_value(b: int) -> float:
    """The value a bin stands for: the middle of the integers it holds."""
    shift = b >> SUB_BITS
    if shift == 0:
        return float(b)
    low = (b & ((1 << SUB_BITS) - 1)) << shift
    return low + ((1 << shift) - 1) / 2


class Histogram(Tally):
    """A :class:`Tally` with the distribution of the values, in bins of relative width at
    most 2**-9 (module docstring): at most 512 bins per octave the values span (durations
    spread over a decade: at most about 1700), whatever the count (``len(h.bins)``)."""

    __slots__ = ("bins", "smallest")

    def __init__(self, values: Iterable[int] = ()) -> None:
        self.bins: dict[int, int] = {}
        self.smallest = 0
        super().__init__(values)

    def add(self, v: int) -> None:  # Tally.add and _bin inlined: once per cycle
        if v < self.smallest or not self.count:
            self.smallest = v
        self.count += 1
        self.total += v
        if v > self.largest:
            self.largest = v
        shift = v.bit_length() - SUB_BITS
        b = v if shift <= 0 else (shift << SUB_BITS) | (v >> shift)
        bins = self.bins
        bins[b] = bins.get(b, 0) + 1

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100) as ``numpy.percentile`` (linear interpolation
        between the two order statistics around rank ``q/100 (n - 1)``) computes it from
        the values, each order statistic taken as its bin's middle (the smallest and the
        largest exactly): within 0.1 % of the exact figure. 0.0 without values."""
        n = self.count
        if not n:
            return 0.0
        rank = q / 100 * (n - 1)
        lo = int(rank)
        hi = min(lo + 1, n - 1)
        a, b = self._order_statistic(lo), self._order_statistic(hi)
        return a + (b - a) * (rank - lo)

    def _order_statistic(self, i: int) -> float:
        """The ``i``-th smallest value (0-based), as its bin's middle."""
        if i <= 0:
            return float(self.smallest)
        if i >= self.count - 1:
            return float(self.largest)
        seen = 0
        for b in sorted(self.bins):
            seen += self.bins[b]
            if seen > i:
                return min(max(_bin_value(b), self.smallest), self.largest)
        return float(self.largest)  # pragma: no cover  (counts add up to count)


class Durations:
    """Durations (ns) of something done once per cycle, all of them in a
    :class:`Histogram` (bounded: a node may serve for hours)."""

    def __init__(self) -> None:
        self.hist = Histogram()

    @property
    def count(self) -> int:
        return self.hist.count

    def add(self, ns: int) -> None:
        self.hist.add(ns)

    def summary(self) -> dict[str, float]:
        """``n``, ``mean_us``; ``median_us``, ``p99_us`` (within 0.1 %: :class:`Histogram`)
        over all of them."""
        h = self.hist
        if not h.count:
            return {"n": 0}
        return {"n": h.count, "mean_us": h.mean * 1e-3, "median_us": h.percentile(50) * 1e-3,
                "p99_us": h.percentile(99) * 1e-3}


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

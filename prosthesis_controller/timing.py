"""Bounded per-cycle duration statistics (for a node that may serve for hours)."""

from __future__ import annotations

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

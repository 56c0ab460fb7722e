"""CAN frame rates of a recording: :class:`CanRates` counts the ``hpcosim.CanFrame``
records written and gives a ``/can/rates`` record (frames per second by direction and
frame name) for every window of log time."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


class CanRates:
    """Counts the CAN frames written and gives the ``/can/rates`` record of each window of
    ``period`` s of log time (the first starts at the first frame)."""

    def __init__(self, period: float = 0.1) -> None:
        if not period > 0:
            raise ValueError(f"CAN rate window {period} s: must be > 0")
        self.period = period
        self._period_ns = round(period * 1e9)
        self._end: int | None = None
        self._counts: dict[str, dict[str, int]] = {"tx": {}, "rx": {}}

    def add(self, message: Mapping[str, Any], ns: int) -> list[tuple[int, dict[str, Any]]]:
        """Count one ``hpcosim.CanFrame`` record logged at ``ns``; returns (log time [ns],
        record) of every window that ended before it."""
        out = []
        if self._end is None:
            self._end = ns + self._period_ns
        while ns >= self._end:
            out.append((self._end, self._close()))
            self._end += self._period_ns
        name = message.get("name") or f"0x{int(message['id']):03X}"
        c = self._counts[message["direction"]]
        c[name] = c.get(name, 0) + 1
        return out

    def _close(self) -> dict[str, Any]:
        assert self._end is not None
        rec: dict[str, Any] = {"t": self._end * 1e-9, "window": self.period}
        for d, c in self._counts.items():
            rec[d] = {n: k / self.period for n, k in c.items()}
            self._counts[d] = dict.fromkeys(c, 0)
        return rec

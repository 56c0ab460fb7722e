"""When the plant stops trusting the controller: the plant's watchdog over the controller's
replies (:class:`ReplyWatchdog`).

A run faults when the controller's liveliness token is lost, when ``periods`` periods in a
row pass without this cycle's torque reply, when the first reply does not come within
``reply_timeout`` of the start (before the watchdog is armed), or when the controller's
heartbeat reports SAFE or FAULT in a period it did not answer.  A SAFE heard right after
the plant's own silence (longer than the node's watchdog: a stall, a descheduled plant) is
the node's answer to that silence, not its fault: it is excused for ``periods`` ticks."""

from __future__ import annotations

import threading
import time

from bus_schemas.transport.protocol import CtrlState


class ReplyWatchdog:
    """The plant's watchdog over one run's controller (module docstring). ``armed``: the
    missed-reply count runs from the first period (lockstep); else from the first reply
    (realtime: a process scheduled late at its start, measured up to 10 ms on a loaded
    2-core machine, is not a dead controller); times in s, ``start`` a perf_counter."""

    def __init__(self, *, periods: int, reply_timeout: float, node_watchdog: float,
                 armed: bool, start: float) -> None:
        self.periods, self.reply_timeout, self.node_watchdog = (periods, reply_timeout,
                                                                node_watchdog)
        self.armed, self.start = armed, start
        self.missed_run = 0  # periods in a row without a reply (once armed)
        self.first_miss = -1  # the first tick of the current silence (-1: none)
        self.safe_excused_until = 0  # a SAFE heartbeat before this tick is excused
        self._sent_ns: int | None = None  # the last cycle's send [perf_counter_ns]

    def sent(self, k: int, now_ns: int) -> None:
        """Tick ``k``'s frames went out at ``now_ns``: a plant silent for longer than the
        node's own watchdog put the node in SAFE itself; the node resumes with this cycle,
        so that SAFE is excused for ``periods`` ticks (a controller that does not come back
        is then caught by the missed replies or by its SAFE state, as any other)."""
        if self._sent_ns is not None and (now_ns - self._sent_ns) * 1e-9 > self.node_watchdog:
            self.safe_excused_until = k + self.periods
        self._sent_ns = now_ns

    def replied(self) -> None:
        """This cycle's reply came: the silence ends, the watchdog is armed."""
        self.missed_run, self.first_miss, self.armed = 0, -1, True

    def answered_late(self) -> None:
        """Realtime: a reply to an earlier tick came: the controller is alive but behind
        (counted late, not missing: the watchdog is for silence)."""
        self.missed_run, self.first_miss = 0, -1

    def missed(self, k: int) -> None:
        """No reply in tick ``k``."""
        if self.armed:
            self.missed_run += 1
        if self.first_miss < 0:
            self.first_miss = k

    def fault(self, k: int, got: bool, ctrl_state: int | None, lost: threading.Event) -> str:
        """Why the plant stops trusting the controller in tick ``k`` ("" while it does);
        ``got``: this cycle's reply came; ``ctrl_state``: the last heartbeat's state."""
        if lost.is_set():
            return "controller liveliness token lost"
        if self.missed_run >= self.periods:
            return f"{self.missed_run} control periods without a torque reply"
        if not self.armed and time.perf_counter() - self.start > self.reply_timeout:
            return (f"no torque reply within {self.reply_timeout} s of the start "
                    f"({k + 1} periods)")
        if ctrl_state in (CtrlState.SAFE, CtrlState.FAULT) and k > 0 and not got and not (
                ctrl_state == CtrlState.SAFE and k < self.safe_excused_until):
            return f"controller reports state {CtrlState(ctrl_state).name}"
        return ""

    def detection_periods(self, k: int) -> int:
        """Periods from the first unanswered one to the fault in tick ``k``."""
        return k - (self.first_miss if self.first_miss >= 0 else k) + 1

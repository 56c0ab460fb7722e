"""When the plant stops trusting the controller: the plant's watchdog over the controller's
replies (:class:`ReplyWatchdog`).

A run faults when the controller's liveliness token is lost, when ``periods`` periods in a
row pass without this cycle's torque reply, when the first reply does not come within
``reply_timeout`` of the start (before the watchdog is armed), or when the controller's
heartbeat reports SAFE or FAULT in a period it did not answer.  A SAFE heard right after
the plant's own silence (longer than the node's watchdog: a stall, a descheduled plant) is
the node's answer to that silence, not its fault: it is excused for ``periods`` ticks.

Who was late (:attr:`ReplyWatchdog.cause`): a silence whose periods mostly went unanswered
while the plant's own loop was held up a period or more (a host stall, measured by the
link: :class:`orchestrator.cosim.schedule.StallMeter`) is the host's; otherwise the
controller missed its deadline although the plant was on time."""

from __future__ import annotations

import threading
import time

from bus_schemas.transport.protocol import CtrlState
from orchestrator.cosim.result import FaultCause


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
        #: the current silence: its periods, those the host's (the plant held up), and the
        #: largest such stall (ms, tick)
        self.silent = self.silent_host = 0
        self.silent_stall: tuple[float, int] = (0.0, -1)
        self.cause = FaultCause.NONE  # who the fault is due to, once there is one
        self.verdict = ""  # the same in words (with the stall in ms)

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
        self.answered_late()
        self.armed = True

    def answered_late(self) -> None:
        """Realtime: a reply to an earlier tick came: the controller is alive but behind
        (counted late, not missing: the watchdog is for silence)."""
        self.missed_run, self.first_miss = 0, -1
        self.silent = self.silent_host = 0
        self.silent_stall = (0.0, -1)

    def missed(self, k: int, stall_ms: float = 0.0) -> None:
        """No reply in tick ``k``; ``stall_ms`` > 0: the plant's own loop was held up that
        long meanwhile (the host's period, :meth:`_silence`)."""
        if self.armed:
            self.missed_run += 1
        if self.first_miss < 0:
            self.first_miss = k
        self.silent += 1
        if stall_ms > 0:
            self.silent_host += 1
            if stall_ms > self.silent_stall[0]:
                self.silent_stall = (stall_ms, k)

    def fault(self, k: int, got: bool, ctrl_state: int | None, lost: threading.Event) -> str:
        """Why the plant stops trusting the controller in tick ``k`` ("" while it does);
        ``got``: this cycle's reply came; ``ctrl_state``: the last heartbeat's state.  Who
        was late: :attr:`cause` and, in words, :attr:`verdict` (:meth:`_silence`)."""
        if lost.is_set():
            return self._controller("controller liveliness token lost")
        if self.missed_run >= self.periods:
            return self._silence(f"{self.missed_run} control periods without a torque reply")
        if not self.armed and time.perf_counter() - self.start > self.reply_timeout:
            return self._silence(f"no torque reply within {self.reply_timeout} s of the start "
                                 f"({k + 1} periods)")
        if ctrl_state in (CtrlState.SAFE, CtrlState.FAULT) and k > 0 and not got and not (
                ctrl_state == CtrlState.SAFE and k < self.safe_excused_until):
            return self._controller(f"controller reports state {CtrlState(ctrl_state).name}")
        return ""

    def _controller(self, reason: str) -> str:
        self.cause, self.verdict = FaultCause.CONTROLLER, "the controller failed"
        return reason

    def _silence(self, reason: str) -> str:
        """``reason``; who was late: the host when most periods of the silence went
        unanswered while the plant itself was held up (the largest stall, in ms); else the
        controller missed its deadline although the plant was on time."""
        ms, k = self.silent_stall
        if 2 * self.silent_host > self.silent:
            self.cause = FaultCause.HOST
            self.verdict = (f"the host stalled: the plant's own loop was held up {ms:.1f} ms at "
                            f"tick {k} ({self.silent_host} of the {self.silent} silent periods)")
        else:
            self.cause = FaultCause.CONTROLLER
            self.verdict = (f"the controller missed its deadline ({self.silent - self.silent_host}"
                            f" of the {self.silent} silent periods with the plant on time)")
        return reason

    def detection_periods(self, k: int) -> int:
        """Periods from the first unanswered one to the fault in tick ``k``."""
        return k - (self.first_miss if self.first_miss >= 0 else k) + 1

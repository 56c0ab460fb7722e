"""What a co-simulation run reports (:class:`CosimResult`, ``hpcosim run``'s table and the
recording's ``summary``) and the timing figures in it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from hp_model.choices import Choice
from hp_model.falls import FallReason
from orchestrator.loop import LoopLog
from prosthesis_controller.timing import Histogram, Tally


class FaultCause(Choice):
    """Who a faulted run's fault is due to (:attr:`CosimResult.fault_cause`)."""

    NONE = "none"  # no fault
    HOST = "host"  # the plant's own loop was held up (a host stall) while the replies missed
    CONTROLLER = "controller"  # it missed its deadline with the plant on time, died, or failed


@dataclass
class CosimResult:
    ticks: int = 0
    sim_time: float = 0.0
    steps: int = 0
    fell: bool = False
    fall_code: int = 0
    faulted: bool = False
    fault_reason: str = ""
    #: who was late (orchestrator.cosim.watchdog): host or controller, and in words (the
    #: host's stall in ms, or the silent periods with the plant on time)
    fault_cause: FaultCause = FaultCause.NONE
    fault_verdict: str = ""
    detection_periods: int = 0  # periods from the first unanswered one to the fault
    wall_time: float = 0.0
    late: int = 0
    missed: int = 0
    frames_tx: int = 0
    frames_rx: int = 0
    plant_rejects: dict[str, int] = field(default_factory=dict)
    ctrl_rejects: dict[str, int] = field(default_factory=dict)
    injected: dict[str, int] = field(default_factory=dict)
    latency_us: dict[str, float] = field(default_factory=dict)
    timing_us: dict[str, float] = field(default_factory=dict)
    node: dict[str, Any] = field(default_factory=dict)  # the controller node's summary
    usage: dict[str, float] = field(default_factory=dict)  # plant process over the loop
    reply_early: float = 0.0  # see reply_early_share
    torque_clamped: int = 0  # torque commands the plant clamped to the device's limits
    overruns: int = 0  # realtime: ticks the plant began a period or more behind its slot
    skipped_slots: int = 0  # realtime: wall-clock slots skipped to catch up (max_lag)
    max_lag_ms: float = 0.0  # realtime: the plant's largest lag behind its schedule
    #: realtime: ticks whose own time (wall time less the waits for the reply and the slot,
    #: up to their deadlines: orchestrator.cosim.schedule.StallMeter) reached a period: the
    #: plant's loop held up (not scheduled, or its own work); the largest [ms], its tick, and
    #: of it the time on a CPU [ms] (the rest the plant's process was not running)
    host_stalls: int = 0
    host_stall_ms: float = 0.0
    host_stall_tick: int = -1
    host_stall_cpu_ms: float = 0.0
    #: realtime: ``late`` split: while the plant's own loop was held up a period or more in
    #: the tick or the one before (the host's), or although the plant was on time
    late_host: int = 0
    late_controller: int = 0
    interrupted: str = ""  # the signal (SIGINT, SIGTERM) that ended the run early
    record: str | None = None
    run_id: str = ""

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else 0.0

    @property
    def fall_reason(self) -> str:
        """The fall's :class:`hp_model.falls.FallReason` label ("" without a fall)."""
        if not self.fell:
            return ""
        try:
            return FallReason(self.fall_code).label
        except ValueError:  # an FMU with codes of its own
            return f"code-{self.fall_code}"

    def take_loop(self, log: LoopLog, dt: float) -> None:
        """How the loop ended (:func:`orchestrator.loop.run_loop`'s log; period ``dt`` s)."""
        self.steps = log.steps
        if log.fall is not None:
            self.fell, self.fall_code = True, log.fall.code
        if log.fault:
            self.faulted, self.fault_reason = True, log.fault
        self.ticks = log.periods
        self.sim_time = log.periods * dt

    def to_dict(self) -> dict[str, Any]:
        """The summary as the recording stores it (with the derived figures)."""
        d = asdict(self)
        d["real_time_factor"] = self.real_time_factor
        d["fall_reason"] = self.fall_reason
        return d


#: a wait shorter than this [ns]: the reply was already in (:func:`reply_early_share`)
EARLY_NS = 20_000


@dataclass
class ReplyTimes:
    """Per answered tick [ns], in constant memory (a run may last hours): send -> this
    cycle's reply in hand (``round_trip``: its distribution, for the latency percentiles),
    MCAP serialization inside it (``record``: every tick of a recorded run), blocked waiting
    after the serialization (``wait``; ``early``: waits under :data:`EARLY_NS`)."""

    round_trip: Histogram = field(default_factory=Histogram)
    record: Tally = field(default_factory=Tally)
    wait: Tally = field(default_factory=Tally)
    early: int = 0

    def replied(self, round_trip_ns: int, wait_ns: int) -> None:
        """This cycle's reply in hand ``round_trip_ns`` after the send, after waiting
        ``wait_ns``."""
        self.round_trip.add(round_trip_ns)
        self.wait.add(wait_ns)
        if wait_ns < EARLY_NS:
            self.early += 1

    def latency_us(self) -> dict[str, float]:
        """Median, 99th percentile (within 0.1 %: :class:`Histogram`) and largest round trip
        [us], and their number ({} if no reply came)."""
        h = self.round_trip
        if not h.count:
            return {}
        return {"median": h.percentile(50) * 1e-3, "p99": h.percentile(99) * 1e-3,
                "max": h.largest * 1e-3, "n": h.count}

    def early_share(self) -> float:
        """:func:`reply_early_share` of the waits."""
        return self.early / max(1, self.wait.count)


def tick_breakdown(tick: Tally | Sequence[int], fmu: Tally | Sequence[int],
                   rt: Tally | Sequence[int], rec: Tally | Sequence[int],
                   wait: Tally | Sequence[int]) -> dict[str, float]:
    """Mean per tick [us] of the whole tick, the FMU calls, the round trip (send -> this
    cycle's reply in hand: zenoh both ways, the node's frame handling and controller tick,
    and the plant's MCAP serialization done meanwhile), and the overhead beyond FMU + round
    trip (FMU-output encoding, frame checks, queuing records); ``record``: serialization
    inside the round trip (it stops once a controller frame is here: ``MAX_BACKLOG``);
    ``wait``: polling or blocked after it, and the reply's frame checks (see
    :func:`reply_early_share`).  Each argument: a :class:`Tally` of ns per tick (or the
    values)."""
    t, f, r, c, w = (x if isinstance(x, Tally) else Tally(x) for x in (tick, fmu, rt, rec,
                                                                         wait))
    n = max(1, t.count)
    out = {"tick": t.mean * 1e-3, "fmu": f.total / n * 1e-3, "round_trip": r.mean * 1e-3,
           "record": c.mean * 1e-3, "wait": w.mean * 1e-3}
    out["overhead"] = out["tick"] - out["fmu"] - r.total / n * 1e-3
    return out


def reply_early_share(wait: Sequence[int], threshold_ns: int = EARLY_NS) -> float:
    """Share of ticks whose reply was already in when the plant finished serializing
    (blocked less than ``threshold_ns``): for those the round trip figure is the
    serialization time, an upper bound of the real round trip."""
    return sum(1 for w in wait if w < threshold_ns) / max(1, len(wait))

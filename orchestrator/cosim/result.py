"""What a co-simulation run reports (:class:`CosimResult`, ``hpcosim run``'s table and the
recording's ``summary``) and the timing figures in it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from hp_model.falls import FallReason
from orchestrator.loop import LoopLog


@dataclass
class CosimResult:
    ticks: int = 0
    sim_time: float = 0.0
    steps: int = 0
    fell: bool = False
    fall_code: int = 0
    faulted: bool = False
    fault_reason: str = ""
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


@dataclass
class ReplyTimes:
    """Per answered tick [ns]: send -> this cycle's reply in hand (``round_trip``), MCAP
    serialization inside it (``record``: every tick of a recorded run), blocked waiting
    after the serialization (``wait``)."""

    round_trip: list[int] = field(default_factory=list)
    record: list[int] = field(default_factory=list)
    wait: list[int] = field(default_factory=list)

    def latency_us(self) -> dict[str, float]:
        """Median, 99th percentile and largest round trip [us], and their number ({} if
        no reply came)."""
        if not self.round_trip:
            return {}
        a = [x * 1e-3 for x in self.round_trip]
        return {"median": _pct(a, 50), "p99": _pct(a, 99), "max": max(a), "n": len(a)}


def tick_breakdown(tick: list[int], fmu: list[int], rt: list[int], rec: list[int],
                   wait: list[int]) -> dict[str, float]:
    """Mean per tick [us] of the whole tick, the FMU calls, the round trip (send -> this
    cycle's reply in hand: zenoh both ways, the node's frame handling and controller tick,
    and the plant's MCAP serialization done meanwhile), and the overhead beyond FMU + round
    trip (FMU-output encoding, frame checks, queuing records); ``record``: serialization
    inside the round trip (it stops once a controller frame is here: ``MAX_BACKLOG``);
    ``wait``: polling or blocked after it, and the reply's frame checks (see
    :func:`reply_early_share`)."""
    n = max(1, len(tick))

    def mean(a: list[int], over: int | None = None) -> float:
        return sum(a) / (over or max(1, len(a))) * 1e-3

    out = {"tick": mean(tick), "fmu": mean(fmu, n), "round_trip": mean(rt),
           "record": mean(rec), "wait": mean(wait)}
    out["overhead"] = out["tick"] - out["fmu"] - sum(rt) / n * 1e-3
    return out


def reply_early_share(wait: list[int], threshold_ns: int = 20_000) -> float:
    """Share of ticks whose reply was already in when the plant finished serializing
    (blocked less than ``threshold_ns``): for those the round trip figure is the
    serialization time, an upper bound of the real round trip."""
    return sum(1 for w in wait if w < threshold_ns) / max(1, len(wait))


def _pct(a: list[float], q: float) -> float:
    return float(np.percentile(a, q)) if a else 0.0

"""The one closed loop: a plant, a link, an optional recorder, wired once.

Per period k (t = k dt):

1. ``obs = plant.observe()``; a plant that holds the previous period's state after ending
   the walk (``obs.held``) has nothing new: the loop ends without a sample;
2. ``cmd = link.exchange(obs)`` (the controller's torque for the period);
3. ``truth = plant.actuate(cmd.torque)``; the sample (obs, cmd, truth) is logged and
   recorded;
4. the loop ends on a fall (``plant.fall``), a link fault, ``steps`` impacts, ``periods``
   periods, or ``stop``; else ``plant.advance()`` and ``link.pace(k)``.

A link that sends before it waits (``link.idle_after_send``: the co-simulation's CAN link
in lockstep) gets the loop's bookkeeping into its wait: ``link.exchange(obs, idle)`` calls
``idle()`` once, after the period's frames went out and before it waits for the reply, and
its Command may be provisional (``V``/``rho`` not read yet: ``link.settle(cmd)`` completes
it).  The loop logs and records period k's sample there, in period k + 1's ``idle`` (or
after the last period): the same samples, recorded in the same order (a recorder's queue
sees period k's records before anything the link queues after period k + 1's send); a
plant with ``read_truth`` (the FMU: its state) reads what the period's truth needs beyond
the observation there too, else in ``actuate``.

The experiments, the sweeps (both backends) and the co-simulation all run through
:func:`run_loop`; the order above is :meth:`hp_model.simulator.HybridSimulator.run`'s, so
every plant logs the same samples.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, TypedDict, TypeGuard, Unpack

from hp_model.domains import Domain
from hp_model.falls import Fall
from orchestrator.loop.link import Command, LateLink, Link
from orchestrator.loop.plant import Observation, Plant, Truth, Vector
from prosthesis_controller.interface import ControllerMode
from prosthesis_controller.timing import Tally


class Recorder(Protocol):
    def record(self, obs: Observation, cmd: Command, truth: Truth) -> None: ...


@dataclass
class LoopLog:
    """Per-period samples of one run and how it ended."""

    t: list[float] = field(default_factory=list)
    tau: list[float] = field(default_factory=list)
    domain: list[int] = field(default_factory=list)  # 0 ps, 1 pns
    q: list[Vector] = field(default_factory=list)  # (12,) ground truth
    qd: list[Vector] = field(default_factory=list)
    torque: list[Vector] = field(default_factory=list)  # (2,) motor torques applied
    socket_force: list[Vector] = field(default_factory=list)  # (3,)
    mode: list[ControllerMode | str] = field(default_factory=list)
    V: list[float | None] = field(default_factory=list)  # None: the link reported none
    rho: list[float | None] = field(default_factory=list)
    fallback_count: int = 0
    steps: int = 0
    fall: Fall | None = None
    fault: str = ""  # the link's failure that ended the run
    #: periods run (counted by :func:`run_loop`, also when it keeps no samples)
    count: int = 0
    #: per period (ns), when ``timed``: the plant's calls, the link's exchange, whole tick;
    #: count, total and largest only (constant memory: a run may last hours)
    plant_ns: Tally = field(default_factory=Tally)
    link_ns: Tally = field(default_factory=Tally)
    tick_ns: Tally = field(default_factory=Tally)

    @property
    def periods(self) -> int:
        """Periods run (a log filled by :meth:`add` alone: its samples)."""
        return max(self.count, len(self.t))

    def add(self, obs: Observation, cmd: Command, truth: Truth) -> None:
        self.t.append(obs.t)
        self.tau.append(obs.tau)
        self.domain.append(Domain(obs.domain).code)
        self.q.append(truth.q)
        self.qd.append(truth.qd)
        self.torque.append(truth.torque if cmd.torque is None else cmd.torque)
        self.socket_force.append(truth.socket_force)
        self.mode.append(cmd.mode)
        self.V.append(cmd.V)
        self.rho.append(cmd.rho)
        self.fallback_count = cmd.fallback_count


class LoopOptions(TypedDict, total=False):
    """:func:`run_loop`'s optional keywords (each absent: its default)."""

    periods: int | None  # end after this many periods (default None: no limit)
    recorder: Recorder | None  # records each period's sample
    stop: threading.Event | None  # set (from another thread): end after the period
    progress: Callable[[int, float, int], None] | None  # (k, t, steps) every 100 periods
    timed: bool  # default False; True: per-period timings (their tallies) in the log
    samples: bool  # default True; False: only the counts and how the run ended (the log's
    #  memory then does not grow with the periods: a co-simulation's recorder keeps them)


def _sends_first(link: Link) -> TypeGuard[LateLink]:
    """Whether ``link`` sends before it waits (``idle_after_send``: a :class:`LateLink`)."""
    return bool(getattr(link, "idle_after_send", False))


class _LateSamples:
    """A :class:`LateLink`'s samples: period k's kept (``keep``: logged, recorded) in
    period k + 1's ``idle``, once the link settled its Command, or at the end."""

    def __init__(self, link: LateLink, keep: Callable[[Observation, Command, Truth], None],
                 read_truth: Callable[[], None] | None) -> None:
        self.link, self.keep, self.read_truth = link, keep, read_truth
        self.last: tuple[Observation, Command, Truth] | None = None  # not yet kept

    def exchange(self, obs: Observation) -> Command:
        return self.link.exchange(obs, self.idle)

    def hold(self, obs: Observation, cmd: Command, truth: Truth) -> None:
        self.last = (obs, cmd, truth)

    def settle(self) -> None:
        """Keep the last period's sample (in the next period's wait, or at the end)."""
        if self.last is None:
            return
        o, c, tr = self.last
        self.last = None
        self.keep(o, self.link.settle(c), tr)

    def idle(self) -> None:
        """While the controller works: the last period's sample, this period's truth."""
        self.settle()
        if self.read_truth is not None:
            self.read_truth()


def _keeper(log: LoopLog, recorder: Recorder | None, samples: bool
            ) -> Callable[[Observation, Command, Truth], None]:
    """What keeps a period's sample: the log (``samples``) and the recorder."""

    def keep(obs: Observation, cmd: Command, truth: Truth) -> None:
        if samples:
            log.add(obs, cmd, truth)
        if recorder is not None:
            recorder.record(obs, cmd, truth)

    return keep


def run_loop(plant: Plant, link: Link, *, steps: int,
             **options: Unpack[LoopOptions]) -> LoopLog:
    """Run the closed loop (module docstring) until a fall, a link fault, ``steps``
    impacts, ``periods`` periods or ``stop``; ``progress(k, t, steps)`` every 100
    periods; ``timed``: per-period timings in the log; ``samples``: keep the per-period
    samples (False: only the counts and how the run ended, e.g. when a recorder keeps
    them). The options: :class:`LoopOptions`."""
    periods, stop = options.get("periods"), options.get("stop")
    progress, timed = options.get("progress"), options.get("timed", False)
    samples = options.get("samples", True)
    log = LoopLog()
    clock = time.perf_counter_ns
    k = 0
    keep = _keeper(log, options.get("recorder"), samples)
    exchange: Callable[[Observation], Command] = link.exchange
    after = keep  # what takes the period's sample after the actuation
    finish: Callable[[], None] | None = None  # what the run's end does with the last sample
    if _sends_first(link):
        late = _LateSamples(link, keep, getattr(plant, "read_truth", None))
        exchange, after, finish = late.exchange, late.hold, late.settle
    try:
        while stop is None or not stop.is_set():
            t0 = clock()
            obs = plant.observe()
            t1 = clock()
            if obs.held:
                break
            cmd = exchange(obs)
            t2 = clock()
            truth = plant.actuate(cmd.torque)
            log.count += 1
            after(obs, cmd, truth)
            log.steps = obs.steps
            t3 = clock()
            if cmd.fault:
                log.fault = cmd.fault
            done = (plant.fall is not None or bool(cmd.fault) or obs.steps >= steps
                    or (periods is not None and k + 1 >= periods))
            if not done:
                plant.advance()
            t4 = clock()
            if timed:
                log.plant_ns.add((t1 - t0) + (t4 - t3) + (t3 - t2))
                log.link_ns.add(t2 - t1)
                log.tick_ns.add(t4 - t0)
            if done:
                break
            k += 1
            link.pace(k)
            if progress is not None and k % 100 == 0:
                progress(k, obs.t, obs.steps)
    finally:
        if finish is not None:
            finish()
    log.fall = plant.fall
    return log

"""Co-simulation master (:func:`run_cosim`, behind ``hpcosim run``): the human FMU on the plant
side, the prosthesis controller in its own process, CAN frames (AMPRO3 protocol) over zenoh
between them, MCAP recording.

The run puts together its parts, each a module of this package:

    config              CosimConfig (what ``hpcosim run`` sets), CosimError
    inputs              the model, gait, tube, FMU file and drives, loaded and checked (a
                        gait library's run: the speed commanded, the gaits scheduled)
    faults              the fault plan (``--perturb``) and its cases (PerturbCase)
    human               the FMU file (cached build) and its instance for the run
    cpus                the CPU of each process (lockstep), polling before blocking
    controller_process  the controller node: spawn, run secret, liveliness, shutdown
    can_link            CanLink: the frames each tick, the reply, the watchdog's verdict
    run_record          the MCAP recording: metadata, attachments, deferred ground truth
    result              CosimResult and its timing figures

and :func:`orchestrator.loop.run_loop` runs the tick loop of the FMU plant and the CAN link:
per tick k (t = k dt, dt = 1 ms by default) the plant reads the FMU's outputs, the link
sends the drives' frames and waits for the torque answering them
(:mod:`orchestrator.cosim.can_link`), the plant sets the torque, records ground truth and
steps the FMU by dt.

Fault handling: a missing reply holds the last torque; ``watchdog_periods`` (5) missed
replies in a row, the controller's liveliness token disappearing, or its heartbeat reporting
SAFE/FAULT make the plant apply the safe torque (zero) and end the run as *faulted*
(:mod:`orchestrator.cosim.watchdog`). The recording is always finished (also on
SIGTERM/SIGINT), except that a run failing before its first tick leaves none.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

from bus_schemas.transport import keys
from orchestrator.cosim.can_link import CanLink
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.controller_process import ControllerProcess
from orchestrator.cosim.cpus import cpu_plan, pinned
from orchestrator.cosim.faults import FaultPlan
from orchestrator.cosim.human import started_fmu
from orchestrator.cosim.inputs import RunInputs
from orchestrator.cosim.result import CosimResult
from orchestrator.cosim.run_record import RunRecord
from orchestrator.loop import FmuPlant, run_loop
from prosthesis_controller.timing import Usage

Progress = Callable[[int, float, int], None]


def run_cosim(cfg: CosimConfig, *, progress: Progress | None = None, model: Any = None,
              say: Callable[[str], None] | None = None,
              install_signal_handlers: bool = False) -> CosimResult:
    """Run one co-simulation (module docstring). Returns the summary; the recording (if any)
    is complete and readable whatever happens once the first tick began; a run that fails
    before it leaves no recording (:class:`RunRecord`). ``model``: the model of
    ``cfg.subject`` and ``cfg.device``, if already built; ``progress(k, t, steps)`` every
    100 ticks; ``say``: what the run is doing, in words; ``install_signal_handlers``:
    SIGINT and SIGTERM end the run early (:attr:`CosimResult.interrupted`) instead of the
    process."""
    say = say or (lambda _m: None)
    plan = FaultPlan.parse(cfg.perturb)
    inputs = RunInputs.load(cfg, model, say)
    run_id = cfg.run_id or f"run-{os.getpid()}-{time.monotonic_ns() % 10**9}"
    keys.validate_run_id(run_id)
    res = CosimResult(run_id=run_id)
    stop = threading.Event()  # a signal asked the run to end
    plant_cpu, node_cpu = cpu_plan(cfg)
    with contextlib.ExitStack() as run:  # everything ended in the reverse order
        if install_signal_handlers:
            run.enter_context(_stop_on_signals(res, stop))
        fmu = run.enter_context(started_fmu(inputs.fmu_path, plan, inputs.walk_start()))
        record = (None if cfg.record is None
                  else run.enter_context(RunRecord(cfg, run_id, inputs, fmu, res)))
        run.enter_context(pinned(plant_cpu))  # before the bus: zenoh's threads inherit it
        controller = run.enter_context(
            ControllerProcess(cfg, run_id, cpu=node_cpu, summary=res.node,
                              tables=inputs.tables, speed=inputs.start_speed))
        if controller.open(stop, say):
            say("controller alive")
            link = CanLink(cfg, controller.bus, res, inputs.drives, plan=plan,
                           rec=None if record is None else record.rec, controller=controller)
            _walk(cfg, link, FmuPlant(fmu, cfg.dt, gaits=inputs.gaits()), record, stop,
                  progress)
    return res


def _walk(cfg: CosimConfig, link: CanLink, plant: FmuPlant, record: RunRecord | None,
          stop: threading.Event, progress: Progress | None) -> None:
    """The tick loop: :func:`orchestrator.loop.run_loop` of the FMU plant and the CAN link
    (ground truth and the walker for Foxglove recorded, deferred, with a recording), and
    the run's result from it."""
    usage = Usage()
    log = run_loop(plant, link, steps=cfg.steps,
                   periods=round(cfg.max_time / cfg.dt), stop=stop, progress=progress,
                   recorder=None if record is None else record.ground_truth(link.log_ns),
                   timed=True, samples=False)
    link.res.take_loop(log, cfg.dt)
    link.report(log)
    link.res.usage = usage.since()


@contextlib.contextmanager
def _stop_on_signals(res: CosimResult, stop: threading.Event) -> Iterator[None]:
    """SIGINT and SIGTERM set ``stop`` (the loop ends at the next tick) and name themselves
    in ``res.interrupted``; the previous handlers are back when the block ends."""
    def on_signal(signum: int, _frame: Any) -> None:  # a flag only: the loop ends
        res.interrupted = signal.Signals(signum).name
        stop.set()

    old = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)

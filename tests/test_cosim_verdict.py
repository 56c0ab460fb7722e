"""A real-time run's verdict says who was late (issue 39): the plant's own loop held up (a
host stall, measured in ms: :class:`orchestrator.cosim.schedule.StallMeter`) or the
controller that missed its deadline although the plant was on time."""

from __future__ import annotations

import math
import os
import threading
import time
from pathlib import Path

import can
import pytest

from bus_schemas.transport import codec
from hp_model.force_tube import save_tube
from orchestrator.cosim.can_link import CanLink
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.drives import Drives
from orchestrator.cosim.faults import FaultPlan, PerturbCase
from orchestrator.cosim.master import run_cosim
from orchestrator.cosim.result import CosimResult, FaultCause
from orchestrator.cosim.schedule import StallMeter
from orchestrator.cosim.watchdog import ReplyWatchdog
from orchestrator.loop import Observation, Sensed
from tests.controller_support import tube_about_nominal
from tests.fmu_support import built_fmu

serial = pytest.mark.serial  # judged against the wall clock (tests/test_cosim.py)


def test_stall_meter_counts_the_plants_own_time_not_its_waits():
    """Own time = the tick's wall time less its waits up to their deadlines; a wait that
    ends past its deadline (the process woke late) is the plant's own; a tick whose own time
    reaches a period is a host stall (ms, tick)."""
    m = StallMeter(1e-3)
    m.begin(0, 10.0)
    m.waited(10.0001, 10.0009, until=10.0008)  # woke 0.1 ms late: 0.7 ms deliberate
    assert m.own(10.001) == pytest.approx(0.3e-3)
    assert m.held_up(10.001) == 0.0
    m.begin(1, 10.001)  # tick 0: 0.3 ms own, no stall
    assert m.previous == pytest.approx(0.3e-3) and m.count == 0
    m.waited(10.0012, 10.0052, until=10.0020)  # 0.8 ms deliberate, then 3.2 ms asleep
    assert m.held_up(10.0053) == pytest.approx(4.3 - 0.8, rel=1e-6)
    m.begin(2, 10.0060)  # tick 1: 5 ms - 0.8 ms own: a stall
    assert m.count == 1 and m.largest[:2] == (pytest.approx(4.2), 1)
    assert 0 <= m.largest[2] < 4.2  # of it on a CPU (this test slept not at all: ~0)
    assert m.held_up(10.0061) == pytest.approx(4.2)  # the previous tick's stall still counts
    m.begin(3, 10.0062)
    assert m.held_up(10.0063) == 0.0 and m.count == 1
    m.end(10.0064)
    m.end(10.0065)  # idempotent
    assert m.count == 1 and m.total_ms == pytest.approx(4.2)


def test_watchdog_names_the_host_when_most_silent_periods_had_the_plant_held_up():
    lost = threading.Event()
    wd = ReplyWatchdog(periods=3, reply_timeout=1.0, node_watchdog=0.05, armed=True,
                       start=time.perf_counter())
    for k, stall in ((10, 0.0), (11, 4.2), (12, 7.5)):
        wd.missed(k, stall)
    assert wd.fault(12, False, None, lost) == "3 control periods without a torque reply"
    assert wd.cause is FaultCause.HOST
    assert wd.verdict == ("the host stalled: the plant's own loop was held up 7.5 ms at tick "
                          "12 (2 of the 3 silent periods)")
    wd = ReplyWatchdog(periods=3, reply_timeout=1.0, node_watchdog=0.05, armed=True,
                       start=time.perf_counter())
    for k, stall in ((20, 9.0), (21, 0.0), (22, 0.0)):
        wd.missed(k, stall)
    assert wd.fault(22, False, None, lost) == "3 control periods without a torque reply"
    assert wd.cause is FaultCause.CONTROLLER
    assert wd.verdict == ("the controller missed its deadline (2 of the 3 silent periods with "
                          "the plant on time)")
    # a reply ends the silence: what the plant's stalls counted goes with it
    wd.replied()
    assert (wd.silent, wd.silent_host, wd.silent_stall) == (0, 0, (0.0, -1))
    lost.set()
    assert wd.fault(23, False, None, lost) == "controller liveliness token lost"
    assert wd.cause is FaultCause.CONTROLLER and wd.verdict == "the controller failed"


def _realtime_link(name: str, plan: FaultPlan) -> tuple[CanLink, can.BusABC, CosimResult]:
    ch = f"verdict-{name}-{os.getpid()}"
    plant_bus = can.Bus(interface="virtual", channel=ch)
    ctrl_bus = can.Bus(interface="virtual", channel=ch, preserve_timestamps=True)
    res = CosimResult()
    link = CanLink(CosimConfig("clfqp", Path("g"), Path("t"), mode="realtime", dt=2e-3,
                               watchdog_periods=3, reply_timeout=1.0), plant_bus, res,
                   Drives((50.0, 50.0), (2.0, 2.0)), plan=plan)
    return link, ctrl_bus, res


def _walk(link: CanLink, ctrl_bus: can.BusABC, answer: set[int], ticks: int) -> str:
    """Realtime ticks 0.. of a controller that answers the ticks in ``answer`` at once
    (its reply on the bus before the tick's frames go out); the fault that ended them."""
    sensed = Sensed(0.1, 0.2, 0.0, 0.0, 500.0, True, math.nan)
    try:
        for k in range(ticks):
            if k in answer:
                ctrl_bus.send(codec.torque_frame(0.1, 0.2, k % 16, timestamp=k * 2e-3)
                              .to_message())
            c = link.exchange(Observation(k, k * 2e-3, "ps", 0, 0.1, sensed))
            if c.fault:
                return c.fault
            link.pace(k + 1)
        return ""
    finally:
        link.bus.shutdown()
        ctrl_bus.shutdown()


@serial
def test_realtime_silence_while_the_plant_stalls_is_the_hosts():
    """The controller answers tick 0, then nothing; the plant sleeps 6 ms (3 periods) before
    each of ticks 1.. : the watchdog's 3 silent periods are the host's, with the stall in
    ms; the late replies count as the host's."""
    plan = FaultPlan(PerturbCase.STALL, start=1, every=1, count=10, stall_ms=6.0)
    link, ctrl_bus, res = _realtime_link("host", plan)
    fault = _walk(link, ctrl_bus, {0}, 10)
    link.report(_log())
    assert fault == "3 control periods without a torque reply"
    assert res.fault_cause is FaultCause.HOST, res.fault_verdict
    assert res.fault_verdict.startswith("the host stalled: the plant's own loop was held up ")
    assert res.late_host == res.late == 3 and res.late_controller == 0
    assert res.host_stalls >= 3 and 6.0 <= res.host_stall_ms < 60
    assert res.host_stall_cpu_ms < 0.5 * res.host_stall_ms  # it slept: not on a CPU


@serial
def test_realtime_silence_with_the_plant_on_time_is_the_controllers():
    """The same silence with the plant on time: the controller missed its deadline."""
    link, ctrl_bus, res = _realtime_link("ctrl", FaultPlan())
    fault = _walk(link, ctrl_bus, {0}, 10)
    link.report(_log())
    assert fault == "3 control periods without a torque reply"
    assert res.fault_cause is FaultCause.CONTROLLER, res.fault_verdict
    assert res.fault_verdict.startswith("the controller missed its deadline")
    assert res.late_controller >= 2 and res.late == res.late_host + res.late_controller


def _log():
    from orchestrator.loop import LoopLog

    return LoopLog()


# ------------------------------------------------------------------ real-time co-simulations


@pytest.fixture(scope="module")
def files(tmp_path_factory, model, template_gait):
    fmu, gait = built_fmu(tmp_path_factory, model, template_gait)
    d = tmp_path_factory.mktemp("verdict")
    tube = d / "tube.json"
    save_tube(tube, tube_about_nominal(template_gait, (0.1, 0.15, 0.02)))
    return {"fmu": fmu, "gait": gait, "tube": tube, "dir": d}


def _cfg(files, **kw) -> CosimConfig:
    return CosimConfig(**{"controller": "clfqp", "gait": files["gait"], "tube": files["tube"],
                          "fmu": files["fmu"], "mode": "realtime", "dt": 2e-3, "steps": 5,
                          **kw})


@serial
def test_realtime_stall_is_measured_as_a_host_stall(files, model):
    """``--perturb stall:50:60`` (the plant sleeps 60 ms before tick 50): a host stall of at
    least 60 ms at tick 50 (unless the machine stalled the plant longer elsewhere), nearly
    all of it off the CPU; any late reply is split between host and controller."""
    res = run_cosim(_cfg(files, perturb="stall:50:60", max_time=0.3, watchdog_periods=25),
                    model=model)
    assert not res.faulted and res.fault_cause is FaultCause.NONE and not res.fault_verdict
    assert res.host_stalls >= 1 and res.host_stall_ms >= 60.0, res
    if res.host_stall_ms < 100:  # the injected stall is the largest
        assert res.host_stall_tick == 50 and res.host_stall_cpu_ms < 20.0, res
    assert res.late == res.late_host + res.late_controller


@serial
def test_realtime_hang_is_the_controller_missing_its_deadline(files, model):
    """``--perturb hang:60`` (the controller stopped, alive): the fault names the controller,
    the plant being on time in most silent periods."""
    start = 60
    for _ in range(3):  # a run ended before the hang by the machine's own stall: again
        res = run_cosim(_cfg(files, perturb=f"hang:{start}", max_time=1.0), model=model)
        if res.ticks > start:
            break
    assert res.faulted and start < res.ticks <= start + 6, res
    assert "without a torque reply" in res.fault_reason
    assert res.fault_cause is FaultCause.CONTROLLER, res.fault_verdict
    assert res.fault_verdict.startswith("the controller missed its deadline")
    assert res.late_controller >= 3

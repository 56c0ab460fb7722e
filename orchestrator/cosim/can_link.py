"""The co-simulation's link to the controller process: CAN frames (AMPRO3's protocol) on a
python-can bus (:class:`CanLink`, the :class:`orchestrator.loop.Link` of ``hpcosim run``).

Per tick k (t = k dt) the link

1. emulates the AMPRO3 drives: encodes ``KneeFeedback``, ``AnkleFeedback``, ``FootLoad``,
   ``SocketImu``, ``SimTime`` (rolling counter k mod 16, timestamp t) from what the plant
   senses and sends them through the fault plan (:mod:`orchestrator.cosim.faults`);
2. while the controller works, queues the tick's records and serializes the queue;
3. waits for the ``TorqueCmd`` answering this cycle (its timestamp echoes t):
   *lockstep* blocks for it up to ``reply_timeout`` (deterministic), *realtime* waits at
   most until 0.8 dt into the tick's wall slot and otherwise holds the last torque (counted
   late); other controller frames (heartbeat, status, rejects, CLF) are checked and
   recorded on the way; the cycle's ``CtrlClf`` gives the period's ``Command.V`` and
   ``.rho``;
4. judges the controller (:mod:`orchestrator.cosim.watchdog`): a missing reply holds the
   last torque; the watchdog, a lost liveliness token or a SAFE/FAULT heartbeat give the
   safe torque (zero) and a :attr:`Command.fault` that ends the run.

In realtime the link also measures the plant's own time in each tick
(:class:`~orchestrator.cosim.schedule.StallMeter`): a late reply while the plant's own loop
was held up a period or more is the host's (``late_host``), else the controller's
(``late_controller``), and a silence that ends the run says which (``fault_cause``).  What
the link keeps of a run is constant in size (latency histogram, tallies, counts), however
long the run.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import can

from bus_schemas.transport import codec
from bus_schemas.transport.bus_config import FrameReader, send_frames
from bus_schemas.transport.frame import Frame
from bus_schemas.transport.protocol import PLANT_TO_CTRL, FrameId, frame_specs
from orchestrator.cosim.config import CosimConfig
from orchestrator.cosim.controller_process import ControllerProcess
from orchestrator.cosim.drives import Drives, Plant
from orchestrator.cosim.faults import FaultPlan
from orchestrator.cosim.frame_records import diagnostics_record, rx_records, tx_records
from orchestrator.cosim.result import CosimResult, ReplyTimes, tick_breakdown
from orchestrator.cosim.schedule import StallMeter, WallSchedule
from orchestrator.cosim.watchdog import ReplyWatchdog
from orchestrator.loop import Command, LoopLog, Observation

_CLF, _TORQUE, _STATUS = int(FrameId.CTRL_CLF), int(FrameId.TORQUE_CMD), int(FrameId.CTRL_STATUS)
_OK = codec.FrameStatus.OK

#: record queue entries the plant may leave for later waits when the controller's reply
#: comes before the serialization is done (a few ticks' worth)
MAX_BACKLOG = 64

#: a received frame and the plant's verdict on it
Checked = tuple[Any, codec.Verdict]


class CanLink:
    """The controller in its own process, over CAN frames on a python-can ``bus`` (module
    docstring): per period the plant's frames go out through the fault ``plan``, the
    controller's frames are checked by the :class:`~orchestrator.cosim.drives.Plant` and
    recorded, and this cycle's ``TorqueCmd`` is awaited.  Recording (``rec``, a
    :class:`bus_schemas.recording.recorder.Recorder`) is deferred: the tick's frames are queued as
    they happen and serialized while the plant waits for the reply.  The cycle's ``CtrlClf``
    frame gives :attr:`Command.V` and :attr:`Command.rho` (None when the frame says absent,
    or when no good frame of this cycle came).  ``controller``: the process (its
    liveliness, the process faults); None: a bus with no process behind it (tests).

    In lockstep under :func:`orchestrator.loop.run_loop` (:attr:`idle_after_send`) only what
    the torque needs is on the way from the reply to the next send: the reply sample's
    ``TorqueCmd`` is checked first (a frame's verdict depends on its own id's counter state
    alone, so it is the verdict it gets after the frames before it); the frames before it
    are checked, and their records queued, in the loop's ``idle`` after the next cycle's
    send (:meth:`settle`), before any other controller frame: the same verdicts, counts,
    Command and records in the same order.  A reply sample of another shape (a fault, a
    python-can bus) is taken frame by frame as before."""

    def __init__(self, cfg: CosimConfig, bus: Any, res: CosimResult, drives: Drives, *,
                 plan: FaultPlan | None = None, rec: Any = None,
                 controller: ControllerProcess | None = None) -> None:
        self.cfg, self.bus, self.res, self.drives, self.rec = cfg, bus, res, drives, rec
        self.plan = plan or FaultPlan()
        self.controller = controller
        self.lost = controller.lost if controller is not None else threading.Event()
        self.frames = FrameReader(bus)
        self.plant = Plant(drives.limits)
        self.dt = cfg.dt
        self.realtime = cfg.realtime
        self.u = (0.0, 0.0)  # the motor torques applied [N m]
        self.times = ReplyTimes()
        self.injected: dict[str, int] = {}
        self.wall0 = time.perf_counter()
        self.schedule = WallSchedule(cfg.dt, cfg.max_lag, self.wall0)
        self.stalls = StallMeter(cfg.dt)  # realtime: the plant's own time per tick
        self.watchdog = ReplyWatchdog(periods=cfg.watchdog_periods,
                                      reply_timeout=cfg.reply_timeout,
                                      node_watchdog=cfg.controller_watchdog,
                                      armed=not self.realtime, start=self.wall0)
        self.rtol = max(1e-7, self.dt * 1e-3)  # matching a reply's echoed timestamp
        self.names = {fid: frame_specs()[fid].name for fid in PLANT_TO_CTRL}
        #: the last good CtrlClf: (timestamp [s], V or None, rho or None)
        self.clf: tuple[float, float | None, float | None] | None = None
        #: lockstep under run_loop (:attr:`idle_after_send`): the reply frames before this
        #: cycle's TorqueCmd, checked after the next cycle's send (:meth:`settle`): (frames,
        #: the TorqueCmd, its verdict, t, the torque applied before it)
        self._held: tuple[list[Any], Any, codec.Verdict, float, tuple[float, float]] | None = None
        #: the Command :meth:`settle` completes, and its cycle's time
        self._provisional: tuple[Command, float] | None = None

    @property
    def idle_after_send(self) -> bool:
        """Lockstep: :meth:`exchange` takes the loop's ``idle`` work (run_loop) and checks
        only this cycle's TorqueCmd before it returns (realtime: everything at once, the log
        times of its records being wall times)."""
        return not self.realtime

    def log_ns(self, t: float) -> int:
        """A record's log time [ns]: the simulation time ``t`` (lockstep), the wall time
        since the start (realtime)."""
        return round((time.perf_counter() - self.wall0 if self.realtime else t) * 1e9)

    # ------------------------------------------------------------------ one period

    def exchange(self, obs: Observation, idle: Callable[[], None] | None = None) -> Command:
        """This period's Command (module docstring); ``idle`` (lockstep, run_loop's
        bookkeeping): called once after the send, and the reply's frames before this
        cycle's TorqueCmd are checked later, in :meth:`settle` (the Command returned is
        then provisional: ``V``/``rho`` None until settled)."""
        self._before_send(obs.k, obs.t)
        frames = self._feedback_frames(obs)
        sent_ns = self._send(obs.k, frames)
        if idle is not None:  # the last period's bookkeeping, while the controller works
            idle()
        self._settle_held()  # before any other controller frame is checked
        if self.rec is not None:
            self._record_tx(obs, frames)
        got, answered = self._await_reply(obs.k, obs.t, sent_ns, late=idle is not None)
        return self._command(obs.t, self._judge(obs.k, got, answered))

    def _before_send(self, k: int, t: float) -> None:
        """The plant's own faults (a stall), realtime catch-up, the process faults."""
        plan = self.plan
        if self.realtime:
            self.stalls.begin(k, time.perf_counter())
        if plan.case.is_plant and plan.hits(k):
            time.sleep(plan.stall_ms * 1e-3)
            self._count(plan.case.value)
        if self.realtime:
            self._catch_up(k, t)
        if self.controller is not None and plan.process_fault_due(k):
            self.controller.inject(plan.case)

    def _catch_up(self, k: int, t: float) -> None:
        """Realtime: a tick begun a period or more late is an overrun (counted; recorded on
        ``/cosim/timing``); past ``max_lag`` the schedule skips slots (:class:`WallSchedule`)."""
        over = self.schedule.catch_up(k)
        if over is None:
            return
        lag, skip = over
        res = self.res
        res.overruns += 1
        res.max_lag_ms = max(res.max_lag_ms, lag * 1e3)
        res.skipped_slots += skip
        if self.rec is not None:
            self.rec.defer("/cosim/timing", {"t": t, "tick": k, "lag": lag, "skipped": skip},
                           self.log_ns(t))

    @staticmethod
    def _feedback_frames(obs: Observation) -> list[Any]:
        """The drives' frames of what the plant senses in period ``obs.k``."""
        s = obs.sensed
        return codec.feedback_frames(s.knee_angle, s.knee_velocity, s.ankle_angle,
                                     s.ankle_velocity, s.foot_load, s.contact, obs.k % 16,
                                     sim_time_us=round(obs.t * 1e6),
                                     socket_pitch=s.socket_pitch, timestamp=obs.t)

    def _send(self, k: int, frames: list[Any]) -> int:
        """Send tick ``k``'s frames through the fault plan; the send time [ns]."""
        send, what = self.plan.apply(k, frames)
        if what:
            self._count(what)
        sent_ns = time.perf_counter_ns()
        self.watchdog.sent(k, sent_ns)
        send_frames(self.bus, send)
        self.res.frames_tx += len(send)
        return sent_ns

    def _record_tx(self, obs: Observation, frames: list[Any]) -> None:
        """While the controller works: queue the tick's frames and measurement and serialize
        the queue, stopping as soon as the reply is here (the rest waits for the next
        tick's wait)."""
        r0 = time.perf_counter_ns()
        t = obs.t
        self.rec.defer_many(self.log_ns(t), tx_records, frames, self.names, obs.sensed,
                            round(t * 1e6), obs.k % 16)
        self.rec.write_deferred(self._reply_here)
        self.times.record.add(time.perf_counter_ns() - r0)

    def _await_reply(self, k: int, t: float, sent_ns: int, *, late: bool) -> tuple[bool, bool]:
        """Wait for this cycle's torque: lockstep up to ``reply_timeout``; realtime until
        0.8 dt into the tick's slot, or 0.8 dt after sending when the plant itself runs
        behind (a late plant must not count its own lateness as the controller's missed
        reply).  What is already in when the deadline has passed (the plant itself woke
        late) is still taken.  (this cycle's reply came, some good TorqueCmd came);
        ``late``: held for :meth:`settle` (:meth:`_take_torque`)."""
        w0 = time.perf_counter_ns()
        deadline = (max(self.schedule.slot(k + 0.8), sent_ns * 1e-9 + 0.8 * self.dt)
                    if self.realtime else sent_ns * 1e-9 + self.cfg.reply_timeout)
        got = answered = False
        while not got and not self.lost.is_set():
            left = deadline - time.perf_counter()
            sample = self.frames.recv_all(min(left, 0.005) if left > 0 else 0.0)
            if sample:
                got, in_sample = self._take_sample(sample, t, late)
                answered = answered or in_sample
            elif left <= 0:
                break
        r1 = time.perf_counter_ns()
        if self.realtime:
            self.stalls.waited(w0 * 1e-9, r1 * 1e-9, deadline)
        if got:
            self.times.replied(r1 - sent_ns, r1 - w0)
        return got, answered

    def _take_sample(self, sample: list[Any], t: float, late: bool) -> tuple[bool, bool]:
        """One received sample's frames checked and queued for the MCAP, a good TorqueCmd
        applied: (this cycle's reply among them, some good TorqueCmd among them).  Frames
        after this cycle's reply are left for the next read."""
        pre = None
        if late:
            pre = self._take_torque(sample, t)
            if self._held is not None:
                return True, True
        got = answered = False
        last = len(sample) - 1
        items: list[Checked] = []
        for i, msg in enumerate(sample):  # a sample's frames: the reply batch
            v = self.on_rx(msg, t, items, pre if i == last else None)
            if v.frame_id == _TORQUE and v.status is _OK:
                self.u = self.plant.command(v.value)
                answered = True
                if abs(msg.timestamp - t) <= self.rtol:
                    got = True
                    if i < last:  # frames after this cycle's reply
                        self.frames.unread(sample[i + 1:])
                    break
        self._defer_rx(items, t)
        return got, answered

    def _judge(self, k: int, got: bool, answered: bool) -> str:
        """Count the reply (or its absence) and ask the watchdog; on a fault the safe
        torque (zero).  The fault's reason, "" while the controller is trusted."""
        res, wd = self.res, self.watchdog
        stall = 0.0  # realtime: the plant's own loop held up [ms] (StallMeter.held_up)
        if got:
            wd.replied()
        else:
            if self.realtime:
                stall = self.stalls.held_up(time.perf_counter())
                res.late += 1
                if stall:
                    res.late_host += 1
                else:
                    res.late_controller += 1
            if self.realtime and answered:
                wd.answered_late()
            else:
                res.missed += 1
                wd.missed(k, stall)
        reason = wd.fault(k, got, self.plant.ctrl_state, self.lost)
        if reason:
            self.u = (0.0, 0.0)
            res.detection_periods = wd.detection_periods(k)
            res.fault_cause, res.fault_verdict = wd.cause, wd.verdict
        return reason

    def _command(self, t: float, fault: str) -> Command:
        """The period's Command; provisional (V and rho once settled) while reply frames
        are held."""
        if self._held is not None:
            cmd = Command(self.u, V=None, rho=None, fault=fault)
            self._provisional = (cmd, t)
            return cmd
        V, rho = self._clf_at(t)
        return Command(self.u, V=V, rho=rho, fault=fault)

    def _clf_at(self, t: float) -> tuple[float | None, float | None]:
        """(V, rho) of the cycle at ``t`` from its CtrlClf, (None, None) without one."""
        c = self.clf
        if c is not None and abs(c[0] - t) <= self.rtol:
            return c[1], c[2]
        return None, None

    # ------------------------------------------------------------------ frames

    def on_rx(self, msg: can.Message, t: float, items: list[Checked] | None = None,
              v: codec.Verdict | None = None) -> codec.Verdict:
        """Check one controller frame (:meth:`Plant.on_rx`; ``v``: a TorqueCmd's verdict
        already taken), take the cycle's V and rho from a good ``CtrlClf``; with a
        recording, the frame and what it carries go to ``items`` (queued for the MCAP per
        sample by :meth:`_defer_rx`; a ``CtrlStatus``'s diagnostics record, every 100
        ticks, is queued here with the torque and CLF values of the moment)."""
        if v is None:
            v = self.plant.on_rx(msg)
        self.res.frames_rx += 1
        fid = v.frame_id
        if fid == _CLF and v.status is _OK:
            c = v.value
            self.clf = (msg.timestamp, c.V if c.v_valid else None,
                        c.rho if c.rho_valid else None)
        if items is None or self.rec is None:
            return v
        items.append((msg, v))
        if fid == _STATUS and v.status is _OK:
            c = self.clf  # the node sends its cycle's CtrlClf before CtrlStatus
            clf = (c[1], c[2]) if c is not None and c[0] == msg.timestamp else (None, None)
            self.rec.defer("/controller/diagnostics", diagnostics_record(
                v.value, msg.timestamp, self.cfg.controller, self.drives.joint(self.u), clf,
                self.plant.ctrl_rejects), self.log_ns(t))
        return v

    def _reply_here(self) -> bool:
        """Stop serializing records: a controller frame is here, and at most
        :data:`MAX_BACKLOG` queue entries are left (serializing keeps up with the run; what
        is left goes in the next waits)."""
        return self.rec.deferred <= MAX_BACKLOG and self.frames.ready()

    def _defer_rx(self, items: list[Checked], t: float) -> None:
        """Queue the records of one received sample's frames (one queue entry)."""
        if items and self.rec is not None:
            self.rec.defer_many(self.log_ns(t), rx_records, items, self.drives.ratio)

    def _count(self, what: str) -> None:
        """One more injected fault ``what``."""
        self.injected[what] = self.injected.get(what, 0) + 1

    # ------------------------------------------------------------------ held replies

    def _take_torque(self, sample: list[Any], t: float) -> codec.Verdict | None:
        """Lockstep's common reply: a sample of Frames ending in its only TorqueCmd. That
        frame checked alone (its verdict depends on its own id's counter state only, as
        every frame's: the same verdict as after the frames before it); when it is this
        cycle's and good, the torque applied and the frames before it held for
        :meth:`settle`: None. Else its verdict, for the frames to be taken in order."""
        m = sample[-1]
        if type(m) is not Frame or m[1] != _TORQUE:
            return None
        for f in sample[:-1]:
            if type(f) is not Frame or f[1] == _TORQUE:
                return None
        v = self.plant.checker.check_all((m,))[0]
        if v.status is not _OK or abs(m[0] - t) > self.rtol:
            return v
        self._held = (sample[:-1], m, v, t, self.u)
        self.u = self.plant.command(v.value)
        return None

    def _settle_held(self) -> None:
        """The held reply frames checked and queued for the MCAP, with the torque frame
        after them: as if taken in order when they came (:meth:`_take_torque`)."""
        h = self._held
        if h is None:
            return
        self._held = None
        frames, m, v, t, u_before = h
        items: list[Checked] = []
        u, self.u = self.u, u_before  # the diagnostics record's torque of the moment
        try:
            for f in frames:
                self.on_rx(f, t, items)
        finally:
            self.u = u
        self.on_rx(m, t, items, v)
        self._defer_rx(items, t)

    def settle(self, cmd: Command) -> Command:
        """``cmd`` complete: the provisional Command of a cycle whose reply frames were
        held (:meth:`exchange` with ``idle``) gets its ``V``/``rho`` from the cycle's
        ``CtrlClf`` once they are checked; any other Command is already complete."""
        p = self._provisional
        if p is None or cmd is not p[0]:
            return cmd
        self._provisional, t = None, p[1]
        self._settle_held()
        V, rho = self._clf_at(t)
        return cmd._replace(V=V, rho=rho)

    # ------------------------------------------------------------------ between periods

    def pace(self, k: int) -> None:
        """Realtime: wait for tick ``k``'s wall slot, taking late replies meanwhile."""
        if not self.realtime:
            return
        end = self.schedule.slot(k)
        t = (k - 1) * self.dt
        self._settle_held()
        p0 = time.perf_counter()
        while (left := end - time.perf_counter()) > 0:
            items: list[Checked] = []
            for msg in self.frames.recv_all(left):
                v = self.on_rx(msg, t, items)
                if v.frame_id == _TORQUE and v.status is _OK and v.value.enable:
                    self.u = (v.value.knee, v.value.ankle)
            self._defer_rx(items, t)
        self.stalls.waited(p0, time.perf_counter(), end)

    def report(self, log: LoopLog) -> None:
        """After the loop: the link's figures into the run's result (wall time, faults
        injected, rejects, torques clamped, reply latency, the tick breakdown, the host
        stalls)."""
        res, plant, times = self.res, self.plant, self.times
        res.wall_time = time.perf_counter() - self.wall0
        if self.realtime:
            st = self.stalls
            st.end(time.perf_counter())
            res.host_stalls = st.count
            res.host_stall_ms, res.host_stall_tick, res.host_stall_cpu_ms = st.largest
        res.injected = self.injected
        res.plant_rejects = plant.rejects()
        res.torque_clamped = plant.torque_clamped
        res.ctrl_rejects = plant.ctrl_rejects
        res.latency_us = times.latency_us()
        res.timing_us = tick_breakdown(log.tick_ns, log.plant_ns, times.round_trip,
                                       times.record, times.wait)
        res.reply_early = times.early_share() if self.rec is not None else 0.0

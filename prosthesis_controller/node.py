"""The controller node: a prosthesis controller behind the AMPRO3 CAN port.

Per control cycle the plant sends ``KneeFeedback``, ``AnkleFeedback``, ``FootLoad``, if it
has an IMU ``SocketImu``, and, last, ``SimTime``, all with the same rolling counter. The
node checks every frame (:class:`bus_schemas.transport.codec.FrameChecker`: id, length, CRC,
counter; rejects are counted and reported in ``CtrlRejects``), collects the cycle, and on
``SimTime`` ticks the controller and answers with (heartbeat every ``heartbeat_every``
ticks, ``CtrlClf`` (the tick's CLF value V and relaxation rho; rho absent for a controller
without a relaxation) on every tick, ``CtrlStatus`` + ``CtrlRejects`` every
``status_every`` ticks, ``CtrlDisturbance`` on every tick with a valid model-error estimate
(``clfqp``'s stance), then) one ``TorqueCmd``. The torque frame's timestamp echoes the
``SimTime`` frame's timestamp, so the plant knows which cycle a reply answers (lockstep
plants stamp frames with simulation time). A feedback frame missing from a cycle (dropped,
corrupted, late) is replaced by its last accepted value and flagged ``stale_feedback``;
before the first complete cycle the node answers with torque disabled. The IMU is optional:
the socket pitch is the cycle's ``SocketImu`` value when it came with the cycle's counter
and ``ImuValid``, NaN otherwise (the controller's swing then runs on its clock; a cycle that
lacks an IMU frame after one was seen is flagged ``stale_feedback`` too).

Watchdog: when no cycle arrives for ``watchdog`` seconds of wall time the node goes SAFE:
zero torque with ``TorqueEnable = 0`` and heartbeats in state SAFE, repeated every
``watchdog`` seconds; the next good cycle resumes RUNNING, with a heartbeat in its reply
whatever ``heartbeat_every`` (the controller's state is kept, so a lockstep run stays
deterministic when a slow plant trips the watchdog). The first cycle arms it: before any
measurement there is nothing to stop (and a SAFE torque frame, timestamp 0, sent while a
slow plant starts up would pass for the reply to its cycle at t = 0). On a bus with
liveliness (:class:`~bus_schemas.transport.liveliness.Liveliness`; over zenoh the token
``hpcosim/run/<id>/ctrl/alive``) the node says it is alive only once the controller is built
and the bus subscribed (so a plant seeing it can start), and leaves when the plant goes away.

Run as ``python -m prosthesis_controller.node --controller clfqp --gait G --tube T
[--bus bus.toml | --run-id ID --connect tcp/127.0.0.1:PORT --key lab.key]`` or
``hpcosim controller serve``. Over zenoh the node serves only a plant that authenticates:
with the key file's secret (``--key`` / the bus config's ``key_file``) or the run's
(``--auth-stdin``, :mod:`bus_schemas.transport.run_auth`); without either it refuses to
start (:func:`require_plant_key`; docs/cosim.md, "Who may drive the controller").
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from collections.abc import Sequence
from typing import Any, NamedTuple

import can

from bus_schemas.transport import codec
from bus_schemas.transport.bus_config import (
    BusConfig,
    BusConfigError,
    FrameReader,
    bus_config_from_dict,
    load_bus_config,
    make_bus,
    read_key,
    send_frames,
)
from bus_schemas.transport.liveliness import liveliness
from bus_schemas.transport.protocol import (
    PLANT_TO_CTRL,
    ActiveConstraint,
    CtrlState,
    FaultFlag,
    FrameId,
    QpStatus,
)
from bus_schemas.transport.run_auth import RunCredentials
from hp_model import json_io
from hp_model.config import ConfigError
from prosthesis_controller.interface import Active, Controller, ControllerName, QpOutcome
from prosthesis_controller.measurement import ProsthesisMeasurement
from prosthesis_controller.timing import Durations, Usage, pin_thread

SUMMARY_PREFIX = "controller node: "  # + the JSON summary, last line on stderr at exit
FEEDBACK = (FrameId.KNEE_FEEDBACK, FrameId.ANKLE_FEEDBACK, FrameId.FOOT_LOAD)
#: the controller's QP outcome as the bus reports it (CtrlStatus.QpStatus)
QP_STATUS: dict[QpOutcome, QpStatus] = {
    QpOutcome.SOLVED: QpStatus.SOLVED, QpOutcome.NOT_RUN: QpStatus.NOT_RUN,
    QpOutcome.INFEASIBLE: QpStatus.PRIMAL_INFEASIBLE, QpOutcome.FAILED: QpStatus.UNSOLVED,
    QpOutcome.NONFINITE: QpStatus.NUMERICS}


_OUTPUT_CLAMP = int(Active.OUTPUT_CLAMP)  # an int: IntFlag's & is Python code
_OK = codec.FrameStatus.OK
#: plain ints (hashing and comparing an IntEnum member is Python code)
_HELD = frozenset(int(f) for f in (*FEEDBACK, FrameId.SOCKET_IMU))  # held until SimTime
_SIM_TIME, _IMU, _TORQUE = (int(FrameId.SIM_TIME), int(FrameId.SOCKET_IMU),
                            int(FrameId.TORQUE_CMD))
_KNEE, _ANKLE, _LOAD = (int(f) for f in FEEDBACK)
_QP_FAILURES = frozenset(q for q in QpOutcome if q.is_failure)
_RUNNING = CtrlState.RUNNING


#: the controller's active QP constraints (``Active``) as the bus reports them
#: (CtrlStatus.ActiveConstraints)
ACTIVE_CONSTRAINTS: tuple[tuple[Active, ActiveConstraint], ...] = (
    (Active.KNEE_LOWER | Active.KNEE_UPPER, ActiveConstraint.KNEE_TORQUE),
    (Active.ANKLE_LOWER | Active.ANKLE_UPPER, ActiveConstraint.ANKLE_TORQUE),
    (Active.RHO_MAX, ActiveConstraint.RELAXATION))


def _active_bits(a: int) -> ActiveConstraint:
    """The ``ActiveConstraint`` bits of a tick's ``Active`` flags."""
    out = ActiveConstraint.NONE
    for active, bit in ACTIVE_CONSTRAINTS:
        if a & active:
            out |= bit
    return out


def _disturbance_frame(d: Any, ts: float) -> codec.Frame:
    """``CtrlDisturbance`` of a tick's diagnostics (model-error estimate, coverage flag)."""
    e = d.disturbance
    return codec.disturbance_frame(e[0], e[1], d.tau, d.disturbance_valid, d.coverage_flag,
                                   d.since_touchdown, timestamp=ts)


class ControllerNode:
    """Frame handling and controller ticking, independent of the transport (testable
    without a bus): :meth:`handle` one received frame -> frames to send; :meth:`poll` the
    watchdog. Frames out are light :class:`bus_schemas.transport.frame.Frame` s (``send_frames``
    sends them as ``can.Message`` s on a bus that needs those)."""

    def __init__(self, controller: Controller, *, watchdog: float = 0.05,
                 heartbeat_every: int = 10, status_every: int = 100) -> None:
        self.controller = controller
        self.watchdog = float(watchdog)
        self.heartbeat_every = max(1, int(heartbeat_every))
        self.status_every = max(1, int(status_every))
        self.checker = codec.FrameChecker(accept=PLANT_TO_CTRL)
        self.pending: dict[int, tuple[int | None, Any]] = {}  # id -> (counter, payload)
        self.last: dict[int, Any] = {}
        self.state = CtrlState.INIT
        self.ticks = 0
        self.stale_cycles = 0
        self.imu_seen = False  # a SocketImu frame came with a cycle
        self.safe_entries = 0
        self._counter = 0  # TorqueCmd rolling counter
        self._hb_counter = 0
        self._clf_counter = 0  # CtrlClf rolling counter
        #: CtrlClf carries rho only for a controller with a relaxation (relaxed CLF-QPs)
        self.sends_rho = bool(getattr(controller, "relaxed", False))
        self._last_cycle: float | None = None  # the watchdog is armed by the first cycle
        self._last_safe_send = 0.0
        self._flags = FaultFlag.NONE
        self._last_diag: Any = None
        self._wrap = 0
        self._last_us: int | None = None
        self.tick_time = Durations()  # controller.tick per cycle
        #: the last tick's bookkeeping (diagnostics, its fault flags, its duration [ns]),
        #: done after its reply is sent (:meth:`after_send`)
        self._book: tuple[Any, int] | None = None
        controller.reset()

    # -- frames in, frames out
    def handle(self, msg: can.Message | codec.Frame, now: float | None = None
               ) -> list[codec.Frame]:
        """One received frame -> the frames to send (the reply on a cycle's ``SimTime``)."""
        return self.handle_frames((msg,), now)

    def handle_frames(self, frames: Sequence[can.Message | codec.Frame],
                      now: float | None = None) -> list[codec.Frame]:
        """Received frames in order (a sample's: the plant's cycle) -> the frames to send:
        :meth:`handle` of each, the replies concatenated."""
        out: list[codec.Frame] = []
        pending = self.pending
        for v in self.checker.check_all(frames):
            fid = v.frame_id
            if v.status is not _OK:
                self._flags |= FaultFlag.BAD_FRAMES
            elif fid in _HELD:
                pending[fid] = (v.counter, v.value)
            elif fid == _SIM_TIME:
                out += self._cycle(v, time.monotonic() if now is None else now)
        return out

    def _time(self, us: int) -> float:
        if self._last_us is not None and us < self._last_us:
            self._wrap += 1 << 32
        self._last_us = us
        return (us + self._wrap) * 1e-6

    def after_send(self) -> None:
        """The last tick's bookkeeping (its duration, diagnostics and the fault flags they
        raise), left for after its reply was sent; done at the latest before anything reads
        it (the next cycle, a status frame, the watchdog, the summary)."""
        b = self._book
        if b is None:
            return
        self._book = None
        d, ns = b
        self.tick_time.add(ns)
        self._last_diag = d
        if d.qp_status in _QP_FAILURES:
            self._flags |= FaultFlag.QP_FAILED
        if int(d.active) & _OUTPUT_CLAMP:
            self._flags |= FaultFlag.TORQUE_SATURATED

    def _cycle(self, v: codec.Verdict, now: float) -> list[codec.Frame]:
        if self._book is not None:
            self.after_send()
        self._last_cycle = now
        fresh = True
        pending, last, c = self.pending, self.last, v.counter
        for f in (_KNEE, _ANKLE, _LOAD):
            p = pending.pop(f, None)
            if p is not None and p[0] == c:
                last[f] = p[1]
            else:
                fresh = False
        imu = pending.pop(_IMU, None)
        pitch = math.nan
        if imu is not None and imu[0] == v.counter:
            self.imu_seen = True
            if imu[1].valid:
                pitch = imu[1].pitch
        elif self.imu_seen:
            fresh = False
        t = self._time(v.value.us)
        out: list[codec.Frame] = []
        if not fresh:
            self.stale_cycles += 1
            self._flags |= FaultFlag.STALE_FEEDBACK
        if len(self.last) < len(FEEDBACK):  # nothing to control on yet
            out.append(codec.torque_frame(0.0, 0.0, self._next(), enable=False,
                                          timestamp=v.timestamp))
            return out
        k, a, ld = last[_KNEE], last[_ANKLE], last[_LOAD]
        meas = ProsthesisMeasurement(t, k.angle, a.angle, k.velocity, a.velocity, ld.load,
                                     bool(ld.contact), pitch)
        t0 = time.perf_counter_ns()
        res = self.controller.tick(meas)
        d = res.diagnostics
        self._book = (d, time.perf_counter_ns() - t0)  # after the reply (after_send)
        resumed = self.state == CtrlState.SAFE
        self.state = _RUNNING
        ts, ticks = v.timestamp, self.ticks
        if ticks % self.heartbeat_every == 0 or resumed:  # leaving SAFE is said at once
            out.append(self._heartbeat(ts))
        c = self._clf_counter
        self._clf_counter = (c + 1) % 16
        out.append(codec.clf_frame(d.V, d.rho if self.sends_rho else None, c, timestamp=ts))
        if ticks % self.status_every == 0:
            out.extend(self.status_frames(ts))
        if d.disturbance_valid:
            out.append(_disturbance_frame(d, ts))
        self.ticks = ticks + 1
        u = res.torque
        out.append(codec.torque_frame(float(u[0]), float(u[1]), self._next(), enable=True,
                                      timestamp=ts))
        return out

    def _next(self) -> int:
        c = self._counter
        self._counter = (c + 1) % 16
        return c

    def _heartbeat(self, ts: float) -> codec.Frame:
        c = self._hb_counter
        self._hb_counter = (c + 1) % 16
        return codec.heartbeat_frame(self.state, self.ticks, c, timestamp=ts)

    def status_frames(self, ts: float = 0.0) -> list[codec.Frame]:
        if self._book is not None:
            self.after_send()  # this tick's diagnostics and flags go in its status
        d = self._last_diag
        qp = QP_STATUS[d.qp_status] if d is not None else QpStatus.NOT_RUN
        frames = codec.encode_status(self._flags, qp, 0,
                                     min(d.fallback_count, 65535) if d is not None else 0,
                                     _active_bits(d.active) if d is not None else 0,
                                     self.checker.counts,
                                     coverage_flag=bool(d is not None and d.coverage_flag),
                                     coverage_count=min(d.coverage_count, 127)
                                     if d is not None else 0, timestamp=ts)
        self._flags = FaultFlag.NONE
        return [codec.Frame(float(ts), m.arbitration_id, bytes(m.data)) for m in frames]

    def poll(self, now: float | None = None) -> list[codec.Frame]:
        """Watchdog: SAFE state (zero torque, disabled) when no cycle came for
        ``watchdog`` s; repeated every ``watchdog`` s while it lasts."""
        now = time.monotonic() if now is None else now
        if self._book is not None:
            self.after_send()
        if self._last_cycle is None or now - self._last_cycle < self.watchdog:
            return []
        if self.state != CtrlState.SAFE:
            self.state = CtrlState.SAFE
            self.safe_entries += 1
            self._flags |= FaultFlag.STALE_FEEDBACK | FaultFlag.PLANT_LOST
        elif now - self._last_safe_send < self.watchdog:
            return []
        self._last_safe_send = now
        return [self._heartbeat(0.0),
                codec.torque_frame(0.0, 0.0, self._next(), enable=False)]


# --------------------------------------------------------------------------- serving


class Artifacts(NamedTuple):
    """The files a controller is built from: the paper's gait and force tube (with the
    subject and device configs; None: the shipped defaults), or a multi-contact gait's
    controller file ``tables`` (:mod:`prosthesis_controller.gait_tables`; it carries its
    subject and device), a gait library's following the person's speed from ``speed`` (m/s,
    the person's first; None: the library's slowest)."""

    gait: str | None = None
    tube: str | None = None
    subject: str | None = None
    device: str | None = None
    tables: str | None = None
    speed: float | None = None


def build_controller(name: str, gait_path: str | None, tube_path: str | None,
                     subject: str | None = None, device: str | None = None, *,
                     tables: str | None = None, speed: float | None = None) -> Controller:
    """The controller ``name`` of the paper's gait and force tube (files), or of a
    multi-contact gait's controller file ``tables`` (the law it holds; a gait library's,
    ``clfqp``, starting at ``speed``: :class:`Artifacts`)."""
    if tables is not None:
        from prosthesis_controller.gait_tables import law_of, load_controller_file
        from prosthesis_controller.speed_following import SpeedFollowing

        ctl = load_controller_file(tables, speed)
        # a gait library's file holds clfqp following the person
        law = ControllerName.CLFQP.value if isinstance(ctl, SpeedFollowing) else law_of(ctl)
        if ControllerName(name) != law:
            raise ValueError(f"--controller {name}: the controller file {tables} holds {law}")
        return ctl
    if speed is not None:
        raise ValueError("--speed: a gait library's controller file (--tables) only")
    if gait_path is None or tube_path is None:
        raise ValueError("give --gait and --tube (the paper's graph), or --tables (a "
                         "multi-contact gait's controller file)")
    import hp_model
    from hp_model.force_tube import load_tube
    from hp_model.gait_artifact import load_gait
    from prosthesis_controller.registry import make_controller

    model = hp_model.load_model(subject, device)
    gait = load_gait(gait_path, model.parameter_hash())
    tube = load_tube(tube_path, gait.hash())
    return make_controller(name, gait, tube, model)


class _PlantPresence:
    """The plant's liveliness, on a bus that has it (CAN over zenoh; any other bus: never
    gone): watched first, then this node says it is alive (the plant may start)."""

    def __init__(self, bus: can.BusABC) -> None:
        live = liveliness(bus)
        self._watch = live.watch_peer() if live is not None else None
        self._seen = False
        if live is not None:
            live.announce_alive()

    def gone(self) -> bool:
        """True once the plant went away after having been seen."""
        if self._watch is None:
            return False
        for alive in self._watch.poll():
            if alive:
                self._seen = True
            elif self._seen:
                return True
        return False

    def close(self) -> None:
        if self._watch is not None:
            self._watch.close()


def serve(node: ControllerNode, bus: can.BusABC, *, stop: Any = None,
          exit_with_plant: bool = True, on_ready: Any = None) -> dict[str, Any]:
    """Serve until ``stop`` (a threading.Event) is set, SIGTERM/SIGINT, or (a bus with
    liveliness) the plant goes away after having been seen. Returns counts."""
    plant = _PlantPresence(bus)
    if on_ready is not None:
        on_ready()
    timeout = max(1e-3, node.watchdog / 2)
    cycle = Durations()  # first frame of a cycle received -> its reply sent
    first: int | None = None
    usage = Usage()
    frames = FrameReader(bus)
    clock = time.perf_counter_ns
    try:
        while stop is None or not stop.is_set():
            got = frames.recv_all(timeout)  # a sample's frames: the plant's cycle
            now = time.monotonic()
            if got:
                if first is None:
                    first = clock()
                out = node.handle_frames(got, now)
                if out:  # the reply first; the bookkeeping and the watchdog after it
                    send_frames(bus, out)
                    if first is not None and out[-1].arbitration_id == _TORQUE:
                        cycle.add(clock() - first)
                        first = None
                    node.after_send()
            send_frames(bus, node.poll(now))
            if plant.gone() and exit_with_plant:
                return _summary(node, "plant gone", cycle, usage)
    except can.CanOperationError:
        return _summary(node, "bus closed", cycle, usage)
    finally:
        plant.close()
    return _summary(node, "stopped", cycle, usage)


def _summary(node: ControllerNode, why: str, cycle: Durations, usage: Usage
             ) -> dict[str, Any]:
    """What the node did; ``timing_us``: ``controller_tick`` (controller.tick alone) and
    ``cycle`` (first frame of a cycle received -> its TorqueCmd sent: frame checks, the
    tick, encoding, sending); ``usage``: the process's CPU time and context switches
    while serving (all threads, zenoh's included); ``coverage_count``: ticks whose
    model-error estimate left the tube's characterised bound (0 without one)."""
    node.after_send()
    d = node._last_diag
    return {"reason": why, "ticks": node.ticks, "stale_cycles": node.stale_cycles,
            "safe_entries": node.safe_entries,
            "coverage_count": int(d.coverage_count) if d is not None else 0,
            "rejects": {str(k): v for k, v in node.checker.counts.items() if str(k) != "ok"},
            "timing_us": {"controller_tick": node.tick_time.summary(),
                          "cycle": cycle.summary()},
            "usage": usage.since()}


#: the command-line option of each bus-config field a verb overrides
OPTION_NAMES = {"interface": "--interface", "run_id": "--run-id", "channel": "--channel",
                "listen": "--listen", "connect": "--connect", "key_file": "--key"}


def bus_config_from_args(bus: str | None = None, **kw: Any) -> BusConfig:
    """A bus file, overridden by the non-None keyword options (interface, run_id, ...,
    key_file); every field checked, an error naming the file's field or the option
    (:data:`OPTION_NAMES`) that set it."""
    base = load_bus_config(bus).to_dict() if bus else {}
    over = {k: v for k, v in kw.items() if v is not None}
    base.update(over)
    return bus_config_from_dict(base, str(bus) if bus else "bus config",
                                names={k: OPTION_NAMES.get(k, k) for k in over})


def require_plant_key(cfg: BusConfig) -> None:
    """Refuse to serve CAN over zenoh without a key: any local user (or, with
    ``allow_remote``, anyone on the network) could otherwise play the plant and receive
    torque commands. A key is a key file (``--key`` / ``key_file``) or a run's secret
    (``--auth-stdin``). Other interfaces need none: virtual is in-process, a CAN bus is a
    wire the lab controls (docs/cosim.md, "Who may drive the controller")."""
    if cfg.authenticates and not cfg.authenticated:
        raise BusConfigError(
            "--key: a controller served over zenoh needs a key file (one line, a secret of "
            "16 or more characters, mode 0600) that its plant's bus config names too "
            "(key_file); e.g. python -c 'import secrets; print(secrets.token_urlsafe(32))' "
            "> lab.key && chmod 600 lab.key")


def run_node(controller: str, artifacts: Artifacts, cfg: BusConfig, *,
             watchdog: float = 0.05, status_every: int = 100) -> dict[str, Any]:
    """Check the bus config (a zenoh bus needs a key: :func:`require_plant_key`; a key
    file is read here, before the controller is built), build the controller, open the
    bus, serve (see :func:`serve`)."""
    if not (math.isfinite(watchdog) and watchdog > 0):
        raise ConfigError(f"--watchdog-ms {watchdog * 1e3:g}: expected a finite number > 0")
    require_plant_key(cfg)
    if cfg.key_file is not None:
        read_key(cfg.key_file)  # a missing or unsafe key file: refused before the build
    a = artifacts
    ctrl = build_controller(controller, a.gait, a.tube, a.subject, a.device, tables=a.tables,
                            speed=a.speed)
    node = ControllerNode(ctrl, watchdog=watchdog, status_every=status_every)
    bus = make_bus(cfg, "ctrl", declare_alive=False)  # alive once serving (see serve)

    def _term(signum: int, _frame: Any) -> None:
        raise SystemExit(128 + signum)

    old = signal.signal(signal.SIGTERM, _term)
    try:
        return serve(node, bus, on_ready=lambda: print("ready", flush=True))
    finally:
        signal.signal(signal.SIGTERM, old)
        bus.shutdown()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="prosthesis_controller.node", description=__doc__.split(
        "\n\n")[0])
    p.add_argument("--controller", required=True, help=f"one of {ControllerName.choices()}")
    p.add_argument("--gait", help="the paper's graph: the gait file (with --tube)")
    p.add_argument("--tube", help="the paper's graph: the force-tube file")
    p.add_argument("--tables", help="a multi-contact gait's controller file "
                   "(prosthesis_controller.gait_tables), instead of --gait and --tube")
    p.add_argument("--speed", type=float, help="a gait library's controller file: the "
                   "person's first walking speed (m/s)")
    p.add_argument("--bus", help="bus config file (TOML/JSON)")
    p.add_argument("--interface")
    p.add_argument("--run-id")
    p.add_argument("--channel")
    p.add_argument("--listen")
    p.add_argument("--connect")
    p.add_argument("--key", help="zenoh: the key file (one line, mode 0600) the plant "
                   "authenticates with (bus_config.read_key)")
    p.add_argument("--low-latency", action="store_true",
                   help="zenoh low-latency transport (the plant must use it too)")
    p.add_argument("--cpu", type=int, help="run the node on this CPU only")
    p.add_argument("--poll-us", type=float, default=0.0,
                   help="zenoh bus: poll this long (yielding the CPU) before blocking")
    p.add_argument("--watchdog-ms", type=float, default=50.0)
    p.add_argument("--status-every", type=int, default=100)
    p.add_argument("--subject")
    p.add_argument("--device")
    p.add_argument("--auth-stdin", action="store_true",
                   help="zenoh: read the run's secret from the first line of stdin and "
                   "authenticate the link with it (bus_schemas.transport.run_auth)")
    return p


def _node_config(a: argparse.Namespace) -> tuple[BusConfig, RunCredentials | None]:
    """The bus config of the command line ``a`` and the run's credentials of
    ``--auth-stdin`` (to close after the run), ValueError for a bad one."""
    cfg = bus_config_from_args(a.bus, interface=a.interface, run_id=a.run_id,
                               channel=a.channel, listen=a.listen, connect=a.connect,
                               key_file=a.key)
    if a.low_latency or a.poll_us:
        cfg = cfg.with_zenoh_options(low_latency=a.low_latency, poll_us=a.poll_us)
    if not a.auth_stdin:
        return cfg, None
    if not cfg.authenticates:
        raise ValueError("--auth-stdin needs the zenoh interface")
    if cfg.key_file is not None:
        raise ValueError("--auth-stdin and --key: give one key")
    creds = RunCredentials(sys.stdin.readline().strip())
    return cfg.with_zenoh_options(zenoh_options=creds.zenoh_options("ctrl")), creds


def main(argv: Sequence[str] | None = None) -> int:
    a = _parser().parse_args(argv)
    creds = None
    try:
        cfg, creds = _node_config(a)
        if a.cpu is not None:  # this process: the serving thread and the bus's, started after
            pin_thread(a.cpu)
        s = run_node(a.controller, Artifacts(a.gait, a.tube, a.subject, a.device, a.tables,
                                                   a.speed),
                     cfg, watchdog=a.watchdog_ms * 1e-3, status_every=a.status_every)
    except KeyboardInterrupt:
        return 130
    except ValueError as e:  # a bad option value (e.g. --cpu): one line, no traceback
        print(f"controller node: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    finally:
        if creds is not None:
            creds.close()
    print(f"{SUMMARY_PREFIX}{json_io.dumps(s)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

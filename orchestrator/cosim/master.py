"""Co-simulation master: the human FMU (fmpy) on the plant side, the prosthesis controller
in its own process, CAN frames (AMPRO3 protocol) over zenoh between them, MCAP recording.

Per tick k (t = k dt, dt = 1 ms by default) the plant

1. reads the FMU outputs (sensors as AMPRO3 senses them; in lockstep the state for the
   ground truth after step 2, while the controller works);
2. emulates the AMPRO3 drives: encodes ``KneeFeedback``, ``AnkleFeedback``, ``FootLoad``,
   ``SimTime`` (rolling counter k mod 16, timestamp t) and sends them (through the fault
   injector of the ``perturb`` case);
3. waits for the ``TorqueCmd`` answering this cycle (its timestamp echoes t):
   *lockstep* blocks for it (deterministic), *realtime* waits at most until the tick's wall
   deadline and otherwise holds the last torque (counted late; latency stats kept);
   other controller frames (heartbeat, status, rejects, CLF) are checked and recorded on
   the way (lockstep: those of the reply sample before its TorqueCmd after the next
   cycle's send, :meth:`CanLink.settle`); the cycle's ``CtrlClf`` gives the period's
   ``Command.V`` and ``.rho`` (None when absent or not received);
4. sets the torque inputs, reads the socket force (it depends on them), records ground
   truth (lockstep: queued after the next cycle's send, in the same order), and steps the
   FMU by dt.

Fault handling: a missing reply holds the last torque; ``watchdog_periods`` (5) missed
replies in a row, the controller's liveliness token disappearing, or its heartbeat reporting
SAFE/FAULT make the plant apply the safe torque (zero) and end the run as *faulted*. The
recording is always finished (also on SIGTERM/SIGINT).

:func:`run_cosim` is the function behind ``hpcosim run``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import can
import numpy as np

from bus_schemas import codec, keys
from bus_schemas.bus_config import FrameReader, send_frames
from bus_schemas.frame import Frame
from bus_schemas.protocol import (
    CTRL_TO_PLANT,
    PLANT_TO_CTRL,
    TORQUE_STEP,
    CtrlState,
    FrameId,
    frame_specs,
)
from bus_schemas.run_auth import RunCredentials
from bus_schemas.zenoh_config import loopback_endpoint
from hp_model.falls import FallReason
from human_fmu.instance import HumanFmu
from orchestrator.loop import Command, FmuPlant, Observation, Sensed, run_loop
from orchestrator.loop.foxglove import WalkerFoxglove
from orchestrator.loop.recorder import GroundTruthRecorder
from orchestrator.modes import CosimMode
from prosthesis_controller.timing import Usage, pin_thread

ROOT = Path(__file__).resolve().parents[2]  # the checkout (git revision, PYTHONPATH)
PERTURB_CASES = ("none", "drop", "delay", "duplicate", "corrupt-counter", "corrupt-checksum",
                 "corrupt-length", "kill", "hang", "stall", "human")
#: the controller-process cases: SIGKILL it (dies, liveliness goes) or SIGSTOP it (hangs
#: alive: only the missing replies show it)
PROCESS_CASES = ("kill", "hang")
#: the plant's own lateness: before tick START the plant loop sleeps MS ms (a page fault, a
#: GC pause, a descheduled process), ``stall:START[:MS]`` (MS 50 by default)
PLANT_CASES = ("stall",)


class CosimError(RuntimeError):
    """A co-simulation that could not start or run (one-line message)."""


@dataclass
class CosimConfig:
    controller: str
    gait: Path
    tube: Path
    steps: int = 20
    max_time: float = 60.0  # s of simulation time
    mode: CosimMode = CosimMode.LOCKSTEP  # or its value
    perturb: str = "none"  # CASE[:start[:every[:count]]] or human:AMPLITUDE[:SEED]
    record: Path | None = None
    fmu: Path | None = None
    dt: float = 1e-3
    run_id: str | None = None
    watchdog_periods: int = 5
    reply_timeout: float = 0.25  # s wall per reply in lockstep before a period counts missed;
    #  realtime: for the first reply (the watchdog is armed by it)
    start_timeout: float = 60.0  # s wall for the controller process to come alive
    status_every: int = 100
    controller_watchdog: float = 0.05  # s, the node's own watchdog
    low_latency: bool = True  # zenoh low-latency transport on both sides
    # lockstep: plant loop and controller node each on its own CPU (>= 2 CPUs; cpu_plan). The
    # calling thread's affinity is restored after the run; zenoh's threads, if this run
    # starts them (the first zenoh session of the process), stay on the plant's CPU.
    pin_cpus: bool = True
    poll_us: float = 300.0  # lockstep: both sides poll this long before blocking on a frame
    # realtime: a plant more than this far behind its wall-clock schedule moves the schedule
    # forward (the wall slots in between are skipped, counted and recorded; simulation time
    # never skips) instead of bursting through the backlog
    max_lag: float = 0.02  # s

    def __post_init__(self) -> None:
        self.mode = CosimMode(self.mode)

    def to_dict(self) -> dict[str, Any]:
        return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items()}


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


# --------------------------------------------------------------------------- FMU


def ensure_fmu(gait_path: Path, model: Any, fmu: Path | None = None,
               progress: Callable[[str], None] | None = None) -> Path:
    """The FMU file: ``fmu`` if given, else a cached build for this gait, model and builder
    (``$HPCOSIM_CACHE`` or ``~/.cache/hpcosim``/fmu/<digest>/human.fmu; the digest covers
    the gait file, the model parameters and :func:`human_fmu.build.builder_digest`)."""
    if fmu is not None:
        if not Path(fmu).is_file():
            raise FileNotFoundError(f"{fmu}: no such FMU")
        from fmpy import read_model_description

        try:
            read_model_description(str(fmu))
        except Exception as e:  # fmpy raises zip, XML and schema errors alike
            raise CosimError(f"{fmu}: not an FMU ({type(e).__name__}: {e})") from None
        return Path(fmu)
    from hp_model.compiled import cache_root
    from human_fmu import build_fmu
    from human_fmu.build import builder_digest

    digest = hashlib.sha256(f"{sha256(gait_path)}\0{model.parameter_hash()}\0"
                            f"{builder_digest()}".encode()).hexdigest()[:16]
    out = cache_root() / "fmu" / digest / "human.fmu"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        build_fmu(gait_path, out, model=model, progress=progress)
    return out


# --------------------------------------------------------------------------- faults


@dataclass
class FaultPlan:
    """Frame faults injected into the plant's KneeFeedback frames (or the controller kill):
    at ticks ``start, start + every, ...`` (``count`` times)."""

    case: str = "none"
    start: int = 100
    every: int = 97
    count: int = 5
    amplitude: float = 0.0  # human perturbation
    seed: int = 0
    stall_ms: float = 50.0  # stall: the plant's sleep

    @classmethod
    def parse(cls, text: str | None) -> FaultPlan:
        if not text or text == "none":
            return cls()
        parts = text.split(":")
        case = parts[0]
        if case not in PERTURB_CASES:
            raise ValueError(f"perturb case {case!r}: choose one of {', '.join(PERTURB_CASES)}")
        if case == "human":
            amp = float(parts[1]) if len(parts) > 1 else 0.001
            return cls(case, amplitude=amp, seed=int(parts[2]) if len(parts) > 2 else 0)
        if case == "stall":
            return cls(case, start=int(parts[1]) if len(parts) > 1 else 100, count=1,
                       stall_ms=float(parts[2]) if len(parts) > 2 else 50.0)
        nums = [int(p) for p in parts[1:]]
        plan = cls(case)
        for name, v in zip(("start", "every", "count"), nums, strict=False):
            setattr(plan, name, v)
        return plan

    def hits(self, k: int) -> bool:
        if self.case in ("none", "human") or k < self.start:
            return False
        d = k - self.start
        return d % max(1, self.every) == 0 and d // max(1, self.every) < self.count

    def apply(self, k: int, frames: list[Any]) -> tuple[list[Any], str | None]:
        """Frames to send this tick (SimTime last unless delayed) and the fault applied."""
        if not self.hits(k) or self.case in PROCESS_CASES + PLANT_CASES:
            return frames, None
        knee = frames[0]
        rest = frames[1:]
        if self.case == "drop":
            return rest, "drop"
        if self.case == "delay":
            return [*rest, knee], "delay"  # arrives after the cycle's SimTime: too late
        if self.case == "duplicate":
            return [knee, knee, *rest], "duplicate"
        bad = can.Message(timestamp=knee.timestamp, arbitration_id=knee.arbitration_id,
                          is_extended_id=False, dlc=8, data=bytearray(knee.data))
        if self.case == "corrupt-counter":
            v = codec.decode(knee).value
            bad = codec.encode_frame(FrameId.KNEE_FEEDBACK,
                                     {"KneeAngle": v.angle, "KneeVelocity": v.velocity},
                                     ((knee.data[6] & 0x0F) + 5) % 16, timestamp=knee.timestamp)
        elif self.case == "corrupt-checksum":
            bad.data[0] ^= 0x01
        elif self.case == "corrupt-length":
            bad = can.Message(timestamp=knee.timestamp, arbitration_id=knee.arbitration_id,
                              is_extended_id=False, dlc=7, data=bytes(knee.data[:7]))
        return [bad, *rest], self.case


# --------------------------------------------------------------------------- helpers


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for p in ("eclipse-zenoh", "python-can", "mcap", "fmpy", "numpy", "casadi", "piqp"):
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            out[p] = "missing"
    try:
        import hp_model

        out["hpcosim"] = hp_model.__version__
    except Exception:  # pragma: no cover
        pass
    try:
        out["git"] = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"],
                                    capture_output=True, text=True, timeout=5).stdout.strip()
    except Exception:  # pragma: no cover
        out["git"] = "unknown"
    return out


def cpu_plan(cfg: CosimConfig) -> tuple[int | None, int | None]:
    """(plant CPU, controller CPU) in lockstep mode when ``pin_cpus`` and this process may
    use two CPUs, else (None, None): a pair of the allowed CPUs, chosen by process id on a
    larger machine so that runs started side by side spread out (on two CPUs: both).

    Lockstep alternates between the two processes, each always busy or about to be; on a
    small shared machine, letting the scheduler place them makes each wake-up (the reply
    arriving, the next cycle's frames) land on a CPU busy with the other process or other
    jobs. Each process on its own CPU, with its zenoh threads, keeps those hand-offs local
    (measured: docs/cosim.md). Realtime mode idles between ticks and is better
    served by any free CPU: pinned, a pinned process stuck behind another job missed 50
    periods in a row in 2 of 6 runs at the 2 ms cycle, unpinned in none.
    """
    avail = sorted(os.sched_getaffinity(0))
    if not cfg.pin_cpus or cfg.mode != CosimMode.LOCKSTEP or len(avail) < 2:
        return None, None
    i = 2 * (os.getpid() % (len(avail) // 2))
    return avail[i], avail[i + 1]


def bus_poll_us(cfg: CosimConfig) -> float:
    """How long a receive polls before it blocks, on both sides: ``poll_us`` in lockstep
    (the next frame is due within a fraction of a millisecond), 0 in realtime mode (pacing
    to the wall clock: nothing to gain, a CPU to keep free)."""
    return float(cfg.poll_us) if cfg.mode == CosimMode.LOCKSTEP else 0.0


def controller_command(cfg: CosimConfig, run_id: str, endpoint: str,
                       cpu: int | None = None) -> list[str]:
    return [sys.executable, "-m", "prosthesis_controller.node", "--controller", cfg.controller,
            "--gait", str(cfg.gait), "--tube", str(cfg.tube), "--run-id", run_id,
            "--connect", endpoint, "--watchdog-ms", str(cfg.controller_watchdog * 1e3),
            "--status-every", str(cfg.status_every), "--auth-stdin"] + (
                ["--low-latency"] if cfg.low_latency else []) + (
                ["--cpu", str(cpu)] if cpu is not None else []) + (
                ["--poll-us", str(bus_poll_us(cfg))] if bus_poll_us(cfg) else [])


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
    return env


def _pct(a: list[float], q: float) -> float:
    return float(np.percentile(a, q)) if a else 0.0


# --------------------------------------------------------------------------- the run


_CLF, _TORQUE, _STATUS, _DISTURBANCE, _HEARTBEAT, _REJECTS = (
    int(FrameId.CTRL_CLF), int(FrameId.TORQUE_CMD), int(FrameId.CTRL_STATUS),
    int(FrameId.CTRL_DISTURBANCE), int(FrameId.CTRL_HEARTBEAT), int(FrameId.CTRL_REJECTS))
_OK = codec.FrameStatus.OK


class Plant:
    """The plant side of one run: rx frame checking, the controller state it implies, and
    the bound on what it applies: every torque command is clamped to the device's motor
    limits ``limits`` (knee, ankle; N m) whatever the sender computed or encoded (the DBC
    admits +-5 N m), and counted when it had to be."""

    def __init__(self, limits: tuple[float, float]) -> None:
        if not all(math.isfinite(x) and x > 0 for x in limits):
            raise ValueError(f"torque limits must be finite and > 0, got {limits}")
        self.limits = (float(limits[0]), float(limits[1]))
        self.checker = codec.FrameChecker(accept=CTRL_TO_PLANT)
        self.ctrl_state: int | None = None
        self.ctrl_rejects: dict[str, int] = {}
        self.last_status: Any = None
        self.torque_clamped = 0  # commands with a torque outside the limits

    def command(self, c: Any) -> tuple[float, float]:
        """The motor torques to apply for a decoded TorqueCmd ``c``: zero unless enabled,
        each clamped to +-limit (a non-finite value is applied as zero and counted)."""
        if not c.enable:
            return 0.0, 0.0
        (k, a), (lk, la) = (float(c.knee), float(c.ankle)), self.limits
        # a command at the limit decodes to within the signal's resolution of it
        if not (abs(k) <= lk + TORQUE_STEP and abs(a) <= la + TORQUE_STEP):
            self.torque_clamped += 1
        return (min(max(k, -lk), lk) if math.isfinite(k) else 0.0,
                min(max(a, -la), la) if math.isfinite(a) else 0.0)

    def on_rx(self, msg: can.Message | codec.Frame) -> codec.Verdict:
        """Classify one controller frame (never raises) and track heartbeat and status."""
        v = self.checker.check(msg)
        if v.status is _OK:
            fid = v.frame_id  # plain ints below: an IntEnum member's lookup is Python code
            if fid == _HEARTBEAT:
                self.ctrl_state = int(v.value.state)
            elif fid == _REJECTS:
                self.ctrl_rejects = {k: int(n) for k, n in v.value._asdict().items()}
            elif fid == _STATUS:
                self.last_status = v.value
        return v


def run_cosim(cfg: CosimConfig, *, progress: Callable[[int, float, int], None] | None = None,
              model: Any = None, say: Callable[[str], None] | None = None,
              install_signal_handlers: bool = False) -> CosimResult:
    """Run one co-simulation (module docstring). Returns the summary; the recording (if any)
    is complete and readable whatever happens."""

    import hp_model
    from bus_schemas.mcap_schemas import Recorder
    from bus_schemas.protocol import DBC_PATH
    from bus_schemas.zenoh_can import ZenohBus
    from hp_model.gait_artifact import load_gait

    say = say or (lambda _m: None)
    plan = FaultPlan.parse(cfg.perturb)
    model = model or hp_model.load_model()
    gait = load_gait(cfg.gait, model.parameter_hash())
    from hp_model.force_tube import load_tube

    tube = load_tube(cfg.tube, gait.hash())  # refuse a mismatched tube here, not in the child
    fmu_path = ensure_fmu(Path(cfg.gait), model, cfg.fmu, say)
    run_id = cfg.run_id or f"run-{os.getpid()}-{time.monotonic_ns() % 10**9}"
    keys.validate_run_id(run_id)
    k_idx, a_idx = model.roles["ps"].prosthesis
    ratio = (float(model.B[k_idx, 4]), float(model.B[a_idx, 5]))

    res = CosimResult(run_id=run_id)
    rec = None
    bus = None
    proc = None
    fmu = None
    lost = threading.Event()
    stop = threading.Event()  # a signal asked the run to end (install_signal_handlers)
    sub = None
    affinity: set[int] | None = None  # to restore after pinning the plant loop
    old_handlers: dict[int, Any] = {}
    creds: RunCredentials | None = None
    if install_signal_handlers:
        def _on_signal(signum: int, _frame: Any) -> None:  # a flag only: the loop ends
            res.interrupted = signal.Signals(signum).name
            stop.set()

        for sig in (signal.SIGINT, signal.SIGTERM):
            old_handlers[sig] = signal.signal(sig, _on_signal)
    try:
        real = {}
        integer = {}
        if plan.case == "human":
            real["human_perturbation"] = plan.amplitude
            integer["human_seed"] = plan.seed
        fmu = HumanFmu(fmu_path)
        fmu.start(real, integer)
        if cfg.record is not None:
            Path(cfg.record).parent.mkdir(parents=True, exist_ok=True)
            rec = Recorder(cfg.record, metadata={"run_id": run_id}, can_rates=0.1)
            rec.register_all()
            rec.add_metadata("config", cfg.to_dict())
            rec.add_metadata("versions", versions())
            rec.add_metadata("hashes", {"gait_sha256": sha256(cfg.gait),
                                        "tube_sha256": sha256(cfg.tube),
                                        "fmu_sha256": sha256(fmu_path),
                                        "gait_hash": gait.hash(),
                                        "model_hash": model.parameter_hash(),
                                        "fmu_guid": fmu.md.guid})
            rec.add_metadata("device", {"gear_ratio_knee": ratio[0],
                                        "gear_ratio_ankle": ratio[1], "dt": cfg.dt})
            rec.add_attachment("gait.json", Path(cfg.gait).read_bytes(), "application/json")
            rec.add_attachment("tube.json", Path(cfg.tube).read_bytes(), "application/json")
            rec.add_attachment("modelDescription.xml", fmu.model_description_xml(),
                               "application/xml")
            rec.add_attachment("ampro3.dbc", Path(DBC_PATH).read_bytes(), "text/plain")

        endpoint = loopback_endpoint()
        plant_cpu, node_cpu = cpu_plan(cfg)
        if plant_cpu is not None:  # before the bus: zenoh threads started now inherit it
            affinity = pin_thread(plant_cpu)
        creds = RunCredentials()  # only this run's controller can join the link
        bus = ZenohBus(f"{run_id}/plant", listen=endpoint, low_latency=cfg.low_latency,
                       poll_us=bus_poll_us(cfg), zenoh_options=creds.zenoh_options("plant"))
        alive = threading.Event()

        def _on_live(is_alive: bool) -> None:  # sets flags only; nothing blocks here
            if is_alive:
                alive.set()
            else:
                lost.set()

        sub = bus.watch_peer(_on_live)
        say(f"starting controller {cfg.controller} (run {run_id})")
        proc = subprocess.Popen(controller_command(cfg, run_id, endpoint, node_cpu), env=_env(),
                                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, cwd=str(ROOT))
        if proc.stdin is not None:  # the secret through a pipe, then EOF
            with contextlib.suppress(BrokenPipeError):
                proc.stdin.write(f"{creds.secret}\n".encode())
                proc.stdin.close()
        deadline = time.monotonic() + cfg.start_timeout
        while not alive.wait(0.05):
            if stop.is_set():
                break
            if proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
                raise CosimError(f"controller process exited ({proc.returncode}) before it "
                                 f"was alive: {err.strip().splitlines()[-1:]}")
            if time.monotonic() > deadline:
                raise CosimError(f"controller not alive after {cfg.start_timeout} s")
        if not stop.is_set() and not bus.wait_for_peer(10.0):
            raise CosimError("controller alive but not subscribed")
        if not stop.is_set():
            say("controller alive")
            limits = (float(model.torque_limits[4]), float(model.torque_limits[5]))
            walker = None if rec is None else WalkerFoxglove(model, gait, tube)
            _loop(cfg, plan, fmu, bus, rec, proc, lost, stop, res, ratio, limits, progress,
                  walker)
    finally:
        if affinity is not None:
            os.sched_setaffinity(0, affinity)
        if sub is not None:
            sub.close()
        if bus is not None:
            bus.shutdown()
        if proc is not None:
            if plan.case == "hang" and proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    proc.send_signal(signal.SIGCONT)  # let it see the plant gone and exit
            try:
                proc.wait(3.0)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(3.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            if proc.stderr:
                with contextlib.suppress(Exception):
                    res.node = node_summary(proc.stderr.read().decode(errors="replace"))
                proc.stderr.close()
        if fmu is not None:
            fmu.free()
        if rec is not None and rec.write_failed:
            rec.abort()  # a full disk: no partial file (the write's error names the file)
        elif rec is not None and not rec.finished:
            try:
                if res.interrupted:
                    rec.add_metadata("signal", {"signal": res.interrupted,
                                                "messages": str(rec.message_count)})
                rec.add_metadata("summary", _summary_dict(res))
            finally:
                rec.finish()
        for sig, h in old_handlers.items():
            signal.signal(sig, h)
        if creds is not None:
            creds.close()
    return res


def node_summary(stderr: str) -> dict[str, Any]:
    """The controller node's JSON summary (its last ``controller node: {...}`` line on
    stderr), or {} if it printed none (killed, crashed)."""
    from prosthesis_controller.node import SUMMARY_PREFIX

    for line in reversed(stderr.splitlines()):
        if line.startswith(SUMMARY_PREFIX):
            try:
                d = json.loads(line[len(SUMMARY_PREFIX):])
            except ValueError:
                return {}
            return d if isinstance(d, dict) else {}
    return {}


def _summary_dict(res: CosimResult) -> dict[str, Any]:
    d = asdict(res)
    d["real_time_factor"] = res.real_time_factor
    d["fall_reason"] = res.fall_reason
    return d


#: record queue entries the plant may leave for later waits when the controller's reply
#: comes before the serialization is done (a few ticks' worth)
MAX_BACKLOG = 64


class CanLink:
    """The controller in its own process, over CAN frames on a python-can ``bus`` (AMPRO3's
    protocol; module docstring, steps 2-3): per period the plant's frames go out through the
    fault ``plan``, the controller's frames are checked and recorded, and this cycle's
    ``TorqueCmd`` is awaited (lockstep: up to ``reply_timeout``; realtime: until 0.8 dt
    into the tick's wall slot).  A missing reply holds the last torque; the watchdog, a
    lost liveliness token or a SAFE/FAULT heartbeat give the safe torque (zero) and a
    :attr:`Command.fault`.  Recording is deferred: the tick's frames are queued as they
    happen and serialized while the plant waits for the reply.  The cycle's ``CtrlClf``
    frame gives :attr:`Command.V` and :attr:`Command.rho` (None when the frame says absent,
    or when no good frame of this cycle came).

    In lockstep under :func:`orchestrator.loop.run_loop` (:attr:`idle_after_send`) only what
    the torque needs is on the way from the reply to the next send: the reply sample's
    ``TorqueCmd`` is checked first (a frame's verdict depends on its own id's counter state
    alone, so it is the verdict it gets after the frames before it); the frames before it
    are checked, and their records queued, in the loop's ``idle`` after the next cycle's
    send (:meth:`settle`), before any other controller frame: the same verdicts, counts,
    Command and records in the same order.  A reply sample of another shape (a fault, a
    python-can bus) is taken frame by frame as before."""

    def __init__(self, cfg: CosimConfig, plan: FaultPlan, bus: Any, rec: Any, proc: Any,
                 lost: threading.Event, res: CosimResult, ratio: tuple[float, float],
                 limits: tuple[float, float]) -> None:
        self.cfg, self.plan, self.bus, self.rec, self.proc = cfg, plan, bus, rec, proc
        self.frames = FrameReader(bus)
        self.lost, self.res, self.ratio = lost, res, ratio
        self.plant = Plant(limits)
        self.dt = cfg.dt
        self.realtime = cfg.mode == CosimMode.REALTIME
        self.u = (0.0, 0.0)
        self.missed_run = 0
        self.fault_first_miss = -1
        self.lat: list[float] = []
        # per tick [ns]: send -> reply in hand, MCAP serialization (inside the round trip),
        # blocked waiting after it
        self.t_rt: list[int] = []
        self.t_rec: list[int] = []
        self.t_wait: list[int] = []
        self.injected: dict[str, int] = {}
        self.wall0 = time.perf_counter()
        self.sched0 = self.wall0  # realtime: tick k's slot starts at sched0 + k dt
        self.rtol = max(1e-7, self.dt * 1e-3)  # matching a reply's echoed timestamp
        self.names = {fid: frame_specs()[fid].name for fid in PLANT_TO_CTRL}
        # realtime: the missed-reply watchdog is armed by the first reply (a process
        # scheduled late at its start, measured up to 10 ms on a loaded 2-core machine, is
        # not a dead controller); before it, the first reply must come within
        # reply_timeout of the start.  Lockstep waits reply_timeout for every reply, so it
        # is armed from the first period.
        self.armed = not self.realtime
        #: the last good CtrlClf: (timestamp [s], V or None, rho or None)
        self.clf: tuple[float, float | None, float | None] | None = None
        #: lockstep under run_loop (:attr:`idle_after_send`): the reply frames before this
        #: cycle's TorqueCmd, checked after the next cycle's send (:meth:`settle`): (frames,
        #: the TorqueCmd, its verdict, t, the torque applied before it)
        self._held: tuple[list[Any], Any, codec.Verdict, float, tuple[float, float]] | None = None
        #: the Command :meth:`settle` completes, and its cycle's time
        self._provisional: tuple[Command, float] | None = None
        #: the last cycle's send [ns, perf_counter_ns] and the first tick at which a SAFE
        #: heartbeat is again the controller's fault: a plant silent for longer than the
        #: node's own watchdog (its stall, a descheduled process) put the node in SAFE
        #: itself; the node resumes with the next cycle, so that SAFE is excused for
        #: ``watchdog_periods`` ticks (a controller that does not come back is then caught
        #: by the missed replies or by its SAFE state, as any other)
        self._sent_ns: int | None = None
        self.safe_excused_until = 0

    @property
    def idle_after_send(self) -> bool:
        """Lockstep: :meth:`exchange` takes the loop's ``idle`` work (run_loop) and checks
        only this cycle's TorqueCmd before it returns (realtime: everything at once, the log
        times of its records being wall times)."""
        return not self.realtime

    def log_ns(self, t: float) -> int:
        return round((time.perf_counter() - self.wall0 if self.realtime else t) * 1e9)

    def on_rx(self, msg: can.Message, t: float,
              items: list[tuple[Any, codec.Verdict]] | None = None,
              v: codec.Verdict | None = None) -> codec.Verdict:
        """Check one controller frame (:meth:`Plant.on_rx`; ``v``: a TorqueCmd's verdict
        already taken), take the cycle's V and rho from
        a good ``CtrlClf``; with a recording, the frame and what it carries go to ``items``
        (queued for the MCAP per sample by :meth:`_defer_rx`; a ``CtrlStatus``'s
        diagnostics record, every 100 ticks, is queued here with the torque and CLF values
        of the moment)."""
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
            st = v.value
            u, r = self.u, self.ratio
            c = self.clf  # the node sends its cycle's CtrlClf before CtrlStatus
            V, rho = (c[1], c[2]) if c is not None and c[0] == msg.timestamp else (None, None)
            self.rec.defer("/controller/diagnostics", {
                "t": msg.timestamp, "controller": self.cfg.controller, "domain": None,
                "tau": None, "V": V, "rho": rho, "u": [u[0] * r[0], u[1] * r[1]],
                "qp_status": getattr(st.qp_status, "name", str(st.qp_status)),
                "active_constraints": [a.name for a in type(st.active_constraints)
                                       if a in st.active_constraints and a.name],
                "fallback_count": st.fallback_count, "fault_flags": int(st.fault_flags),
                "coverage_flag": bool(st.coverage_flag), "coverage_count": st.coverage_count,
                "solve_time_us": None, "source": "CtrlStatus frame",
                "ctrl_rejects": self.plant.ctrl_rejects}, self.log_ns(t))
        return v

    def _reply_here(self) -> bool:
        """Stop serializing records: a controller frame is here, and at most
        :data:`MAX_BACKLOG` queue entries are left (serializing keeps up with the run; what
        is left goes in the next waits)."""
        return self.rec.deferred <= MAX_BACKLOG and self.frames.ready()

    def _defer_rx(self, items: list[tuple[Any, codec.Verdict]], t: float) -> None:
        """Queue the records of one received sample's frames (one queue entry)."""
        if items and self.rec is not None:
            self.rec.defer_many(self.log_ns(t), rx_records, items, self.ratio)

    def _inject(self, what: str) -> None:
        self.injected[what] = self.injected.get(what, 0) + 1

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
        items: list[tuple[Any, codec.Verdict]] = []
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
        c = self.clf
        if c is not None and abs(c[0] - t) <= self.rtol:
            return cmd._replace(V=c[1], rho=c[2])
        return cmd._replace(V=None, rho=None)

    def exchange(self, obs: Observation, idle: Callable[[], None] | None = None) -> Command:
        """This period's Command (class docstring); ``idle`` (lockstep, run_loop's
        bookkeeping): called once after the send, and the reply's frames before this
        cycle's TorqueCmd are checked later, in :meth:`settle` (the Command returned is
        then provisional: ``V``/``rho`` None until settled)."""
        cfg, plan, rec, res, k, t = self.cfg, self.plan, self.rec, self.res, obs.k, obs.t
        if plan.case in PLANT_CASES and plan.hits(k):
            time.sleep(plan.stall_ms * 1e-3)
            self._inject(plan.case)
        if self.realtime:
            self.sched0 = _catch_up(res, rec, t, k, self.dt, self.sched0, cfg.max_lag,
                                    self.log_ns)
        if plan.case in PROCESS_CASES and k == plan.start and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL if plan.case == "kill" else signal.SIGSTOP)
        s = obs.sensed
        t_us = round(t * 1e6)
        frames = codec.feedback_frames(s.knee_angle, s.knee_velocity, s.ankle_angle,
                                       s.ankle_velocity, s.foot_load, s.contact, k % 16,
                                       sim_time_us=t_us, socket_pitch=s.socket_pitch,
                                       timestamp=t)
        send, what = plan.apply(k, frames)
        if what:
            self._inject(what)
        clock = time.perf_counter_ns
        s0 = clock()
        if self._sent_ns is not None and (s0 - self._sent_ns) * 1e-9 > cfg.controller_watchdog:
            self.safe_excused_until = k + cfg.watchdog_periods
        self._sent_ns = s0
        send_frames(self.bus, send)
        res.frames_tx += len(send)
        if idle is not None:  # the last period's bookkeeping, while the controller works
            idle()
        if self._held is not None:
            self._settle_held()  # before any other controller frame is checked
        if rec is not None:  # while the controller works: queue and serialize the records,
            # stopping as soon as the reply is here (the rest waits for the next tick's wait)
            r0 = clock()
            rec.defer_many(self.log_ns(t), tx_records, frames, self.names, s, t_us, k % 16)
            rec.write_deferred(self._reply_here)
            self.t_rec.append(clock() - r0)
        w0 = clock()
        # this cycle's torque: lockstep up to reply_timeout; realtime until 0.8 dt into the
        # tick's slot, or 0.8 dt after sending when the plant itself runs behind (a late
        # plant must not count its own lateness as the controller's missed reply)
        got = answered = False
        deadline = (max(self.sched0 + (k + 0.8) * self.dt, s0 * 1e-9 + 0.8 * self.dt)
                    if self.realtime else s0 * 1e-9 + cfg.reply_timeout)
        reader, rtol = self.frames, self.rtol
        while not got:
            left = deadline - time.perf_counter()
            if left <= 0 or self.lost.is_set():
                break
            sample = reader.recv_all(min(left, 0.005))
            if not sample:
                continue
            pre = None
            if idle is not None:
                pre = self._take_torque(sample, t)
                if self._held is not None:
                    got = answered = True
                    break
            last = len(sample) - 1
            items: list[tuple[Any, codec.Verdict]] = []
            for i, msg in enumerate(sample):  # a sample's frames: the reply batch
                v = self.on_rx(msg, t, items, pre if i == last else None)
                if v.frame_id == _TORQUE and v.status is _OK:
                    self.u = self.plant.command(v.value)
                    answered = True
                    if abs(msg.timestamp - t) <= rtol:
                        got = True
                        if i + 1 < len(sample):  # frames after this cycle's reply
                            reader.unread(sample[i + 1:])
                        break
            self._defer_rx(items, t)
        if got:
            r1 = clock()
            self.lat.append((r1 - s0) * 1e-9)
            self.t_rt.append(r1 - s0)
            self.t_wait.append(r1 - w0)
            self.missed_run, self.fault_first_miss, self.armed = 0, -1, True
        elif self.realtime and answered:
            # a reply to an earlier tick arrived (and is applied): the controller is alive
            # but behind; counted late, not missing (the watchdog is for silence)
            res.late += 1
            self.missed_run, self.fault_first_miss = 0, -1
        else:
            if self.realtime:
                res.late += 1
            res.missed += 1
            if self.armed:
                self.missed_run += 1
            if self.fault_first_miss < 0:
                self.fault_first_miss = k
        reason = self._fault(k, got)
        if reason:
            self.u = (0.0, 0.0)
            first = self.fault_first_miss if self.fault_first_miss >= 0 else k
            res.detection_periods = k - first + 1
        if self._held is not None:  # V and rho once settled
            cmd = Command(self.u, V=None, rho=None, fault=reason)
            self._provisional = (cmd, t)
            return cmd
        c = self.clf
        if c is not None and abs(c[0] - t) <= self.rtol:  # this cycle's CtrlClf
            return Command(self.u, V=c[1], rho=c[2], fault=reason)
        return Command(self.u, V=None, rho=None, fault=reason)

    def _fault(self, k: int, got: bool) -> str:
        """Why the plant stops trusting the controller this period ("" while it does)."""
        if self.lost.is_set():
            return "controller liveliness token lost"
        if self.missed_run >= self.cfg.watchdog_periods:
            return f"{self.missed_run} control periods without a torque reply"
        if not self.armed and time.perf_counter() - self.wall0 > self.cfg.reply_timeout:
            return (f"no torque reply within {self.cfg.reply_timeout} s of the start "
                    f"({k + 1} periods)")
        state = self.plant.ctrl_state
        if state in (CtrlState.SAFE, CtrlState.FAULT) and k > 0 and not got and not (
                state == CtrlState.SAFE and k < self.safe_excused_until):
            return f"controller reports state {CtrlState(state).name}"
        return ""

    def pace(self, k: int) -> None:
        """Realtime: wait for tick ``k``'s wall slot, taking late replies meanwhile."""
        if not self.realtime:
            return
        end = self.sched0 + k * self.dt
        t = (k - 1) * self.dt
        self._settle_held()
        while True:
            left = end - time.perf_counter()
            if left <= 0:
                break
            items: list[tuple[Any, codec.Verdict]] = []
            for msg in self.frames.recv_all(left):
                v = self.on_rx(msg, t, items)
                if v.frame_id == _TORQUE and v.status is _OK and v.value.enable:
                    self.u = (v.value.knee, v.value.ankle)
            self._defer_rx(items, t)


def _loop(cfg: CosimConfig, plan: FaultPlan, fmu: HumanFmu, bus: Any, rec: Any, proc: Any,
          lost: threading.Event, stop: threading.Event, res: CosimResult,
          ratio: tuple[float, float], limits: tuple[float, float],
          progress: Callable[[int, float, int], None] | None,
          walker: WalkerFoxglove | None = None) -> None:
    """The tick loop (module docstring): :func:`orchestrator.loop.run_loop` of the FMU
    plant and the CAN link, and the run's summary from it; ``walker``: the recording also
    carries the walker for Foxglove (:mod:`orchestrator.loop.foxglove`)."""
    link = CanLink(cfg, plan, bus, rec, proc, lost, res, ratio, limits)
    usage = Usage()
    log = run_loop(FmuPlant(fmu, cfg.dt), link, steps=cfg.steps,
                   periods=round(cfg.max_time / cfg.dt), stop=stop, progress=progress,
                   recorder=(None if rec is None else
                             GroundTruthRecorder(rec, log_ns=link.log_ns, deferred=True,
                                                 walker=walker)),
                   timed=True, samples=False)
    res.steps = log.steps
    if log.fall is not None:
        res.fell, res.fall_code = True, log.fall.code
    if log.fault:
        res.faulted, res.fault_reason = True, log.fault
    res.ticks = log.periods
    res.sim_time = log.periods * cfg.dt
    res.wall_time = time.perf_counter() - link.wall0
    res.injected = link.injected
    res.plant_rejects = {str(s): n for s, n in link.plant.checker.counts.items()
                         if str(s) != "ok"}
    res.torque_clamped = link.plant.torque_clamped
    res.ctrl_rejects = link.plant.ctrl_rejects
    if link.lat:
        a = [x * 1e6 for x in link.lat]
        res.latency_us = {"median": _pct(a, 50), "p99": _pct(a, 99), "max": max(a),
                          "n": len(a)}
    res.timing_us = tick_breakdown(log.tick_ns, log.plant_ns, link.t_rt, link.t_rec,
                                   link.t_wait)
    res.reply_early = reply_early_share(link.t_wait) if rec is not None else 0.0
    res.usage = usage.since()


def _catch_up(res: CosimResult, rec: Any, t: float, k: int, dt: float, sched0: float,
              max_lag: float, log_ns: Callable[[float], int]) -> float:
    """Realtime: the plant's lag behind tick ``k``'s wall slot. A tick begun a period or
    more late is an overrun (counted; recorded on ``/cosim/timing``); past ``max_lag`` the
    schedule moves forward by whole periods (the slots skipped counted and recorded), so a
    plant that fell behind resumes pacing instead of bursting through the backlog.
    Returns the (possibly moved) schedule origin."""
    lag = time.perf_counter() - (sched0 + k * dt)
    if lag < dt:
        return sched0
    res.overruns += 1
    res.max_lag_ms = max(res.max_lag_ms, lag * 1e3)
    skip = int(lag // dt) if lag > max_lag else 0
    res.skipped_slots += skip
    if rec is not None:
        rec.defer("/cosim/timing", {"t": t, "tick": k, "lag": lag, "skipped": skip},
                  log_ns(t))
    return sched0 + skip * dt


def tx_records(frames: list[Any], names: dict[int, str], s: Sensed, t_us: int,
               counter: int) -> list[tuple[str, Any]]:
    """The records of one cycle's plant frames (as encoded, before any injected fault):
    each frame on ``/can/tx`` and the measurement they carry."""
    from bus_schemas.mcap_schemas import can_frame_message  # the recorder's module, loaded

    out: list[tuple[str, Any]] = [
        ("/can/tx", can_frame_message(m, "tx", name=names[m.arbitration_id]))
        for m in frames]
    out.append(("/prosthesis/measurements", measurement_record(s, t_us, counter)))
    return out


def rx_records(items: list[tuple[Any, codec.Verdict]], ratio: tuple[float, float]
               ) -> list[tuple[str, Any]]:
    """The records of one received sample's controller frames: each on ``/can/rx`` with the
    plant's verdict, and a good ``TorqueCmd`` or ``CtrlDisturbance`` on its own channel."""
    from bus_schemas.mcap_schemas import can_frame_message

    out: list[tuple[str, Any]] = []
    for m, v in items:
        out.append(("/can/rx", can_frame_message(m, "rx", name=v.name, status=str(v.status))))
        if v.status is not _OK:
            continue
        if v.frame_id == _TORQUE:
            out.append(("/prosthesis/torque_command",
                        torque_record(v.value, v.counter, m.timestamp, ratio)))
        elif v.frame_id == _DISTURBANCE:
            out.append(("/controller/disturbance", disturbance_record(v.value, m.timestamp)))
    return out


_Q_ANGLE = codec.scalar_quantizer(FrameId.KNEE_FEEDBACK, "KneeAngle")  # quantize_angle
_Q_VELOCITY = codec.scalar_quantizer(FrameId.KNEE_FEEDBACK, "KneeVelocity")
_Q_LOAD = codec.scalar_quantizer(FrameId.FOOT_LOAD, "FootNormalLoad")
_Q_PITCH = codec.scalar_quantizer(FrameId.SOCKET_IMU, "SocketPitch")


def measurement_record(s: Sensed, t_us: int, counter: int) -> dict[str, Any]:
    """``/prosthesis/measurements``: what AMPRO3 senses (``s``) as the controller decodes it
    (codec quantization: ``quantize_angle`` etc., their constants bound once)."""
    return {"knee_angle": _Q_ANGLE(s.knee_angle),
            "knee_velocity": _Q_VELOCITY(s.knee_velocity),
            "ankle_angle": _Q_ANGLE(s.ankle_angle),
            "ankle_velocity": _Q_VELOCITY(s.ankle_velocity),
            "foot_load": _Q_LOAD(s.foot_load), "contact": s.contact,
            "socket_pitch": (_Q_PITCH(s.socket_pitch)
                             if math.isfinite(s.socket_pitch) else None),
            "sim_time_us": t_us % (1 << 32), "counter": counter}


def torque_record(c: codec.TorqueCmd, counter: int | None, timestamp: float,
                  ratio: tuple[float, float]) -> dict[str, Any]:
    """``/prosthesis/torque_command``: motor torques [N m] and the joint torques they give
    (gear ``ratio``), for the cycle whose SimTime timestamp [s] the frame echoes."""
    return {"knee": c.knee, "ankle": c.ankle, "knee_joint": c.knee * ratio[0],
            "ankle_joint": c.ankle * ratio[1], "enable": bool(c.enable), "counter": counter,
            "cycle_time_us": round(timestamp * 1e6)}


def disturbance_record(e: codec.CtrlDisturbance, timestamp: float) -> dict[str, Any]:
    """``/controller/disturbance``: the controller's model-error estimate of the cycle
    whose SimTime timestamp [s] the frame echoes."""
    return {"t": timestamp, "d": [e.dy1, e.d2y2], "tau": e.tau, "valid": bool(e.valid),
            "flag": bool(e.flag), "since_touchdown": e.since_touchdown}


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


def tmp_run_id() -> str:
    return f"t{next(tempfile._get_candidate_names())}"

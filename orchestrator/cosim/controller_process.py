"""The prosthesis controller node (:mod:`prosthesis_controller.node`) in its own process for
one run, and the plant's end of the zenoh link to it.

:class:`ControllerProcess` opens the plant's bus (listening on a loopback endpoint, the link
authenticated with this run's secret so that only this run's controller can join), watches
the controller's liveliness token, spawns the node with the run's configuration (the secret
through its stdin), waits until it is alive and subscribed, injects the process faults
(SIGKILL, SIGSTOP), and at the end shuts it all down and reads the node's summary."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from bus_schemas.transport.run_auth import RunCredentials
from bus_schemas.transport.zenoh_config import loopback_endpoint
from orchestrator.cosim.config import CosimConfig, CosimError
from orchestrator.cosim.cpus import bus_poll_us
from orchestrator.cosim.faults import PerturbCase

ROOT = Path(__file__).resolve().parents[2]  # the checkout (git revision, PYTHONPATH)


def controller_command(cfg: CosimConfig, run_id: str, endpoint: str,
                       cpu: int | None = None, tables: Path | None = None,
                       speed: float | None = None) -> list[str]:
    """The node's command line: ``cfg``'s controller, artifacts, subject and device (as
    absolute paths: the node runs in the checkout), or a multi-contact gait's controller
    file ``tables`` (a gait library's: the person's first ``speed``, m/s); the link
    (``run_id``, the plant's ``endpoint``) and the node's CPU ``cpu``."""
    poll = bus_poll_us(cfg)
    artifacts = (["--tables", _abs(tables)] if tables is not None else
                 ["--gait", _abs(cfg.gait), "--tube", _abs(cfg.tube)] if cfg.tube else [])
    return [sys.executable, "-m", "prosthesis_controller.node", "--controller", cfg.controller,
            *artifacts, *(["--speed", repr(float(speed))] if speed is not None else []),
            "--run-id", run_id,
            "--connect", endpoint, "--watchdog-ms", str(cfg.controller_watchdog * 1e3),
            "--status-every", str(cfg.status_every), "--auth-stdin",
            *(["--subject", _abs(cfg.subject)] if cfg.subject is not None else []),
            *(["--device", _abs(cfg.device)] if cfg.device is not None else []),
            *(["--low-latency"] if cfg.low_latency else []),
            *(["--cpu", str(cpu)] if cpu is not None else []),
            *(["--poll-us", str(poll)] if poll else [])]


def _abs(path: Path) -> str:
    return str(Path(path).resolve())


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


def _env() -> dict[str, str]:
    """The node's environment: this one, the checkout first on PYTHONPATH."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]]
                                                      if env.get("PYTHONPATH") else []))
    return env


class ControllerProcess:
    """The controller node of one run and the plant's bus to it (module docstring).

    :meth:`open` starts both; :attr:`bus` is then the plant's python-can bus and
    :attr:`lost` is set once the node's liveliness token has gone.  :meth:`close` (the
    context manager's exit) ends both and puts the node's own summary into ``summary``."""

    def __init__(self, cfg: CosimConfig, run_id: str, *, cpu: int | None = None,
                 summary: dict[str, Any] | None = None, tables: Path | None = None,
                 speed: float | None = None) -> None:
        self.cfg, self.run_id, self.cpu, self.tables = cfg, run_id, cpu, tables
        self.speed = speed  # a gait library's controller: the person's first speed, m/s
        self.summary = summary if summary is not None else {}
        self.lost = threading.Event()
        self._alive = threading.Event()
        self.bus: Any = None
        self._watch: Any = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._creds: RunCredentials | None = None
        self._stopped = False  # SIGSTOP sent (the hang case)

    def __enter__(self) -> ControllerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self, stop: threading.Event, say: Callable[[str], None]) -> bool:
        """Open the plant's bus, spawn the node and wait until it is alive and subscribed
        (True), or until ``stop`` is set (False). CosimError if the node exits first or is
        not alive within ``start_timeout``."""
        from bus_schemas.transport.zenoh_can import ZenohBus

        cfg = self.cfg
        endpoint = loopback_endpoint()
        self._creds = RunCredentials()  # only this run's controller can join the link
        self.bus = ZenohBus(f"{self.run_id}/plant", listen=endpoint,
                            low_latency=cfg.low_latency, poll_us=bus_poll_us(cfg),
                            zenoh_options=self._creds.zenoh_options("plant"))
        self._watch = self.bus.watch_peer(self._on_liveliness)
        say(f"starting controller {cfg.controller} (run {self.run_id})")
        self._spawn(controller_command(cfg, self.run_id, endpoint, self.cpu, self.tables,
                                        self.speed))
        self._wait_alive(stop)
        if not stop.is_set() and not self.bus.wait_for_peer(10.0):
            raise CosimError("controller alive but not subscribed")
        return not stop.is_set()

    def _on_liveliness(self, is_alive: bool) -> None:
        """The node's token appeared or went (sets flags only; nothing blocks here)."""
        if is_alive:
            self._alive.set()
        else:
            self.lost.set()

    def _spawn(self, command: list[str]) -> None:
        """Start the node; the run's secret through a pipe, then EOF."""
        assert self._creds is not None
        self._proc = proc = subprocess.Popen(
            command, env=_env(), stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE, cwd=str(ROOT))
        if proc.stdin is not None:
            with contextlib.suppress(BrokenPipeError):
                proc.stdin.write(f"{self._creds.secret}\n".encode())
                proc.stdin.close()

    def _wait_alive(self, stop: threading.Event) -> None:
        """Until the node's liveliness token is seen or ``stop`` is set."""
        proc = self._proc
        assert proc is not None
        deadline = time.monotonic() + self.cfg.start_timeout
        while not self._alive.wait(0.05):
            if stop.is_set():
                return
            if proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
                raise CosimError(f"controller process exited ({proc.returncode}) before it "
                                 f"was alive: {err.strip().splitlines()[-1:]}")
            if time.monotonic() > deadline:
                raise CosimError(f"controller not alive after {self.cfg.start_timeout} s")

    def inject(self, case: PerturbCase) -> None:
        """A process fault: ``kill`` (SIGKILL: it dies, its token goes) or ``hang``
        (SIGSTOP: it stays alive, only its replies stop), if it still runs."""
        proc = self._proc
        if proc is None or proc.poll() is not None:
            return
        if case is PerturbCase.KILL:
            proc.send_signal(signal.SIGKILL)
        elif case is PerturbCase.HANG:
            proc.send_signal(signal.SIGSTOP)
            self._stopped = True

    def close(self) -> None:
        """Close the bus (the node sees the plant gone and exits), wait for the node
        (terminate, then kill, after 3 s each) and read its summary."""
        if self._watch is not None:
            self._watch.close()
            self._watch = None
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None
        if self._proc is not None:
            self._end(self._proc)
            self._proc = None
        if self._creds is not None:
            self._creds.close()
            self._creds = None

    def _end(self, proc: subprocess.Popen[bytes]) -> None:
        if self._stopped and proc.poll() is None:
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
                self.summary.update(node_summary(proc.stderr.read().decode(errors="replace")))
            proc.stderr.close()

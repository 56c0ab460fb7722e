"""The co-simulation's configuration (:class:`CosimConfig`, what ``hpcosim run`` sets) and its
one-line error (:class:`CosimError`)."""

from __future__ import annotations

from dataclasses import KW_ONLY, asdict, dataclass
from pathlib import Path
from typing import Any

from orchestrator.modes import CosimMode


class CosimError(RuntimeError):
    """A co-simulation that could not start or run (one-line message)."""


@dataclass
class CosimConfig:
    """One co-simulation run: the controller and the artifacts it is built from, how long
    and how the run goes, what it records; times in s unless named otherwise."""

    controller: str
    gait: Path
    tube: Path
    _: KW_ONLY
    #: subject and device TOML (None: the shipped defaults), for the plant's model and the
    #: controller process alike
    subject: Path | None = None
    device: Path | None = None
    steps: int = 20
    max_time: float = 60.0  # s of simulation time
    mode: CosimMode = CosimMode.LOCKSTEP  # or its value
    perturb: str = "none"  # CASE[:start[:every[:count]]] or human:AMPLITUDE[:SEED] (faults.py)
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
    # lockstep: plant loop and controller node each on its own CPU (>= 2 CPUs; cpus.cpu_plan).
    # The calling thread's affinity is restored after the run; zenoh's threads, if this run
    # starts them (the first zenoh session of the process), stay on the plant's CPU.
    pin_cpus: bool = True
    poll_us: float = 300.0  # lockstep: both sides poll this long before blocking on a frame
    # realtime: a plant more than this far behind its wall-clock schedule moves the schedule
    # forward (the wall slots in between are skipped, counted and recorded; simulation time
    # never skips) instead of bursting through the backlog
    max_lag: float = 0.02  # s

    def __post_init__(self) -> None:
        self.mode = CosimMode(self.mode)

    @property
    def realtime(self) -> bool:
        return self.mode == CosimMode.REALTIME

    def to_dict(self) -> dict[str, Any]:
        """The configuration as plain values (paths as strings), as recordings store it."""
        return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items()}

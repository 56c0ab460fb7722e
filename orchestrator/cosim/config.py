"""The co-simulation's configuration (:class:`CosimConfig`, what ``hpcosim run`` sets) and its
one-line error (:class:`CosimError`)."""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, asdict, dataclass
from pathlib import Path
from typing import Any

from bus_schemas.transport.keys import validate_run_id
from hp_model.speed_profile import SpeedProfile
from orchestrator.cosim.faults import FaultPlan
from orchestrator.modes import CosimMode
from prosthesis_controller.interface import ControllerName


class CosimError(RuntimeError):
    """A co-simulation that could not start or run (one-line message)."""


#: the command-line option of a configuration field (errors name it)
_OPTION = {"max_time": "--max-time", "steps": "--steps", "perturb": "--perturb"}
#: the numbers of a configuration that must be finite: > 0 (True) or >= 0 (False)
_FINITE = {"max_time": True, "dt": True, "reply_timeout": True, "start_timeout": True,
           "controller_watchdog": True, "poll_us": False, "max_lag": True}


@dataclass
class CosimConfig:
    """One co-simulation run: the controller and the artifacts it is built from, how long
    and how the run goes, what it records; times in s unless named otherwise."""

    controller: str
    gait: Path
    #: the paper's graph's force tube (None: a multi-contact gait's run, which has none)
    tube: Path | None
    _: KW_ONLY
    #: subject and device TOML (None: the shipped defaults), for the plant's model and the
    #: controller process alike
    subject: Path | None = None
    device: Path | None = None
    #: a multi-contact gait's run: a gait library of its person (``hpcosim gait library``),
    #: the person walking it at the commanded ``speed_profile`` (SpeedProfile's text form;
    #: None: the gait's own speed) and ``clfqp`` following the person's speed over it
    library: Path | None = None
    speed_profile: str | None = None
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
        """Every value checked before anything starts: :class:`CosimError` naming the
        option (``hpcosim run``'s) or field."""
        for name, kind in (("mode", CosimMode), ("controller", ControllerName)):
            try:
                setattr(self, name, kind(getattr(self, name)))
            except ValueError as e:
                raise CosimError(f"--{name}: {' '.join(str(e).split())}") from None
        if isinstance(self.steps, bool) or not isinstance(self.steps, int) or self.steps < 1:
            raise CosimError(f"--steps {self.steps!r}: expected a whole number >= 1")
        for name, strict in _FINITE.items():
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) \
                    or v < 0 or (strict and v == 0):
                raise CosimError(f"{_OPTION.get(name, name)} {v!r}: expected a finite number "
                                 f"{'>' if strict else '>='} 0")
        if not math.isfinite(self.max_time / self.dt):
            raise CosimError(f"--max-time {self.max_time!r}: too many periods of {self.dt} s")
        for name in ("watchdog_periods", "status_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise CosimError(f"{name} {v!r}: expected a whole number >= 1")
        _speed_profile(self.speed_profile, self.library)  # CosimError if bad
        try:
            FaultPlan.parse(self.perturb)
            if self.run_id is not None:
                validate_run_id(self.run_id)
        except ValueError as e:
            raise CosimError(str(e)) from None

    @property
    def profile(self) -> SpeedProfile | None:
        """The commanded speed (None: none given)."""
        return _speed_profile(self.speed_profile, self.library)

    @property
    def realtime(self) -> bool:
        return self.mode == CosimMode.REALTIME

    def to_dict(self) -> dict[str, Any]:
        """The configuration as plain values (paths as strings), as recordings store it."""
        return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items()}


def _speed_profile(text: str | None, library: Path | None) -> SpeedProfile | None:
    """``--speed-profile``'s text parsed (None: none given); CosimError naming the option when
    it is not a profile, or given without ``--library``."""
    if text is None:
        return None
    if library is None:
        raise CosimError("--speed-profile: the person changes speed over a gait library; "
                         "give --library")
    try:
        return SpeedProfile.parse(text)
    except ValueError as e:
        raise CosimError(f"--speed-profile {text!r}: {e}") from None

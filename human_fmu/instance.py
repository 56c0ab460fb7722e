"""One instance of a co-simulation FMU loaded through fmpy, with name-based value references.

Shared by the co-simulation master (:mod:`orchestrator.cosim`) and the sweep's FMU backend
(:mod:`orchestrator.sweep_fmu`).  (``tests/fmu_runner.py`` keeps its own copy on purpose: it
must run in a Python where this project cannot be imported.)
"""

from __future__ import annotations

import ctypes
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any


def step_or_end(slave: Any, component: Any, t: float, dt: float) -> bool:
    """``slave.fmi2DoStep(component, t, dt, fmi2True)`` on an fmpy ``FMU2Slave``: True on
    success, False when the FMU discards the step and reports itself terminated (the end of
    the walk), else the ``FMICallException`` propagates."""
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import fmi2Boolean, fmi2Discard, fmi2Terminated, fmi2True

    try:
        slave.fmi2DoStep(component, t, dt, fmi2True)
        return True
    except FMICallException as e:
        if e.status != fmi2Discard:
            raise
    done = fmi2Boolean()
    slave.fmi2GetBooleanStatus(component, fmi2Terminated, ctypes.byref(done))
    if not done.value:
        raise FMICallException(function="fmi2DoStep", status=fmi2Discard)
    return False


class FmuInstance:
    """An fmpy ``FMU2Slave`` of the FMU at ``path``, extracted into ``unzipdir`` (a fresh
    temporary folder by default, removed by :meth:`free`) and instantiated once."""

    def __init__(self, path: str | Path, *, unzipdir: str | Path | None = None,
                 instance: str = "human") -> None:
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.path = Path(path)
        self.md = read_model_description(str(path))
        if self.md.fmiVersion != "2.0":
            from human_fmu.build import FmuBuildError

            raise FmuBuildError(f"{path}: an FMI {self.md.fmiVersion} FMU; the co-simulation "
                                "and the sweeps drive FMI 2.0 FMUs (hpcosim fmu build "
                                "without --fmi 3; the two are bit-identical)")
        self.unzipdir = Path(extract(str(path),
                                     unzipdir=None if unzipdir is None else str(unzipdir)))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(self.unzipdir),
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance)
        self.fmu.instantiate()

    def vrs(self, names: Iterable[str]) -> list[int]:
        """Value references of ``names`` (KeyError for an unknown name)."""
        return [self.vr[n] for n in names]

    def initialize(self, real: Mapping[str, float] | None = None,
                   integer: Mapping[str, int] | None = None) -> None:
        """setupExperiment(t = 0), set the start values, enter and exit initialization."""
        f = self.fmu
        f.setupExperiment(startTime=0.0)
        if real:
            f.setReal(self.vrs(real), [float(v) for v in real.values()])
        if integer:
            f.setInteger(self.vrs(integer), [int(v) for v in integer.values()])
        f.enterInitializationMode()
        f.exitInitializationMode()

    def do_step(self, t: float, dt: float) -> bool:
        """fmi2DoStep(t, dt): True while the walk goes on, False once the FMU has ended it
        (fmi2Discard with fmi2Terminated: a fall; the outputs hold the last valid state).
        Any other failure raises fmpy's ``FMICallException``."""
        return step_or_end(self.fmu, self.fmu.component, t, dt)

    def free(self) -> None:
        """Terminate and free the instance, then remove the extracted files."""
        try:
            self.fmu.terminate()
            self.fmu.freeInstance()
        finally:
            shutil.rmtree(self.unzipdir, ignore_errors=True)

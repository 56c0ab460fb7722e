"""The run modes of the co-simulation and the sweeps, in a module the command line loads at
start-up (its options are these enums; :mod:`orchestrator.cosim.master` and
:mod:`orchestrator.sweep.spec`, which use them, load only when a verb needs them)."""

from __future__ import annotations

from hp_model.choices import Choice


class CosimMode(Choice):
    """How the co-simulation's plant paces the run (:mod:`orchestrator.cosim.master`)."""

    LOCKSTEP = "lockstep"  # each tick waits for the controller's reply
    REALTIME = "realtime"  # ticks on the wall clock


class SweepBackend(Choice):
    """What a sweep run simulates the human with (:mod:`orchestrator.sweep.spec`)."""

    SIMULATOR = "simulator"  # the in-process hybrid simulator
    FMU = "fmu"  # the human FMU (fmpy, in the worker's process)

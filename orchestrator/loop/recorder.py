"""The loop's optional recorder: the ground truth of every period into an MCAP recording
(``/ground_truth``, the channel :mod:`orchestrator.cosim.recording` and ``hpcosim animate``
read)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from orchestrator.loop.link import Command
from orchestrator.loop.plant import Observation, Truth


def ground_truth_record(obs: Observation, truth: Truth) -> dict[str, Any]:
    """``/ground_truth`` of one period: socket force (Fx, Fz [N], My [N m]) under the
    applied motor torques, q and qd, domain, phase and step count."""
    fs, u = truth.socket_force, truth.torque
    return {"t": obs.t, "socket_force": {"Fx": float(fs[0]), "Fz": float(fs[1]),
                                         "My": float(fs[2])},
            "q": _floats(truth.q), "qd": _floats(truth.qd), "domain": obs.domain,
            "tau": obs.tau, "step": obs.steps, "fallen": False,
            "u_applied": [float(u[0]), float(u[1])]}


def _floats(v: Sequence[float]) -> list[float]:
    """A list of floats (the FMU's values already are; the simulator's are an array)."""
    return v.tolist() if isinstance(v, np.ndarray) else list(v)


class GroundTruthRecorder:
    """Writes ``/ground_truth`` to ``rec`` (a :class:`bus_schemas.mcap_schemas.Recorder`)
    at log time ``log_ns(t)`` (default: the simulation time); ``deferred``: queued and
    serialized when the owner calls ``rec.write_deferred()`` (the co-simulation does it
    while it waits for the controller)."""

    def __init__(self, rec: Any, *, log_ns: Callable[[float], int] | None = None,
                 deferred: bool = False) -> None:
        self.rec, self.deferred = rec, deferred
        self.log_ns = log_ns or (lambda t: round(t * 1e9))

    def record(self, obs: Observation, cmd: Command, truth: Truth) -> None:
        ns = self.log_ns(obs.t)
        if self.deferred:
            self.rec.defer_call("/ground_truth", ns, ground_truth_record, obs, truth)
        else:
            self.rec.write("/ground_truth", ground_truth_record(obs, truth), ns)

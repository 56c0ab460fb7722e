"""The loop's optional recorder: the ground truth of every period into an MCAP recording
(``/ground_truth``, the channel :mod:`orchestrator.cosim.recording` and ``hpcosim animate``
read), the link's CLF value and relaxation of every period (``/controller/clf``, null
where the link reported none) and, given a
:class:`~orchestrator.loop.foxglove.WalkerFoxglove`, every
:data:`~orchestrator.loop.foxglove.PERIOD` of simulation time the walker for Foxglove
(``/walker/tf``, ``/walker/scene``, ``/walker/reference``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from orchestrator.loop.foxglove import (
    PERIOD,
    REFERENCE_TOPIC,
    SCENE_TOPIC,
    TRANSFORMS_TOPIC,
    WalkerFoxglove,
)
from orchestrator.loop.link import Command
from orchestrator.loop.plant import Observation, Truth, Vector


def ground_truth_record(obs: Observation, truth: Truth) -> dict[str, Any]:
    """``/ground_truth`` of one period: socket force (Fx, Fz [N], My [N m]) under the
    applied motor torques, q and qd, domain, phase and step count."""
    fs, u = truth.socket_force, truth.torque
    return {"t": obs.t, "socket_force": {"Fx": float(fs[0]), "Fz": float(fs[1]),
                                         "My": float(fs[2])},
            "q": _floats(truth.q), "qd": _floats(truth.qd), "domain": obs.domain,
            "tau": obs.tau, "step": obs.steps, "fallen": False,
            "u_applied": [float(u[0]), float(u[1])]}


CLF_TOPIC = "/controller/clf"


def clf_record(t: float, V: float | None, rho: float | None) -> dict[str, Any]:
    """``/controller/clf`` of one period: time [s], the command's CLF value and relaxation
    (dimensionless; None where the link reported none)."""
    return {"t": t, "V": V, "rho": rho}


def _floats(v: Vector) -> list[float]:
    """A list of floats (the FMU's values already are; the simulator's are an array)."""
    return v.tolist() if isinstance(v, np.ndarray) else list(v)


class GroundTruthRecorder:
    """Writes ``/ground_truth`` and ``/controller/clf`` to ``rec`` (a
    :class:`bus_schemas.recording.recorder.Recorder`) at log time ``log_ns(t)`` (default: the
    simulation time); ``deferred``: queued and
    serialized when the owner calls ``rec.write_deferred()`` (the co-simulation does it
    while it waits for the controller); ``walker``: also the walker for Foxglove, at the
    first period and then every ``period`` s of simulation time (the messages are built
    when written, so a deferred recorder's hot path only queues them)."""

    def __init__(self, rec: Any, *, log_ns: Callable[[float], int] | None = None,
                 deferred: bool = False, walker: WalkerFoxglove | None = None,
                 period: float = PERIOD) -> None:
        self.rec, self.deferred, self.walker, self.period = rec, deferred, walker, period
        self.log_ns = log_ns or (lambda t: round(t * 1e9))
        self._next = -np.inf  # simulation time of the next walker message [s]

    def record(self, obs: Observation, cmd: Command, truth: Truth) -> None:
        ns = self.log_ns(obs.t)
        walk = self.walker is not None and obs.t >= self._next
        if walk:
            self._next = obs.t + self.period * (1.0 - 1e-6)
        if self.deferred:  # one queue entry: the period's records, built when written
            self.rec.defer_many(ns, self._messages, ns, obs, cmd, truth, walk)
            return
        for topic, message in self._messages(ns, obs, cmd, truth, walk):
            self.rec.write(topic, message, ns)

    def _messages(self, ns: int, obs: Observation, cmd: Command, truth: Truth, walk: bool
                  ) -> list[tuple[str, Any]]:
        """The period's (topic, message) pairs in their file order."""
        out: list[tuple[str, Any]] = [
            ("/ground_truth", ground_truth_record(obs, truth)),
            (CLF_TOPIC, clf_record(obs.t, cmd.V, cmd.rho))]
        w = self.walker
        if walk and w is not None:
            out += [(TRANSFORMS_TOPIC, w.transforms(ns, truth.q)),
                    (SCENE_TOPIC, w.scene(ns, obs.t, truth.q, truth.socket_force, obs.domain,
                                          obs.tau, obs.steps)),
                    (REFERENCE_TOPIC, w.reference(obs.t, obs.domain, obs.tau))]
        return out

"""The simulated person walking a gait library (``hpcosim gait library``) at a commanded speed
that changes while it walks (a speed profile, :class:`hp_model.speed_profile.SpeedProfile`),
in the in-process plant: entering each domain, the person takes the library's curves at the
speed commanded then (:func:`characterization.gait.library.speed_schedule`), starting from
the cycle's start at the first speed (:func:`characterization.gait.library.start_at`).

The prosthesis: the held oracle (the full feedback linearization of the person's curves of
the moment, held over each 1 ms period), or ``clfqp`` / contact-pd following the person's
speed over the library from their own sensors
(:func:`orchestrator.cosim.following.speed_following`).

Usage: python -m orchestrator.experiments.speed_walk LIBRARY.json --profile 0:0.8,20:1.2,40:0.8
       [--steps 100] [--controller oracle|clfqp|contact-pd] [--swing-phase time|thigh]
(exit 0: it took every step; 1: it fell; 2: bad input.)
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from characterization.gait.contact_gait import GAINS, held_oracle
from characterization.gait.library import (
    GaitLibrary,
    load_gait_library,
    speed_schedule,
    start_at,
)
from characterization.gait.multicontact import GRAPH
from hp_model.artifacts import ArtifactError
from hp_model.closed_loop import ClosedLoop
from hp_model.domains import Domain
from hp_model.simulator import SimResult
from hp_model.speed_profile import SpeedProfile
from orchestrator.cosim.contact_controllers import loop_simulator
from orchestrator.cosim.following import speed_following
from orchestrator.experiments.contact_walk import controller_run
from prosthesis_controller.contact_phase_pd import DEFAULT_SWING_PHASE, SWING_PHASES

CONTROLLERS = ("oracle", "clfqp", "contact-pd")


@dataclass(frozen=True)
class SpeedWalk:
    """A walk along a speed profile: the steps taken of ``wanted``, how it ended (``fall``:
    its message, None if it took every step), and per stride (the person's heel strike to
    heel strike) its end ``t`` (s), its speed (m/s), the speed commanded at its end and the
    controller's estimate then (NaN for the oracle)."""

    steps: int
    wanted: int
    fall: str | None
    t: np.ndarray
    speed: np.ndarray
    command: np.ndarray
    estimate: np.ndarray

    @property
    def walks(self) -> bool:
        return self.fall is None and self.steps >= self.wanted

    def lag_rms(self) -> float:
        """RMS of the strides' speed less the command (m/s; NaN without strides)."""
        e = self.speed - self.command
        return float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan")

    def line(self) -> str:
        if not self.walks:
            return f"falls after {self.steps} steps: {self.fall}"
        return (f"walks {self.steps} steps; stride speeds {self.speed.min():.2f}-"
                f"{self.speed.max():.2f} m/s, {self.lag_rms():.3f} m/s RMS off the command")

    def to_json(self) -> dict[str, Any]:
        return {"walks": self.walks, "steps": self.steps, "wanted": self.wanted,
                "fall": self.fall, "t": self.t, "speed": self.speed, "command": self.command,
                "estimate": self.estimate}


def _strides(res: SimResult, profile: SpeedProfile, estimate: np.ndarray, dt: float
             ) -> tuple[np.ndarray, ...]:
    """Per stride of the person's heel strikes: end time, speed, command, estimate."""
    strikes = [i for i in res.impacts if i.into == Domain.DS_H]
    t = np.array([i.t for i in strikes])
    x = np.array([float(i.q[0]) for i in strikes])
    if t.size < 2:
        return tuple(np.zeros(0) for _ in range(4))
    ends = t[1:]
    k = np.clip((ends / dt).astype(int), 0, max(estimate.size - 1, 0))
    est = estimate[k] if estimate.size else np.full(ends.size, np.nan)
    return ends, np.diff(x) / np.diff(t), np.array([profile.at(s) for s in ends]), est


def speed_walk(library: GaitLibrary, profile: SpeedProfile, steps: int,
               controller: str = "oracle", swing_phase: str = DEFAULT_SWING_PHASE,
               closed_loop: ClosedLoop | None = None) -> SpeedWalk:
    """Walk ``steps`` steps of ``library`` along ``profile`` with the prosthesis on
    ``controller`` (module docstring); a walk ends at a fall or 2 s per step."""
    if controller not in CONTROLLERS:
        raise ValueError(f"controller {controller!r}: choose from {', '.join(CONTROLLERS)}")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    cl = closed_loop or ClosedLoop(library.model,
                                   library.curves[0].params[GRAPH.domains[0]].degree)
    v0 = profile.at(0.0)
    sim = loop_simulator(library.model, library.gait_at(v0), GAINS, cl)
    schedule, start = speed_schedule(library, profile), start_at(library, v0)
    if controller == "oracle":
        policy = held_oracle(cl, {Domain(d): th for d, th in sim.thetas.items()}, sim.gains)
        res = sim.run(*start, GRAPH.domains[0], steps=steps, duration=2.0 * steps,
                      policy=policy, gaits=schedule)
        estimate = np.zeros(0)
    else:
        ctl = speed_following(library, controller, v0, swing_phase, cl)
        log: list[float] = []
        res = controller_run(sim, library.gaits[0].trajectory, ctl, steps,
                             on_output=lambda _out: log.append(ctl.speed), gaits=schedule,
                             start=start)
        estimate = np.array(log)
    t, v, cmd, est = _strides(res, profile, estimate, sim.opt.dt)
    return SpeedWalk(res.steps, steps, None if res.fall is None else res.fall.message(), t, v,
                     cmd, est)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("library")
    ap.add_argument("--profile", required=True, help="time:speed pairs, s:m/s")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--controller", choices=CONTROLLERS, default="oracle")
    ap.add_argument("--swing-phase", choices=SWING_PHASES, default=DEFAULT_SWING_PHASE)
    a = ap.parse_args(argv)
    try:
        lib = load_gait_library(a.library)
        w = speed_walk(lib, SpeedProfile.parse(a.profile), a.steps, a.controller,
                       a.swing_phase)
    except (OSError, ValueError, ArtifactError) as e:
        print(f"speed_walk: error: {a.library}: {e}", file=sys.stderr)
        return 2
    print(f"{'t (s)':>8} {'speed':>7} {'command':>8} {'estimate':>9}")
    for k in range(0, w.t.size, max(1, w.t.size // 20)):
        print(f"{w.t[k]:8.2f} {w.speed[k]:7.3f} {w.command[k]:8.3f} {w.estimate[k]:9.3f}")
    print(f"{a.controller}: {w.line()}")
    return 0 if w.walks else 1


if __name__ == "__main__":
    raise SystemExit(main())

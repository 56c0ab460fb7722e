"""Checks that an optimized gait is a real, stable walking gait of the model.

- ``simulate_gait``: the full model under feedback linearization of all 6 outputs, started
  from the optimized initial state (start of ps), for N steps on the hybrid simulator.
- ``poincare``: the return map P from the post-impact state of ps to the next one (one
  cycle ps -> pns -> ps), in the 12 independent coordinates (6 joint angles, 6 joint
  velocities; the base follows from the stance foot flat at x = 0 and at rest:
  :func:`hp_model.placement.place`), its fixed
  point (found by iterating the map), and the eigenvalues of its Jacobian by central finite
  differences.  The orbit is locally exponentially stable when all |eig| < 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hp_model.closed_loop import ClosedLoop
from hp_model.domains import PAPER_DOMAINS, Domain
from hp_model.gait_artifact import Gait
from hp_model.human_prosthesis import HumanProsthesisModel
from hp_model.simulator import HybridSimulator, SimOptions, SimResult

JOINTS = ("th_lh", "th_lk", "th_la", "th_rh", "th_pk", "th_pa")


def make_simulator(model: HumanProsthesisModel, gait: Gait, gains: np.ndarray | None = None,
                   options: SimOptions | None = None) -> HybridSimulator:
    cl = ClosedLoop(model, gait.degree)
    return HybridSimulator(model, cl, {d: gait.theta(d) for d in PAPER_DOMAINS},
                           gait.gains_array if gains is None else gains, options)


def simulate_gait(sim: HybridSimulator, gait: Gait, steps: int = 20) -> SimResult:
    tr = gait.trajectory[Domain.PS]
    return sim.run(tr["q"][:, 0], tr["qd"][:, 0], Domain.PS, steps=steps)


class _Section:
    """Post-impact ps states <-> 12 independent coordinates."""

    def __init__(self, model: HumanProsthesisModel) -> None:
        self.model = model
        self.j = [model.coord_names.index(c) for c in JOINTS]

    def reduce(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.r_[q[self.j], qd[self.j]]

    def expand(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = self.model
        q, qd = np.zeros(m.nq), np.zeros(m.nq)
        q[self.j], qd[self.j] = s[:6], s[6:]
        return m.stance_state(q, qd, Domain.PS)


@dataclass(frozen=True)
class PoincareResult:
    fixed_point: np.ndarray  # (12,) joint angles and velocities after the pns -> ps impact
    fixed_point_residual: float  # |P(x*) - x*|_inf
    eigenvalues: np.ndarray
    jacobian: np.ndarray

    @property
    def spectral_radius(self) -> float:
        return float(np.abs(self.eigenvalues).max())


def return_map(sim: HybridSimulator, sec: _Section, s: np.ndarray) -> np.ndarray:
    q, qd = sec.expand(s)
    r = sim.run(q, qd, Domain.PS, steps=2)
    if r.failed or r.steps < 2:
        raise RuntimeError(f"return map: the cycle did not complete ({r.reason})")
    imp = r.impacts[-1]
    return sec.reduce(imp.q, imp.qd_plus)


def poincare(sim: HybridSimulator, gait: Gait, iterations: int = 6,
             delta: float = 1e-5) -> PoincareResult:
    sec = _Section(sim.model)
    tr = gait.trajectory[Domain.PS]
    s = sec.reduce(tr["q"][:, 0], tr["qd"][:, 0])
    for _ in range(iterations):
        s = return_map(sim, sec, s)
    p = return_map(sim, sec, s)
    Jm = np.empty((12, 12))
    for i in range(12):
        e = np.zeros(12)
        e[i] = delta
        Jm[:, i] = (return_map(sim, sec, s + e) - return_map(sim, sec, s - e)) / (2 * delta)
    return PoincareResult(fixed_point=s, fixed_point_residual=float(np.abs(p - s).max()),
                          eigenvalues=np.linalg.eigvals(Jm), jacobian=Jm)
